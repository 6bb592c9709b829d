"""The motion step compiled: edge repulsion, speed clamp, move and edges.

One loop over the agents does what `Simulation._move` does in five numpy passes, with
the same operations in the same order: positions and velocities come out bit for bit
as on the numpy backend. The heading is the language's own `atan2` (`ops/portable.py`)
of the new velocity, compiled in a second loop (its kernel is kept on disk under the
fingerprint of the portable math, so a change there compiles it anew).
Used only when no extension replaces the motion (kilobot vibration).
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.runtime.compiled import threads
from swarmdsl.runtime.compiled.jit import njit, prange
from swarmdsl.runtime.world import corner_nodes


@njit(cache=True, nogil=True, error_model="numpy")
def _push(x, y, width, height, grid, r, reach, corners):
    """World.edge_push for one agent, before the weight: nodes wall by wall, as there
    (`corners`: `world.corner_nodes`, the end nodes of the bottom and top sides that
    belong to the left or right side)."""
    px = 0.0
    py = 0.0
    lo_top, hi_bottom, hi_top = corners
    for wall in range(4):
        skip_lo, skip_hi = False, False
        if wall == 0:
            dp, al, sign, length, perp = x, y, 1.0, height, 0
        elif wall == 1:
            dp, al, sign, length, perp = width - x, y, -1.0, height, 0
        elif wall == 2:
            dp, al, sign, length, perp = y, x, 1.0, width, 1
            skip_lo, skip_hi = True, hi_bottom
        else:
            dp, al, sign, length, perp = height - y, x, -1.0, width, 1
            skip_lo, skip_hi = lo_top, hi_top
        if not dp < r:
            continue
        base = np.rint(al / grid)
        kmax = math.floor(length / grid + 1e-9)
        for m in range(-reach, reach + 1):
            k = base + m
            diff = al - k * grid
            d2 = dp * dp + diff * diff
            if k >= 0 + skip_lo and k <= kmax - skip_hi and d2 < r * r and d2 > 0:
                d = np.sqrt(d2)
                q = r / d
                mag = q * q / d
                if perp == 0:
                    px += sign * dp * mag
                    py += diff * mag
                else:
                    py += sign * dp * mag
                    px += diff * mag
    return px, py


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _wrap(x, size):
    """`np.mod(x, size)` with its bits, without its `fmod` (some 10 ns) for the usual
    case of a step across at most one edge: in [0, 2 size) the remainder is `x` or the
    exact `x - size`; in [-size, 0) numpy adds `size` to `x` as here. A hypothesis test
    checks the bits against `np.mod` (tests/test_compiled.py)."""
    if 0.0 < x < size:
        return x
    if x == 0.0:            # -0.0 too: numpy's remainder is +0.0
        return 0.0
    if size <= x < 2.0 * size:
        return x - size
    if -size <= x < 0.0:
        return x + size
    return np.mod(x, size)


@njit(cache=True, nogil=True, error_model="numpy")
def wrap_all(xs, size):
    """`_wrap` of every value (for its test against `np.mod`)."""
    out = np.empty_like(xs)
    for i in range(xs.size):
        out[i] = _wrap(xs[i], size)
    return out


def move_agents(sim):
    """(pos, vel, heading) after this tick's motion, or None to use the numpy path."""
    if any(getattr(ext, "motion", None) is not None for ext in sim.extensions):
        return None
    cols, w = sim.agents.cols, sim.world
    pos, vel = cols["pos"], cols["vel"]
    new_pos, new_vel = np.empty_like(pos), np.empty_like(vel)
    chunks = threads.chunks(pos.shape[0])
    (_move_par if chunks > 1 else _move)(
        np.ascontiguousarray(pos), np.ascontiguousarray(vel),
        np.ascontiguousarray(cols["max_speed"]),
        w.edges == "repel" and w.edge_weight > 0, w.width, w.height, w.grid,
        w.edge_weight, w.edge_range, corner_nodes(w.width, w.height, w.grid), w.wraps,
        new_pos, new_vel, chunks)
    heading = np.empty(pos.shape[0])
    serial, parallel = _heading_kernels()
    if chunks > 1:
        parallel(new_vel, cols["heading"], heading, chunks)
    else:
        serial(new_vel, cols["heading"], heading, 0, pos.shape[0])
    return new_pos, new_vel, heading


_HEADINGS: list = []


def _heading_kernels():
    """(serial, parallel) loops writing each agent's heading: the `atan2` of its new
    velocity, or the heading it had when it stands still (as `Simulation._move`)."""
    if not _HEADINGS:
        from swarmdsl.runtime.compiled.disk_cache import keep_on_disk
        from swarmdsl.runtime.compiled.kernels import scalar_function

        atan2 = scalar_function("atan2")

        @njit(nogil=True, error_model="numpy")
        def headings(vel, old, out, i0, i1):
            for i in range(i0, i1):
                vx, vy = vel[i, 0], vel[i, 1]
                out[i] = atan2(vy, vx) if (vx != 0.0 or vy != 0.0) else old[i]

        @njit(nogil=True, error_model="numpy", parallel=True)
        def headings_par(vel, old, out, chunks):
            n = vel.shape[0]
            for c in prange(chunks):
                headings(vel, old, out, c * n // chunks, (c + 1) * n // chunks)

        _HEADINGS.extend([keep_on_disk(headings), keep_on_disk(headings_par)])
    return _HEADINGS


@njit(cache=True, nogil=True, error_model="numpy")
def _move(pos, vel, limit, repel, width, height, grid, weight, r, corners, wrap, new_pos,
          new_vel, chunks):
    _move_range(0, pos.shape[0], pos, vel, limit, repel, width, height, grid, weight, r,
                corners, wrap, new_pos, new_vel)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _move_par(pos, vel, limit, repel, width, height, grid, weight, r, corners, wrap,
              new_pos, new_vel, chunks):
    """`_move` on numba's threads: each agent's motion is its own (threads.py)."""
    n = pos.shape[0]
    for c in prange(chunks):
        _move_range(c * n // chunks, (c + 1) * n // chunks, pos, vel, limit, repel,
                    width, height, grid, weight, r, corners, wrap, new_pos, new_vel)


@njit(cache=True, nogil=True, error_model="numpy")
def _move_range(i0, i1, pos, vel, limit, repel, width, height, grid, weight, r, corners,
                wrap, new_pos, new_vel):
    reach = int(math.ceil(r / grid))
    for i in range(i0, i1):
        x, y = pos[i, 0], pos[i, 1]
        vx, vy = vel[i, 0], vel[i, 1]
        if repel:
            px, py = _push(x, y, width, height, grid, r, reach, corners)
            vx = vx + px * weight
            vy = vy + py * weight
        speed = np.sqrt(vx * vx + vy * vy)
        if speed > limit[i]:
            f = limit[i] / speed
            vx *= f
            vy *= f
        nx, ny = x + vx, y + vy
        if wrap:
            nx, ny = _wrap(nx, width), _wrap(ny, height)
        else:
            if nx < 0:
                nx, vx = -nx, abs(vx)
            elif nx > width:
                nx, vx = 2 * width - nx, -abs(vx)
            if ny < 0:
                ny, vy = -ny, abs(vy)
            elif ny > height:
                ny, vy = 2 * height - ny, -abs(vy)
            nx = min(max(nx, 0.0), width)
            ny = min(max(ny, 0.0), height)
        new_pos[i, 0], new_pos[i, 1] = nx, ny
        new_vel[i, 0], new_vel[i, 1] = vx, vy
