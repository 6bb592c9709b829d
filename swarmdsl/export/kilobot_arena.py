"""The world's edges on a Kilobot: what the robots meet at the edge of the world, the
same in swarmdsl and in Kilombo.

Kilombo has no walls: its robots wander off a table of any size. A `wall` world (the
default) is carried into the Kilombo build as an arena (Kilombo's obstacles callback)
that does what swarmdsl's walls do: a robot's centre that crossed an edge is put back
as far inside, and its heading turned back, as swarmdsl reflects an agent's position
and velocity. A real robot meets a physical wall instead, which stops it rather than
turning it back, so a program whose robots move is warned, at the world, of that
difference and of the arena to build. A `wrap` world (a torus: no table is one) and
`repel` edges (forces from points along the edge, which a Kilobot cannot sense) are
refused, located.
"""

from __future__ import annotations

from swarmdsl.compiler import ast
from swarmdsl.errors import SwarmError
from swarmdsl.export.kilobot_c import Refusal, number

BODY = 33     # a Kilobot's diameter, mm


def world_decl(info):
    """The program's `world { ... }` declaration, or None."""
    return next((d for d in info.tree.decls if isinstance(d, ast.WorldDecl)), None)


def _edges_span(info):
    decl = world_decl(info)
    if decl is None:
        return info.kinds[0].decl.name_span
    option = next((o for o in decl.options if o.name == "edges"), None)
    return option.span if option is not None else decl.span


def refusals(info) -> list[Refusal]:
    """`wrap` and `repel` edges, refused at the world's `edges` line."""
    edges = info.world.edges
    if edges == "wrap":
        return [Refusal("a wrap-around world (`edges wrap`)", _edges_span(info),
                        "robots on a table meet its edge: use `edges wall` (the default) "
                        "for an arena, or a world large enough that they never reach it")]
    if edges == "repel":
        return [Refusal("`edges repel` (forces from points along the world's edge)",
                        _edges_span(info),
                        "a Kilobot senses no edge: use `edges wall` (the default), an "
                        "arena its robots bump into")]
    return []


def warnings(info, moves: bool) -> list[SwarmError]:
    """A program whose robots move, in a walled world: what real robots meet there."""
    if not moves or info.world.edges != "wall":
        return []
    w, h = info.world.width, info.world.height
    return [SwarmError(
        f"the world's walls ({w:g} x {h:g}) are an arena on Kilobots: swarmdsl and the "
        "exported Kilombo build turn a robot back at them (its position and heading "
        "reflected), a real robot pressed against a wall stops or slides along it "
        "until its program turns it (target kilobot)", _edges_span(info),
        f"build the arena's walls {w + BODY:g} x {h + BODY:g} mm (a robot's centre then "
        f"stays within {w:g} x {h:g}), or give the world room enough that no robot "
        "reaches its edge", severity="warning")]


def kilombo_arena(info) -> str:
    """The C of Kilombo's arena for a walled world (in the Kilombo build only: on a
    robot the arena is the experimenter's), registered in main() by `SET_CALLBACK`.
    Kilombo's y axis points down (bots.json mirrors y), so the world's y is -y here,
    and its heading is measured from +y clockwise (x += sin, y += cos)."""
    if info.world.edges != "wall":
        return ""
    w, h = number(info.world.width, None), number(info.world.height, None)
    return f"""
#ifndef KB_KILOLIB
#include <kilombo/skilobot.h>
/* The world's walls as Kilombo's arena, as swarmdsl's walls: a centre beyond an edge
 * is reflected back inside and the heading turned to point in (swarmdsl reflects the
 * position and turns the velocity's component). The callback is given a position:
 * the robot is the one there. */
#define KB_ARENA_W ((double){w})
#define KB_ARENA_H ((double){h})
static int16_t kb_arena(double x, double y, double *dx, double *dy)
{{
    double nx = x, ny = y;
    int in_x = 0, in_y = 0;   /* the heading's x (sin) and y (cos) made to point in */
    if (nx < 0) {{ nx = -nx; in_x = 1; }}
    else if (nx > KB_ARENA_W) {{ nx = 2 * KB_ARENA_W - nx; in_x = -1; }}
    if (ny > 0) {{ ny = -ny; in_y = -1; }}
    else if (ny < -KB_ARENA_H) {{ ny = -2 * KB_ARENA_H - ny; in_y = 1; }}
    if (!in_x && !in_y) return 0;
    nx = nx < 0 ? 0 : nx > KB_ARENA_W ? KB_ARENA_W : nx;
    ny = ny > 0 ? 0 : ny < -KB_ARENA_H ? -KB_ARENA_H : ny;
    for (int i = 0; i < n_bots; i++) {{
        kilobot *b = allbots[i];
        if (b->x != x || b->y != y) continue;
        if (in_x && sin(b->direction) * in_x < 0) b->direction = -b->direction;
        if (in_y && cos(b->direction) * in_y < 0) b->direction = M_PI - b->direction;
        break;
    }}
    *dx = nx - x;
    *dy = ny - y;
    return 1;
}}
#endif
"""
