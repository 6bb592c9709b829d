"""Fields and regions declared: `field NAME { ... }` and `region`/`food`/`nest`/
`obstacle` declarations, checked against the world, and what the checker learns of
the environment (`EnvInfo`, `ProgramInfo.extra["env"]`).

Split from `lang_fields.py` (sensing, region tests, `deposit`, the runtime hook), which
re-exports what other modules import from it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from swarmdsl.compiler import ast, checker
from swarmdsl.compiler.builtins import NUM, TYPE_TEXT
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.errors import did_you_mean

# The runtime modules load where a program needs them (a region, a field, a run), so
# checking a program without them does not pay for their import.
if TYPE_CHECKING:
    from swarmdsl.runtime import regions as shapes

ERR = "error"
LABEL, LABELS = "label", "labels"
TYPE_TEXT.setdefault(LABEL, "a food label")
TYPE_TEXT.setdefault(LABELS, "a set of food labels")
REGION_KINDS = ("region", "food", "nest", "obstacle")

# Extra `field NAME { ... }` options: name -> fn(chk, env, decl, option). Physical twins
# (`lang_twins.py`) register `twin` here.
FIELD_OPTIONS: dict = {}
# Run after a field's options: fn(chk, env, decl, seen option names).
FIELD_DECL_HOOKS: list = []


@dataclass
class EnvInfo:
    """What the checker learns about the environment; `ProgramInfo.extra["env"]`."""

    fields: dict[str, ast.FieldDecl] = field(default_factory=dict)
    field_specs: dict[str, tuple[float, float, ast.Expr | None]] = field(default_factory=dict)
    regions: dict[str, shapes.Region] = field(default_factory=dict)
    memories: dict[str, dict[str, int]] = field(default_factory=dict)   # kind -> name -> K
    label_sets: dict[str, set] = field(default_factory=dict)            # kind -> names
    twins: dict[str, object] = field(default_factory=dict)   # name -> TwinInfo
    vector_fields: dict[str, ast.FieldDecl] = field(default_factory=dict)
    extra: dict = field(default_factory=dict)   # what other extensions hand the runtime
    used: bool = False                      # a call needs the runtime environment

    def needed(self) -> bool:
        return bool(self.used or self.fields or self.vector_fields or self.regions
                    or any(self.memories.values())
                    or any(self.label_sets.values()))

    def food_labels(self) -> list[str]:
        return [r.name for r in self.regions.values() if r.kind == "food"]


def env_info(chk) -> EnvInfo:
    return chk.extra.setdefault("env", EnvInfo())


# ---- declarations ----

def _declarations(chk) -> None:
    env = env_info(chk)
    for d in chk.tree.decls_of(ast.FieldDecl):
        _field_decl(chk, env, d)
    for d in chk.tree.decls_of(ast.RegionDecl):
        _region_decl(chk, env, d)
    food = env.food_labels()
    if not food:
        return
    from swarmdsl.runtime.memory import MAX_LABELS

    if len(food) > MAX_LABELS:
        chk.fail(f"at most {MAX_LABELS} food sources are supported",
                 chk.tree.decls_of(ast.RegionDecl)[-1].span)


def _rate(chk, opt: ast.Option, what: str, hi: float, why: str) -> float:
    if len(opt.args) != 1:
        chk.fail(f"`{opt.name}` takes one rate: `{opt.name} 0.05`", opt.span)
        return 0.0
    v = chk._const(opt.args[0], what)
    if v is None:
        return 0.0
    if isinstance(v, bool) or not isinstance(v, int | float):
        chk.fail(f"{what} must be a number", opt.args[0].span)
        return 0.0
    if not 0.0 <= v <= hi:
        chk.fail(f"{what} {v:g} {why}", opt.args[0].span)
        return 0.0
    return float(v)


def _field_decl(chk, env: EnvInfo, d: ast.FieldDecl) -> None:
    from swarmdsl.runtime.fields import MAX_STABLE_DIFFUSION

    decay, diffuse, init = 0.0, 0.0, None
    seen: set[str] = set()
    for opt in d.options:
        if opt.name in seen:
            chk.fail(f"option `{opt.name}` is already set for field `{d.name}`", opt.name_span)
            continue
        seen.add(opt.name)
        if opt.has_in:
            chk.fail(f"`{opt.name}` does not take `in`", opt.span)
        elif opt.name == "decay":
            decay = _rate(chk, opt, "the decay rate", 1.0,
                          "must be between 0 and 1 (the fraction lost per tick)")
        elif opt.name == "diffuse":
            diffuse = _rate(chk, opt, "the diffusion rate", MAX_STABLE_DIFFUSION,
                            f"is numerically unstable: it must be between 0 and "
                            f"{MAX_STABLE_DIFFUSION:g} on a 2-D grid")
        elif opt.name == "initial":
            if len(opt.args) != 1:
                chk.fail("`initial` takes one value or formula of `pos`", opt.span)
                continue
            init = opt.args[0]
            _check_formula(chk, init, d.name)
        elif opt.name in FIELD_OPTIONS:
            FIELD_OPTIONS[opt.name](chk, env, d, opt)
        else:
            chk.fail(f"unknown field option `{opt.name}`", opt.name_span,
                     did_you_mean(opt.name, ["decay", "diffuse", "initial",
                                             *FIELD_OPTIONS]))
    if not periodic_grid_fits(chk.world):
        chk.fail(f"field `{d.name}` needs a wrap-around world whose size is a whole "
                 f"multiple of the grid spacing ({chk.world.grid:g})", d.name_span)
    for hook in FIELD_DECL_HOOKS:
        hook(chk, env, d, seen)
    if d.name in env.vector_fields:
        return
    env.fields[d.name] = d
    env.field_specs[d.name] = (decay, diffuse, init)


def periodic_grid_fits(w) -> bool:
    """Whether the world's grid can be built: in a wrap-around world the grid is
    periodic (`runtime/fields.Grid`), so its size must be a whole number (at least one)
    of grid spacings."""
    if w.edges != "wrap":
        return True
    cells = w.width / w.grid, w.height / w.grid
    return all(c >= 1 - 1e-9 and abs(c - round(c)) <= 1e-9 * max(1.0, c) for c in cells)


def _grid_of_the_environment(chk) -> None:
    """Regions, memories and label sets need the world grid too (the run's environment
    is built on it): in a wrap-around world whose size is not a whole number of
    spacings, refused where the first of them is declared (a field says so itself)."""
    env = env_info(chk)
    w = chk.world
    if not env.needed() or env.fields or env.vector_fields or periodic_grid_fits(w):
        return
    what, span = _first_user_of_the_grid(chk, env)
    chk.fail(f"{what} needs a wrap-around world whose size is a whole multiple of the "
             f"grid spacing: {w.width:g} x {w.height:g} is {w.width / w.grid:g} x "
             f"{w.height / w.grid:g} spacings of {w.grid:g}", span,
             "give `grid` a spacing that divides the world's width and height")


def _first_user_of_the_grid(chk, env) -> tuple[str, object]:
    regions = [d for d in chk.tree.decls_of(ast.RegionDecl) if d.name in env.regions]
    if regions:
        return f"{regions[0].keyword} `{regions[0].name}`", regions[0].name_span
    for k in chk.kinds:
        for opt in k.decl.items_of(ast.Option):
            if opt.name in ("memory", "labels") and opt.args:
                return f"`{opt.name}` of `{k.name}`", opt.span
    world = chk.tree.decls_of(ast.WorldDecl)
    grid = [o for o in world[0].options if o.name in ("grid", "size")] if world else []
    return "the environment", (grid[0].span if grid else chk.tree.span)


def _check_formula(chk, expr: ast.Expr, name: str) -> None:
    from swarmdsl.compiler.info import AGENT_STATE
    from swarmdsl.compiler.scope import Scope

    for node in _walk(expr):
        if isinstance(node, ast.Name) and node.id in AGENT_STATE and node.id != "pos":
            chk.fail(f"a field's initial value is a formula of the node position `pos`; "
                     f"`{node.id}` is not known there", node.span)
            return
    t = chk.expr(expr, Scope(None, init=True))
    if t not in (NUM, ERR):
        chk.fail(f"the initial value of field `{name}` must be a number, got "
                 f"{TYPE_TEXT.get(t, t)}", expr.span)


_SHAPES = {"circle": (3, "circle(x, y, radius)"),
           "rect": (4, "rect(x0, y0, x1, y1)"),
           "polygon": (None, "polygon((x, y), (x, y), (x, y), ...)")}


def _walk(node):
    yield node
    for c in node.children():
        yield from _walk(c)


def _region_decl(chk, env: EnvInfo, d: ast.RegionDecl) -> None:
    s = d.shape
    if not isinstance(s, ast.Call) or s.name not in _SHAPES:
        chk.fail("a region is a shape: circle(x, y, r), rect(x0, y0, x1, y1) or "
                 "polygon((x, y), ...)", s.span,
                 did_you_mean(s.name, _SHAPES) if isinstance(s, ast.Call) else None)
        return
    arity, usage = _SHAPES[s.name]
    if (arity is not None and len(s.args) != arity) or s.each or s.default:
        chk.fail(f"`{s.name}` takes {arity} numbers: `{usage}`", s.span)
        return
    try:
        vals = [const_value(a, chk.params) for a in s.args]
    except NotConstant as exc:
        chk.fail("a region's shape must be constant (numbers and params only)",
                 exc.node.span)
        return
    except (ArithmeticError, ValueError, TypeError) as exc:
        chk.fail(f"cannot compute the region's shape: {exc}", s.span)
        return
    want_vec = s.name == "polygon"
    for a, v in zip(s.args, vals, strict=True):
        if want_vec != isinstance(v, tuple) or isinstance(v, bool | str):
            chk.fail(f"`{s.name}` takes {'points (x, y)' if want_vec else 'numbers'}: "
                     f"`{usage}`", a.span)
            return
    from swarmdsl.runtime import regions as shapes

    try:
        shape = {"circle": shapes.Circle, "rect": shapes.Rect}[s.name](*vals) \
            if not want_vec else shapes.Polygon(tuple(vals))
    except ValueError as exc:
        chk.fail(str(exc), s.span)
        return
    kind = d.keyword
    env.regions[d.name] = shapes.Region(d.name, kind, d.name if kind == "food" else None,
                                        shape)


checker.DECL_HOOKS.append(_declarations)
checker.PROGRAM_CHECK_HOOKS.append(_grid_of_the_environment)
