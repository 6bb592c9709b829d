"""Agents as oriented markers: their colours (status, LED or behaviour-tree leaf),
triangles while the swarm is small, fixed pixel stencils beyond `splat_above`."""

from __future__ import annotations

import numpy as np

from swarmdsl.errors import SwarmError
from swarmdsl.runtime.snapshot import Snapshot
from swarmdsl.viz.palette import leaf_colours, status_palette
from swarmdsl.viz.pixels import Pixels

_DENSE = 30_000                # above this many agents, splats shrink to 2 pixels


def agent_colours(snap: Snapshot, n: int, opts) -> np.ndarray:
    """`(n, 3)` uint8 colours: by tree leaf or LED when asked and present, else status."""
    if opts.by_tree_leaf and snap.tree_leaf is not None:
        return leaf_colours(snap)
    if opts.use_led and snap.led is not None:
        led = np.asarray(snap.led)
        if led.shape != (n, 3):
            raise SwarmError(f"snapshot led has shape {led.shape}, expected ({n}, 3)")
        return np.clip(led, 0, 255).astype(np.uint8)
    status = np.asarray(snap.status, dtype=np.int64).reshape(-1)
    if status.shape[0] != n:
        raise SwarmError(f"snapshot status has {status.shape[0]} entries for {n} agents")
    palette = status_palette(max(len(snap.status_names), 1))
    return palette[np.mod(status, len(palette))]


def draw_agents(pixels: Pixels, px: np.ndarray, heading: np.ndarray, colours: np.ndarray,
                opts, hollow: bool) -> None:
    """One marker per agent at pixel `px`, pointing along `heading` (radians, y up)."""
    n = len(px)
    if n == 0:
        return
    keep = np.isfinite(px).all(axis=1) & np.isfinite(heading)
    inside = keep & (px[:, 0] > -32) & (px[:, 0] < pixels.width + 32) \
        & (px[:, 1] > -32) & (px[:, 1] < pixels.height + 32)
    px, heading, colours = px[inside], heading[inside], colours[inside]
    # Heading is counter-clockwise with y up, so the pixel direction flips dy.
    direction = np.stack([np.cos(heading), -np.sin(heading)], axis=1)
    length = opts.marker_px if opts.marker_px is not None else _auto_marker(n)
    if n <= opts.splat_above:
        _draw_triangles(pixels, px, direction, colours, float(length), hollow)
    else:
        _draw_splats(pixels, px, direction, colours, hollow)


def _draw_triangles(pixels: Pixels, px, direction, colours, length, hollow) -> None:
    # Vertices chosen so the triangle's centroid is the agent's position.
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1)
    nose = px + direction * (2.0 * length / 3.0)
    back = px - direction * (length / 3.0)
    half = normal * (0.35 * length)
    tris = np.stack([nose, back + half, back - half], axis=1)        # (N, 3, 2)
    width = 1 if hollow else 0
    polygon, surface = pixels.pg.draw.polygon, pixels.surface
    for tri, colour in zip(tris.tolist(), colours.tolist(), strict=True):
        polygon(surface, colour, tri, width)


def _draw_splats(pixels: Pixels, px, direction, colours, hollow) -> None:
    """Fixed pixel stencils for big swarms: a 3x3 body plus a nose pixel ahead.

    The loop runs over the (at most nine) stencil offsets, each writing every agent at once;
    bodies are clamped one pixel inside the frame so no per-offset bounds mask is
    needed (agents in the outermost pixel ring draw shifted by one pixel).
    """
    w, h = pixels.width, pixels.height
    bx = np.clip(np.floor(px[:, 0]).astype(np.int64), 1, w - 2)
    by = np.clip(np.floor(px[:, 1]).astype(np.int64), 1, h - 2)
    base = by * w + bx
    packed = pixels.pack(colours)
    reach = 2.5 if len(px) <= _DENSE else 1.0
    nose_x = np.clip(bx + np.rint(direction[:, 0] * reach).astype(np.int64), 0, w - 1)
    nose_y = np.clip(by + np.rint(direction[:, 1] * reach).astype(np.int64), 0, h - 1)
    # Past _DENSE agents a 3x3 body would paint the whole frame: shrink to one pixel.
    if len(px) > _DENSE:
        stencil = [(0, 0)] if not hollow else [(-1, 0), (1, 0), (0, -1), (0, 1)]
    else:
        stencil = [(dx, dy) for dy in (-1, 0, 1) for dx in (-1, 0, 1)
                   if not (hollow and dx == 0 and dy == 0)]
    with pixels.rows() as rows:
        flat = rows.reshape(-1)
        for dx, dy in stencil:
            flat[base + (dy * w + dx)] = packed
        flat[nose_y * w + nose_x] = packed


def _auto_marker(n: int) -> float:
    if n <= 200:
        return 12.0
    if n <= 1000:
        return 9.0
    return 7.0
