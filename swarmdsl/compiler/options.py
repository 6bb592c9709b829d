"""The `name args...` options of `world { }` and `agent { }` blocks, and their checks.

Each option is one entry in a table, so adding one (a robot profile, a memory) is one
entry here and one use in codegen.
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import NUM, REGION, STATUS, TYPE_TEXT, VEC
from swarmdsl.compiler.info import EDGE_MODES
from swarmdsl.errors import did_you_mean
from swarmdsl.limits import MIN_WORLD_SIZE, over, upper


@dataclass(frozen=True)
class OptionSpec:
    """`early` runs while options are read (constants); `late` once variables exist.
    `declares`: the option's first value names something the kind's code reads (a map,
    a memory, a label set), so a refused option is where that name's uses went wrong."""

    early: object
    late: object = None
    doc: str = ""
    declares: bool = False

    def __call__(self, checker, opt, target):
        if opt.has_in and not getattr(self.early, "accepts_in", False):
            checker.fail(f"`{opt.name}` does not take `in`", opt.span)
        return self.early(checker, opt, target)


def _arity(checker, opt: ast.Option, n: int, usage: str) -> bool:
    if len(opt.args) != n:
        signed = any(isinstance(a, ast.Neg) for a in opt.args[1:])
        checker.fail(f"`{opt.name}` takes {n} value{'s' if n != 1 else ''}: `{usage}`",
                     opt.span, "values are separated by spaces, so `n -1` is two values; "
                     "write `n - 1` to subtract" if signed else None)
        return False
    return True


def _positive(checker, expr, what: str, integer=False, allow_zero=False, limit=None):
    """A constant that is positive (or 0), finite and within the option's limit."""
    v = checker._const(expr, what)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int | float):
        checker.fail(f"{what} must be a number", expr.span)
        return None
    if integer and float(v) != int(v):
        checker.fail(f"{what} must be a whole number, got {v}", expr.span)
        return None
    if v < 0 or (v == 0 and not allow_zero):
        checker.fail(f"{what} must be {'at least 0' if allow_zero else 'positive'}, got {v}",
                     expr.span)
        return None
    problem = over(limit, v) if limit else None
    if problem:
        checker.fail(problem, expr.span, "see the limits in docs/limits.md")
        return None
    return int(v) if integer else float(v)


# ---- world ----

def _size(checker, opt, world):
    args = list(opt.args)
    if len(args) == 3 and isinstance(args[1], ast.Name) and args[1].id == "x":
        args = [args[0], args[2]]
    elif len(args) == 2 and _is_x_call(args[1]):   # `size 40 x (a * 2)` reads as `x(...)`
        args = [args[0], args[1].args[0]]
    if len(args) != 2:
        checker.fail("`size` takes a width and a height: `size 800 x 600`", opt.span)
        return
    w = _positive(checker, args[0], "the world's width", limit="size")
    h = _positive(checker, args[1], "the world's height", limit="size")
    for side, value, arg in (("width", w, args[0]), ("height", h, args[1])):
        if value is not None and value < MIN_WORLD_SIZE:
            checker.fail(f"the world's {side} must be at least {MIN_WORLD_SIZE:g}, got "
                         f"{value:g}", arg.span, "see the limits in docs/limits.md")
            w = h = None
    if w is not None and h is not None:
        world.width, world.height = w, h


def _is_x_call(e) -> bool:
    """`x (a * 2)`: the separator `x` and a bracketed height parse as a call of `x`."""
    return (isinstance(e, ast.Call) and e.name == "x" and len(e.args) == 1
            and e.each is None and e.default is None)


def _grid(checker, opt, world):
    if _arity(checker, opt, 1, "grid SPACING"):
        g = _positive(checker, opt.args[0], "the grid spacing", limit="grid")
        if g is not None:
            world.grid = g


def _edges(checker, opt, world):
    if not opt.args or not isinstance(opt.args[0], ast.Name):
        checker.fail("`edges` takes a mode: `edges wall`, `edges wrap` or "
                     "`edges repel WEIGHT [RANGE]`", opt.span)
        return
    mode = opt.args[0].id
    if mode not in EDGE_MODES:
        checker.fail(f"unknown edge mode `{mode}`", opt.args[0].span,
                     did_you_mean(mode, EDGE_MODES) or "use wall, wrap or repel")
        return
    world.edges = mode
    rest = opt.args[1:]
    if mode != "repel" and rest:
        checker.fail(f"`edges {mode}` takes no values", rest[0].span)
        return
    if len(rest) > 2:
        checker.fail("`edges repel` takes a weight and an optional range", rest[2].span)
        return
    if rest:
        w = _positive(checker, rest[0], "the edge repulsion weight", allow_zero=True,
                      limit="edges")
        world.edge_weight = w if w is not None else 1.0
    if len(rest) == 2:
        world.edge_range = _positive(checker, rest[1], "the edge repulsion range",
                                      limit="edges")


def _steps(checker, opt, world):
    if _arity(checker, opt, 1, "steps N"):
        n = _positive(checker, opt.args[0], "the number of steps", integer=True,
                      allow_zero=True, limit="steps")
        if n is not None:
            world.steps = n


# name -> fn(checker, option, world). An option is given once per world, unless its
# function is marked `repeatable = True` (`refine`, one per refined region).
WORLD_OPTIONS = {
    "size": _size,
    "grid": _grid,
    "edges": _edges,
    "steps": _steps,
}


# ---- agent kinds ----

MAX_AGENTS = upper("count")   # ~2.4 GB of core state; beyond that a run cannot fit in memory


def _count(checker, opt, kind):
    if _arity(checker, opt, 1, "count N"):
        n = _positive(checker, opt.args[0], f"the count of `{kind.name}`", integer=True,
                      allow_zero=True)
        if n is not None and n > MAX_AGENTS:
            checker.fail(f"the count of `{kind.name}` is {n:,}; a run holds at most "
                         f"{MAX_AGENTS:,} agents", opt.args[0].span)
            n = 0
        kind.count = n or 0


def _sense(checker, opt, kind):
    if _arity(checker, opt, 1, "sense RADIUS"):
        v = _positive(checker, opt.args[0], "the sense radius", limit="sense")
        kind.sense = v


def _robot(checker, opt, kind):
    from swarmdsl.compiler.profiles import PROFILES

    if not _arity(checker, opt, 1, "robot NAME") or not isinstance(opt.args[0], ast.Name):
        return
    name = opt.args[0].id
    if name not in PROFILES and name not in checker.robot_names():
        checker.fail(f"unknown robot profile `{name}`", opt.args[0].span,
                     did_you_mean(name, list(PROFILES) + checker.robot_names()))
        return
    kind.robot = name


def _place_early(checker, opt, kind):
    if len(opt.args) != 1:
        checker.fail("`place` takes one value: `place uniform`, `place (x, y)` or "
                     "`place in REGION`", opt.span)


_place_early.accepts_in = True


def _place_late(checker, opt, kind, scope):
    arg = opt.args[0]
    if opt.has_in:
        t = checker.expr(arg, scope)
        if t not in (REGION, "error"):
            checker.fail(f"`place in` needs a region, got {TYPE_TEXT.get(t, t)}", arg.span)
        return
    if isinstance(arg, ast.Name) and arg.id == "uniform":
        checker.facts.set_name(arg, ("uniform",))
        return
    checker.expect(arg, VEC, scope, "a placement")


def _expr_late(want: str, what: str):
    def late(checker, opt, kind, scope):
        if _arity(checker, opt, 1, f"{opt.name} EXPR"):
            checker.expect(opt.args[0], want, scope, what)
    return late


def _known(checker, expr):
    """The value of an option's expression when it is known at check time (constants
    and params at their values), else None; non-finite constants are refused elsewhere
    (`resources.check_constant_values`)."""
    from swarmdsl.compiler.consteval import NotConstant, const_value

    try:
        return const_value(expr, checker.params)
    except (NotConstant, ArithmeticError, ValueError, TypeError):
        return None


def refuse_negative(checker, expr, what: str) -> None:
    """Report `what` if `expr` is a constant below 0 (a speed, a reach, a margin): a
    value known only per agent is the run's business."""
    v = _known(checker, expr)
    if isinstance(v, int | float) and not isinstance(v, bool) and v < 0:
        checker.fail(f"{what} must be 0 or more, got {v:g}", expr.span)


def _max_speed_late(checker, opt, kind, scope):
    if not _arity(checker, opt, 1, "max_speed EXPR"):
        return
    if checker.expect(opt.args[0], NUM, scope, "the maximum speed") != NUM:
        return
    # the same words as the run's own check of a per-agent value (simulation.py)
    refuse_negative(checker, opt.args[0], f"the max_speed of `{kind.name}`")


def _initial_early(checker, opt, kind):
    _arity(checker, opt, 1, "initial STATUS")


def _initial_late(checker, opt, kind, scope):
    arg = opt.args[0]
    if isinstance(arg, ast.Name) and arg.id not in kind.status_decls:
        checker.fail(f"unknown status `{arg.id}` in agent `{kind.name}`", arg.span,
                     did_you_mean(arg.id, kind.statuses))
        return
    checker.expect(arg, STATUS, scope, "the initial status")


def _one_arg(checker, opt, kind):
    _arity(checker, opt, 1, f"{opt.name} EXPR")


AGENT_OPTIONS = {
    "count": OptionSpec(_count, doc="how many agents of this kind (a constant)"),
    "place": OptionSpec(_place_early, _place_late, "where agents start"),
    "velocity": OptionSpec(_one_arg, _expr_late(VEC, "the initial velocity"),
                           "initial velocity (per agent)"),
    "heading": OptionSpec(_one_arg, _expr_late(NUM, "the initial heading"),
                          "initial heading in radians when the velocity is zero"),
    "sense": OptionSpec(_sense, doc="sense radius: caps every neighbour query"),
    "max_speed": OptionSpec(_one_arg, _max_speed_late, "speed limit applied every tick"),
    "initial": OptionSpec(_initial_early, _initial_late, "the starting status"),
    "robot": OptionSpec(_robot, doc="the robot profile: what the agent can sense"),
}

__all__ = ["AGENT_OPTIONS", "WORLD_OPTIONS", "OptionSpec"]
