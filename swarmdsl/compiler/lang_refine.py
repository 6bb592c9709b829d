"""Refined grids in the language: `world { refine SHAPE [LEVELS] }`.

`SHAPE` is `rect(x0, y0, x1, y1)`, `circle(x, y, r)` or the name of a declared region;
`LEVELS` (default 1, at most 4) halves the spacing that many times there. The option
may repeat. Fields then live on every node of the refined grid
(`runtime/refined_grid.py`, which documents the scheme).
"""

from __future__ import annotations

from swarmdsl.compiler import ast, checker, lang_fields, options
from swarmdsl.limits import MAX_GRID_NODES

_USAGE = "`refine rect(x0, y0, x1, y1) LEVELS`, `refine circle(x, y, r) LEVELS` or " \
         "`refine REGION LEVELS`"


def _refine_option(chk, opt: ast.Option, world) -> None:
    chk.extra.setdefault("refine", []).append(opt)


_refine_option.repeatable = True   # several refined regions: one `refine` each
options.WORLD_OPTIONS["refine"] = _refine_option


def _shape(chk, env, a: ast.Expr):
    if isinstance(a, ast.Name):
        region = env.regions.get(a.id)
        if region is None:
            chk.fail(f"unknown region `{a.id}` to refine", a.span,
                     f"declare it (`region {a.id} = rect(...)`) or write the shape here")
            return None
        return region.shape
    if not isinstance(a, ast.Call) or a.name not in ("rect", "circle") or a.each or \
            a.default or len(a.args) != (4 if a.name == "rect" else 3):
        chk.fail(f"a refined region is {_USAGE}", a.span)
        return None
    vals = [chk._const(x, "a refined region") for x in a.args]   # finite, within limits
    if any(v is None for v in vals):
        return None
    if any(isinstance(v, bool | str | tuple) for v in vals):
        chk.fail(f"a refined region is {_USAGE}", a.span)
        return None
    from swarmdsl.runtime import regions as shapes

    try:
        return (shapes.Rect if a.name == "rect" else shapes.Circle)(*vals)
    except ValueError as exc:
        chk.fail(str(exc), a.span)
        return None


def _levels(chk, opt):
    if len(opt.args) == 1:
        return 1
    from swarmdsl.runtime.refined_grid import MAX_LEVELS

    v = chk._const(opt.args[1], "the number of refinement levels")
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int | float) or v != int(v) or \
            not 1 <= v <= MAX_LEVELS:
        chk.fail(f"the number of refinement levels is a whole number from 1 to "
                 f"{MAX_LEVELS}, got {v}", opt.args[1].span)
        return None
    return int(v)


def _declarations(chk) -> None:
    opts = chk.extra.get("refine", [])
    if not opts:
        return
    env = lang_fields.env_info(chk)
    w = chk.world
    out = []
    for opt in opts:
        if opt.has_in or not 1 <= len(opt.args) <= 2:
            chk.fail(f"`refine` takes a region and a number of levels: {_USAGE}", opt.span)
            continue
        if w.edges == "wrap":
            chk.fail("a wrap-around world cannot be refined", opt.name_span,
                     "use `edges wall` or `edges repel`")
            continue
        shape, levels = _shape(chk, env, opt.args[0]), _levels(chk, opt)
        if shape is None or levels is None:
            continue
        x0, y0, x1, y1 = shape.bounds()
        if x0 >= w.width or y0 >= w.height or x1 <= 0 or y1 <= 0 or shape.area() == 0:
            where = "has no area" if shape.area() == 0 else (
                f"lies outside the world (0, 0) to ({w.width:g}, {w.height:g})")
            chk.fail(f"this refined region {where}: it would refine no cell", opt.args[0].span)
            continue
        cells = (min(x1, w.width) - max(x0, 0) + 2 * w.grid) * \
            (min(y1, w.height) - max(y0, 0) + 2 * w.grid) / w.grid ** 2
        nodes = max(cells, 0) * 4 ** levels
        if nodes > MAX_GRID_NODES:
            chk.fail(f"refining this region {levels} time{'s' if levels > 1 else ''} adds "
                     f"about {nodes:,.0f} grid nodes; fields are limited to "
                     f"{MAX_GRID_NODES:,} nodes", opt.span, "use fewer levels")
            continue
        out.append((shape, levels))
    if out:
        env.extra["refinements"] = out
        env.used = True


checker.DECL_HOOKS.append(_declarations)


def _spec_hook(info, env, spec, gen) -> None:
    spec.refinements = list(env.extra.get("refinements", []))


lang_fields.ENV_SPEC_HOOKS.append(_spec_hook)
