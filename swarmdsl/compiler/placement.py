"""Where agents start: a `place` known at check time is checked against the world.

A constant point (or one per agent from `index` and params) and the regions of `place in
REGION` are known before a run. Wholly outside the world is an error (no agent could
start in it); partly outside is a warning (a nest in a corner, a row of agents longer
than the world); a region with no area cannot hold an agent. A wrap-around world has
no outside for a region: it repeats a whole world away, so some copy lies in the world
and agents drawn in the region start at the matching point of it. A region declared
wholly outside a bounded world is a warning at its declaration.
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.compiler import ast, checker
from swarmdsl.compiler.builtins import VEC
from swarmdsl.compiler.consteval import NotConstant, const_value

# `place (10 * index, 50)` is evaluated per agent at check time up to this many agents.
MAX_EVALUATED = 10_000

_FAULTS = (NotConstant, ArithmeticError, ValueError, TypeError)


def check_placement(chk, kind) -> None:
    """KIND_HOOKS entry: the kind's placement, when known, lies in the world and not
    where obstacles would hold its agents still."""
    opt = kind.options.get("place")
    if _world_covered(chk, kind, opt):
        return
    if opt is None or len(opt.args) != 1:
        return
    arg = opt.args[0]
    if opt.has_in:
        _regions(chk, kind, arg)
    elif chk.facts.type_of(arg) == VEC:
        _points(chk, kind, arg)


def _world_text(chk) -> str:
    return f"{chk.world.width:g} x {chk.world.height:g}"


def _hint(chk) -> str:
    w = chk.world
    return (f"the world spans (0, 0) to ({w.width:g}, {w.height:g}); move the placement "
            "or enlarge the world (`world { size W x H }`)")


def _inside(chk, x: float, y: float) -> bool:
    return 0 <= x <= chk.world.width and 0 <= y <= chk.world.height


def _point(value) -> tuple[float, float] | None:
    if not isinstance(value, tuple) or len(value) != 2:
        return None
    x, y = value
    if not (math.isfinite(x) and math.isfinite(y)):
        return None   # refused as a constant elsewhere, or a located fault when placing
    return float(x), float(y)


def _points(chk, kind, arg: ast.Expr) -> None:
    try:
        value = const_value(arg, chk.params)
    except NotConstant:
        value = None
    except (ArithmeticError, ValueError, TypeError):
        return   # refused where every constant is checked
    if chk.world.edges == "wrap":
        return   # a torus has no outside: a point beyond an edge starts across it
    if value is not None:
        p = _point(value)
        if p is not None and not _inside(chk, *p):
            chk.fail(f"agents of `{kind.name}` would start at ({p[0]:g}, {p[1]:g}), "
                     f"outside the world ({_world_text(chk)})", arg.span, _hint(chk))
        elif p is not None:
            _blocked_points(chk, kind, arg, [(0, p)], kind.count)
        return
    if not 0 < kind.count <= MAX_EVALUATED:
        return
    outside, inside = [], []
    for i in range(kind.count):   # a point per agent from `index` and params
        try:
            p = _point(const_value(arg, {**chk.params, "index": i}))
        except _FAULTS:
            return
        if p is None:
            return
        if not _inside(chk, *p):
            outside.append((i, p))
        else:
            inside.append((i, p))
    _blocked_points(chk, kind, arg, inside, len(inside))
    if not outside:
        return
    i, (x, y) = outside[0]
    if len(outside) == kind.count:
        chk.fail(f"every agent of `{kind.name}` would start outside the world "
                 f"({_world_text(chk)}): index {i} at ({x:g}, {y:g})", arg.span,
                 _hint(chk))
    else:
        chk.warn(f"{len(outside)} of {kind.count} agents of `{kind.name}` would start "
                 f"outside the world ({_world_text(chk)}), the first (index {i}) at "
                 f"({x:g}, {y:g})", arg.span, _hint(chk))


def _regions(chk, kind, arg: ast.Expr) -> None:
    res = chk.facts.name_of(arg)
    env = chk.extra.get("env")
    if res is None or res[0] != "region" or env is None:
        return
    name = res[1]
    chosen = [env.regions[name]] if name in env.regions else \
        [r for r in env.regions.values() if r.kind == name]
    if not chosen:
        return
    if _no_area(chosen):
        what = f"region `{name}` has" if len(chosen) == 1 else f"the `{name}` regions have"
        chk.fail(f"{what} no area: agents of `{kind.name}` cannot be placed in it",
                 arg.span)
        return
    _blocked_region(chk, kind, arg, name, chosen)
    if chk.world.edges == "wrap":
        return   # every region has a copy in a torus: agents start in it, wrapped
    where = [(r, _overlap(chk, r.shape)) for r in chosen]
    if all(o == "outside" for _r, o in where):
        what, it = (f"region `{name}` lies", "it") if len(chosen) == 1 else \
            (f"every `{name}` region lies", "them")
        chk.fail(f"{what} outside the world ({_world_text(chk)}): agents of "
                 f"`{kind.name}` placed in {it} would start outside", arg.span, _hint(chk))
        return
    for r, o in where:
        if o != "inside":
            chk.warn(f"region `{r.name}` {'reaches' if o == 'partly' else 'lies'} outside "
                     f"the world ({_world_text(chk)}): some agents of `{kind.name}` "
                     "placed in it would start outside", arg.span, _hint(chk))
            return


# ---- obstacles: a move that ends inside one is cancelled ----

_STUCK_HINT = ("a move that would end inside an obstacle is cancelled, so an agent that "
               "starts inside one stays there until a single step takes it out")


def _obstacles(chk) -> list:
    env = chk.extra.get("env")
    return [] if env is None else [r for r in env.regions.values() if r.kind == "obstacle"]


def _holding(obstacles, pts: np.ndarray) -> np.ndarray:
    """``(M,)`` index into `obstacles` of the first one holding each point, -1 if none."""
    held = np.full(len(pts), -1)
    for k, obstacle in enumerate(obstacles):
        held[(held < 0) & obstacle.shape.contains(pts)] = k
    return held


def _world_covered(chk, kind, opt) -> bool:
    """Obstacles that cover the whole world leave agents nowhere to start or move: an
    error at the kind's placement (its name when it has none). A lattice of points over
    the world, edges included, stands for the world."""
    obstacles = _obstacles(chk)
    if not obstacles:
        return False
    xs = np.linspace(0.0, chk.world.width, 65)
    ys = np.linspace(0.0, chk.world.height, 65)
    lattice = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    held = _holding(obstacles, lattice)
    if (held < 0).any():
        return False
    names = ", ".join(f"`{obstacles[k].name}`" for k in sorted(set(held.tolist())))
    span = opt.span if opt is not None else kind.decl.name_span
    chk.fail(f"obstacles cover the whole world ({_world_text(chk)}): agents of "
             f"`{kind.name}` would start inside {names} and could never move", span,
             "shrink the obstacle or enlarge the world")
    return True


def _blocked_points(chk, kind, arg, placed, count: int) -> None:
    """Warn when constant starting points lie inside an obstacle. `placed`: (index,
    point) pairs; a single pair stands for all `count` agents."""
    obstacles = _obstacles(chk)
    if not obstacles or not placed:
        return
    held = _holding(obstacles, np.array([p for _i, p in placed], dtype=np.float64))
    hit = np.flatnonzero(held >= 0)
    if hit.size == 0:
        return
    i, (x, y) = placed[hit[0]]
    n = count if len(placed) == 1 else hit.size
    which = "" if len(placed) == 1 else f", the first (index {i})"
    chk.warn(f"{n} of {kind.count} agents of `{kind.name}` would start inside obstacle "
             f"`{obstacles[held[hit[0]]].name}`{which} at ({x:g}, {y:g})", arg.span,
             _STUCK_HINT)


def _blocked_region(chk, kind, arg, name: str, chosen) -> None:
    """Warn when `place in R` draws from a region an obstacle wholly covers (judged on
    a fixed sample of the region's points)."""
    obstacles = _obstacles(chk)
    if not obstacles:
        return
    rng = np.random.default_rng(0)
    for region in chosen:
        if region.shape.area() == 0:
            continue
        held = _holding(obstacles, region.shape.sample_points_inside(rng, 256))
        if (held >= 0).all():
            what = "is an obstacle" if region.kind == "obstacle" else \
                f"lies inside obstacle `{obstacles[held[0]].name}`"
            chk.warn(f"region `{region.name}` {what}: agents of `{kind.name}` placed in "
                     "it would start inside", arg.span, _STUCK_HINT)
            return


def _no_area(chosen) -> bool:
    """True when the run could not draw a point: several regions of no area in all
    (drawn in proportion to area), or one whose box has area but it has none."""
    if len(chosen) > 1:
        return sum(r.shape.area() for r in chosen) == 0
    x0, y0, x1, y1 = chosen[0].shape.bounds()
    return chosen[0].shape.area() == 0 and (x1 - x0) * (y1 - y0) > 0


def _overlap(chk, shape) -> str:
    """"inside", "partly" or "outside" the world (closed shapes, closed world)."""
    w, h = chk.world.width, chk.world.height
    x0, y0, x1, y1 = shape.bounds()
    if x0 >= 0 and y0 >= 0 and x1 <= w and y1 <= h:
        return "inside"
    if x1 < 0 or y1 < 0 or x0 > w or y0 > h:
        return "outside"
    from swarmdsl.runtime import regions as shapes  # loaded: `shape` is one of them

    if isinstance(shape, shapes.Circle):
        dx = max(-shape.cx, 0.0, shape.cx - w)
        dy = max(-shape.cy, 0.0, shape.cy - h)
        return "partly" if math.hypot(dx, dy) <= shape.r else "outside"
    if isinstance(shape, shapes.Polygon):
        return "partly" if _polygon_meets_box(shape, w, h) else "outside"
    return "partly"   # a rect whose box meets the world's meets it


def _polygon_meets_box(poly, w: float, h: float) -> bool:
    """Whether a polygon and the box [0, w] x [0, h] share a point."""
    pts = poly.points
    if any(0 <= x <= w and 0 <= y <= h for x, y in pts):
        return True
    corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)]
    if poly.contains(corners).any():
        return True
    return any(_segment_meets_box(a, b, w, h) for a, b in zip(pts, pts[1:] + pts[:1],
                                                                 strict=True))


def _segment_meets_box(a, b, w: float, h: float) -> bool:
    """Liang-Barsky: whether segment a-b has a point in [0, w] x [0, h]."""
    t0, t1 = 0.0, 1.0
    dx, dy = b[0] - a[0], b[1] - a[1]
    for p, q in ((-dx, a[0]), (dx, w - a[0]), (-dy, a[1]), (dy, h - a[1])):
        if p == 0:
            if q < 0:
                return False
            continue
        t = q / p
        if p < 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 > t1:
            return False
    return True


def check_regions_in_world(chk) -> None:
    """PROGRAM_CHECK_HOOKS entry: a region, food source, nest or obstacle wholly outside
    a bounded world is warned about where it is declared: agents stay in the world, so
    none can ever stand in it or touch it (its distance can still guide them, so it is
    not refused). A wrap-around world has no outside."""
    env = chk.extra.get("env")
    if env is None or chk.world.edges == "wrap":
        return
    for d in chk.tree.decls_of(ast.RegionDecl):
        r = env.regions.get(d.name)
        if r is not None and not _no_area([r]) and _overlap(chk, r.shape) == "outside":
            chk.warn(f"{d.keyword} `{d.name}` lies wholly outside the world "
                     f"({_world_text(chk)}): no agent can ever stand in it",
                     d.name_span, f"the world spans (0, 0) to ({chk.world.width:g}, "
                     f"{chk.world.height:g})")


checker.KIND_HOOKS.append(check_placement)
checker.PROGRAM_CHECK_HOOKS.append(check_regions_in_world)
