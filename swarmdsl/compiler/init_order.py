"""The order in which a kind's initial values are computed when its agents are placed.

`place`, `velocity`, `heading` and `max_speed` may read the kind's variables (`attr r0 =
50 + 10 * index; place (r0, 100)`), and a variable's initial value may read what those
options set (`var home = pos`). Each step runs once what it reads is known: in the
written order (place, velocity, heading, max_speed, then the variables as declared),
except that a step waits for the steps it reads. Random draws are keyed by their call
site, not drawn in sequence, so moving a step earlier changes none of them. Steps that
read each other round in a circle (`place` reading a variable whose value reads `pos`)
are a located error of the checker, naming the circle.
"""

from __future__ import annotations

from swarmdsl.compiler import ast, checker
from swarmdsl.compiler.builtins import FUNCTIONS
from swarmdsl.compiler.facts import Facts

OPTION_STEPS = ("place", "velocity", "heading", "max_speed")
# the agent column a step sets -> the step (`heading` follows the velocity)
_SETS = {"pos": "place", "vel": "velocity", "heading": "heading", "max_speed": "max_speed"}
# Calls beyond the plain functions that still read nothing but their arguments: a
# network's output is a function of its inputs alone (so `place (nn(...), 100)` runs).
_ARGUMENTS_ONLY = {"nn"}


def _reads(expr: ast.Expr | None, facts: Facts) -> list[tuple[str, str]]:
    """The steps `expr` reads: ("var", NAME) for a variable, ("option", STEP) for what
    an option sets. A call that is not a plain function (`sample(F)`, `inside(R)`,
    `nn(...)`) may read the agent's position and velocity without naming them."""
    out: list[tuple[str, str]] = []
    if expr is None:
        return out
    for node in ast.walk(expr):
        if isinstance(node, ast.Name):
            res = facts.name_of(node)
            if res is None:
                continue
            if res[0] == "var":
                out.append(("var", res[1]))
            elif res[0] == "state" and res[1] in _SETS:
                out.append(("option", _SETS[res[1]]))
        elif (isinstance(node, ast.Call) and node.name not in FUNCTIONS
              and node.name not in _ARGUMENTS_ONLY):
            out += [("option", "place"), ("option", "velocity")]
    return out


def _option_expr(kind, name: str) -> ast.Expr | None:
    opt = kind.options.get(name)
    if opt is None or not opt.args:
        return None
    if name == "place" and (opt.has_in or (isinstance(opt.args[0], ast.Name)
                                           and opt.args[0].id == "uniform")):
        return None
    return opt.args[0]


def init_steps(kind, facts: Facts) -> tuple[list, dict, dict]:
    """The steps in their written order, what each reads, and where each is written."""
    steps: list[tuple[str, str]] = [("option", s) for s in OPTION_STEPS]
    steps += [("var", v) for v in kind.vars]
    reads, spans = {}, {}
    for s in OPTION_STEPS:
        expr = _option_expr(kind, s)
        reads[("option", s)] = _reads(expr, facts)
        spans[("option", s)] = kind.options[s].span if s in kind.options else None
    reads[("option", "heading")].append(("option", "velocity"))   # set from it
    for v in kind.vars.values():
        reads[("var", v.name)] = _reads(v.decl.value, facts)
        spans[("var", v.name)] = v.decl.span
    known = set(steps)   # a name refused elsewhere is no step to wait for
    return steps, {s: [r for r in rs if r in known] for s, rs in reads.items()}, spans


def order(kind, facts: Facts) -> tuple[list, list | None]:
    """The steps in the order they run, and a circle of steps that read each other (or
    None). Each step runs as soon as all it reads has; among ready steps, the written
    order decides."""
    steps, reads, _spans = init_steps(kind, facts)
    done: set = set()
    out: list = []
    while len(out) < len(steps):
        ready = next((s for s in steps
                      if s not in done and all(r in done for r in reads[s])), None)
        if ready is None:
            return out, _circle(steps, reads, done)
        done.add(ready)
        out.append(ready)
    return out, None


def _circle(steps, reads, done) -> list:
    """A path of steps, each reading the next, that comes back to where it started."""
    path = [next(s for s in steps if s not in done)]
    while True:
        nxt = next(r for r in reads[path[-1]] if r not in done)
        if nxt in path:
            return path[path.index(nxt):] + [nxt]
        path.append(nxt)


def _name(step) -> str:
    return f"`{step[1]}`"


def _read(step) -> str:
    """What a reader of `step` names: the position for `place`, else the step's name."""
    return "`pos`" if step == ("option", "place") else f"`{step[1]}`"


def _check(chk, kind) -> None:
    """Order the kind's initial values; a circle is an error at its first step."""
    steps, circle = order(kind, chk.facts)
    chk.extra.setdefault("init_order", {})[kind.name] = steps
    if circle is None:
        return
    _steps, _reads, spans = init_steps(kind, chk.facts)
    where = spans[circle[0]] or kind.decl.span
    if len(circle) == 2:     # a step reading what it sets itself
        chk.fail(f"{_name(circle[0])} reads {_read(circle[0])}, which it sets itself",
                 where, "an initial value cannot depend on itself")
        return
    parts = [f"{_name(a)} reads {_read(b)}" + (f", which {_name(b)} sets"
                                               if b[0] == "option" else "")
             for a, b in zip(circle, circle[1:], strict=False)]
    chk.fail(f"these initial values need each other: {'; '.join(parts)}", where,
             "an option may read variables whose initial values do not read what it sets")


checker.KIND_HOOKS.append(_check)
