"""What a program's options add up to (grid nodes, neighbour pairs, memory columns),
estimated and refused at compile time, so a run never dies allocating them mid-way."""

from __future__ import annotations

import math

from swarmdsl.compiler import ast, checker, limits


def _world_option(chk, name: str) -> ast.Option | None:
    for w in chk.tree.decls_of(ast.WorldDecl)[:1]:
        for opt in w.options:
            if opt.name == name:
                return opt
    return None


def _kind_option(kind, name: str) -> ast.Option | None:
    for item in kind.decl.items:
        if isinstance(item, ast.Option) and item.name == name:
            return item
    return None


def _count(n: float) -> str:
    """A node count for a message: digits while readable, else 1.2e+302."""
    return f"{n:,.0f}" if n < 1e15 else f"{n:.3g}"


def _where(opt: ast.Option | None, fallback):
    return opt.span if opt is not None else fallback


def _grid_span(chk, fallback):
    """Where a grid too fine is to be mended: the `grid` option, or, when the default
    spacing is used, the world's `size` (what makes the default grid too big)."""
    return _where(_world_option(chk, "grid") or _world_option(chk, "size"), fallback)


def check_resources(chk) -> None:
    """Fail, located at the option to change, when a run could not hold its state."""
    world = chk.world
    program_span = chk.tree.span
    total = sum(k.count for k in chk.kinds)
    if total > limits.upper("count"):
        big = max(chk.kinds, key=lambda k: k.count)
        chk.fail(f"{total:,} agents in all; a run holds at most {limits.upper('count'):,}",
                 _where(_kind_option(big, "count"), program_span))
    nodes = (world.width / world.grid + 1) * (world.height / world.grid + 1)  # float: no overflow
    env = chk.extra.get("env")
    if env is not None and env.needed() and nodes > limits.MAX_GRID_NODES:
        chk.fail(f"the grid has {_count(nodes)} nodes ({world.width:g} x {world.height:g} at "
                 f"spacing {world.grid:g}); fields are limited to "
                 f"{limits.MAX_GRID_NODES:,} nodes", _grid_span(chk, program_span),
                 "use a coarser `grid`")
    if env is not None and env.needed() and world.grid > min(world.width, world.height):
        axis = "width" if world.width < world.grid else "height"
        chk.warn(f"the grid spacing {world.grid:g} is larger than the world's {axis} "
                 f"({world.width:g} x {world.height:g}): fields have one node along it, so "
                 "they cannot vary across the world that way", _grid_span(chk, program_span),
                 "use a grid spacing of at most a tenth of the world's size")
    side = max(world.width, world.height)
    if side / world.grid + 1 > limits.MAX_GRID_NODES:  # outputs list each axis's nodes
        chk.fail(f"the grid has {_count(side / world.grid + 1)} nodes along one side ({side:g} "
                 f"at spacing {world.grid:g}); at most {limits.MAX_GRID_NODES:,} are "
                 "allowed", _grid_span(chk, program_span), "use a coarser `grid`")
    if world.edges == "repel":
        reach = (world.edge_range or 2 * world.grid) / world.grid
        if reach > limits.MAX_EDGE_REACH:
            chk.fail(f"the edge repulsion range is {reach:,.0f} grid spacings; at most "
                     f"{limits.MAX_EDGE_REACH:,} are allowed",
                     _where(_world_option(chk, "edges"), program_span),
                     "use a shorter range or a coarser `grid`")
    _check_pairs(chk, total, program_span)
    memories = env.memories if env is not None else {}
    for kind in chk.kinds:
        cap = sum(memories.get(kind.name, {}).values())
        need = kind.count * cap * 16
        if need > limits.MAX_MEMORY_BYTES:
            chk.fail(f"the path memories of `{kind.name}` need {need / 2**30:,.1f} GiB "
                     f"({kind.count:,} agents x {cap:,} points); at most "
                     f"{limits.MAX_MEMORY_BYTES // 2**30} GiB are allowed",
                     _where(_kind_option(kind, "memory"), program_span))


def _check_pairs(chk, total: int, program_span) -> None:
    world = chk.world
    area = world.width * world.height
    for kind in chk.kinds:
        radii = [r for _, r in kind.neighbor_calls if r is not None]
        if kind.sense is not None:
            radii = [min(r, kind.sense) for r in radii] or [kind.sense]
        if not kind.uses_neighbors or not radii:
            continue
        r = max(radii)
        share = min(1.0, math.pi * r * r / area)
        pairs = float(kind.count) * max(total - 1, 0) * share
        need = pairs * limits.PAIR_BYTES
        if need > limits.MAX_PAIR_BYTES:
            opt = _kind_option(kind, "sense") or _kind_option(kind, "count")
            chk.fail(f"neighbour queries of `{kind.name}` within {r:g} would hold about "
                     f"{pairs:,.0f} pairs ({need / 2**30:,.0f} GiB) in a "
                     f"{world.width:g} x {world.height:g} world with {total:,} agents; at "
                     f"most {limits.MAX_PAIR_BYTES // 2**30} GiB are allowed",
                     _where(opt, program_span),
                     "use a smaller radius (`sense`), fewer agents or a larger world")


checker.PROGRAM_CHECK_HOOKS.append(check_resources)


# Agent options whose value is an expression per agent: constant ones are still checked
# (finite, not huge), as every constant is.
_EXPRESSION_OPTIONS = ("place", "velocity", "heading", "max_speed", "believe")


def check_constant_values(chk, kind) -> None:
    """Refuse non-finite or huge constants in per-agent options and variable values."""
    from swarmdsl.compiler.consteval import is_constant

    for item in kind.decl.items:
        if isinstance(item, ast.Option) and item.name in _EXPRESSION_OPTIONS:
            exprs, what = item.args, f"`{item.name}`"
        elif isinstance(item, ast.VarDecl | ast.AttrDecl):
            exprs, what = (item.value,), f"the value of `{item.name}`"
        else:
            continue
        for e in exprs:
            if is_constant(e, chk.params) and _no_limit(item, e, chk.params):
                chk.fail("`max_speed` is infinite: a constant is finite", e.span,
                         "leave `max_speed` out for no speed limit")
            elif is_constant(e, chk.params):
                chk._const(e, what)


def _no_limit(item, e: ast.Expr, params) -> bool:
    """`max_speed inf`: meant as no limit, which is leaving `max_speed` out."""
    from swarmdsl.compiler.consteval import const_value

    if not (isinstance(item, ast.Option) and item.name == "max_speed"):
        return False
    try:
        return const_value(e, params) == math.inf
    except (ArithmeticError, ValueError, TypeError):
        return False


checker.KIND_HOOKS.append(check_constant_values)


# ---- constants that cannot be computed ----

def _sure_children(node: ast.Node) -> list[ast.Node]:
    """The children an agent computes whenever it computes `node`. The sides of an `if`,
    `and` or `or` it may not take are left out (`if n > 0 then t / n else 0` is fine
    with `n` 0), and so are a neighbour filter's condition and an aggregate's `: EXPR`
    and `else`, where a NaN is each pair's own business (docs/language.md)."""
    if isinstance(node, ast.Cond):
        return [node.test]
    if isinstance(node, ast.AndOp | ast.OrOp):
        return [node.left]
    if isinstance(node, ast.Chain) and node.rest[0][0] in ("and", "or"):
        return [node.first]
    if isinstance(node, ast.Where):
        return [node.source]
    if isinstance(node, ast.Call) and (node.each is not None or node.default is not None):
        return list(node.args)
    return list(node.children())


def _fault(node: ast.Node, params) -> Exception | None:
    """The arithmetic fault computing `node` as a constant raises, if it is one."""
    from swarmdsl.compiler.consteval import NotConstant, const_value

    if not isinstance(node, ast.Expr):
        return None
    try:
        const_value(node, params)
    except (ArithmeticError, ValueError) as exc:
        return exc
    except (NotConstant, TypeError):   # per agent, or a type error reported already
        return None
    return None


def _overlaps(a, b) -> bool:
    return ((a.line, a.col) < (b.end_line, b.end_col)
            and (b.line, b.col) < (a.end_line, a.end_col))


def check_constant_faults(chk) -> None:
    """A constant part of an expression that cannot be computed (`5 / 0`, `log(-1)`,
    `normal(0 / 0, 1)`, a field's `initial 1 / 0`) is an error of `swarmdsl check`,
    at the smallest such part; the run would fault on it at its first tick. Places
    already reported (a param's value, a region's shape) are not reported again."""
    from swarmdsl.compiler.consteval import scoped_params

    stack: list[tuple[ast.Node, dict]] = [(chk.tree, chk.params)]
    while stack:
        node, params = stack.pop()
        params = scoped_params(node, params)
        exc = _fault(node, params)
        if exc is None:
            if isinstance(node, ast.AssignStmt) and node.op == "/=" \
                    and _constant_zero(node.value, params):
                _report(chk, node.value.span, "`/= 0` divides by zero")
            stack.extend((c, params) for c in _sure_children(node))
            continue
        inner = next((c for c in _sure_children(node) if _fault(c, params)), None)
        while inner is not None:
            node, exc = inner, _fault(inner, params)
            inner = next((c for c in _sure_children(node) if _fault(c, params)), None)
        _report(chk, node.span, f"cannot compute this constant: {exc}")



def check_clamp_bounds(chk) -> None:
    """`clamp(x, 3, 1)`: constant bounds the wrong way round give `hi` for every `x`
    (numpy's clip), never what was meant; refused as `uniform(5, 1)` is."""
    from swarmdsl.compiler.consteval import NotConstant, const_value, walk_with_params

    for node, params in walk_with_params(chk.tree, chk.params):
        if not (isinstance(node, ast.Call) and node.name == "clamp" and len(node.args) == 3
                and node.each is None and node.default is None):
            continue
        try:
            lo, hi = (const_value(a, params) for a in node.args[1:])
        except (NotConstant, ArithmeticError, ValueError, TypeError):
            continue
        if all(isinstance(v, int | float) and not isinstance(v, bool) for v in (lo, hi)) \
                and lo > hi:
            chk.fail(f"`clamp(x, lo, hi)` needs lo <= hi, got lo = {lo:g} and hi = {hi:g}",
                     node.span, f"put the smaller bound first: `clamp(x, {hi:g}, {lo:g})`")


def _constant_zero(e: ast.Expr, params) -> bool:
    from swarmdsl.compiler.consteval import NotConstant, const_value

    try:
        return const_value(e, params) == 0
    except (NotConstant, ArithmeticError, ValueError, TypeError):
        return False


def _report(chk, span, message: str) -> None:
    if any(e.span is not None and _overlaps(e.span, span) for e in chk.errors):
        return
    chk.fail(message, span, "it is a constant, so the run would fault wherever it is "
                            "computed")


checker.PROGRAM_CHECK_HOOKS.append(check_constant_faults)
checker.PROGRAM_CHECK_HOOKS.append(check_clamp_bounds)
