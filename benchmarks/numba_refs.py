"""Hand-written serial numba programs of the benchmark models: the speed a swarm
researcher gets by writing the loops by hand.

Imported only when numba is installed (`python -m benchmarks` skips these columns
without it). Each model keeps its state in plain arrays and follows the rules, parameters
and update order of its `.swarm` program and of its numpy reference. Random draws come
from the same numpy `Generator` calls as the numpy reference, outside the kernels, so a
numba and a numpy reference started alike stay equal up to rounding.

The neighbour search is a cell list: a counting sort of the agents by cell (cells at
least as wide as the radius), then, per agent, the agents of the 3 x 3 cells around its
own. Every agent visits its own neighbours (directed pairs), the plain way to write it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def cell_grid(pos, width, height, radius, wrap):
    """Counting sort of agents into cells: (start (C+1,), order (N,), cx (N,), cy (N,), nx, ny)."""
    n = pos.shape[0]
    nx = max(1, int(width // radius))
    ny = max(1, int(height // radius))
    cw = width / nx
    ch = height / ny
    cx = np.empty(n, np.int64)
    cy = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        a = int(pos[i, 0] / cw)
        b = int(pos[i, 1] / ch)
        a = min(max(a, 0), nx - 1)
        b = min(max(b, 0), ny - 1)
        cx[i] = a
        cy[i] = b
        start[b * nx + a + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        c = cy[i] * nx + cx[i]
        order[fill[c]] = i
        fill[c] += 1
    return start, order, cx, cy, nx, ny


@njit(cache=True)
def around(c, nc, wrap, out):
    """The distinct cell columns (or rows) next to `c`, into `out`; returns how many."""
    k = 0
    for d in (-1, 0, 1):
        e = c + d
        if wrap:
            e %= nc
        elif e < 0 or e >= nc:
            continue
        seen = False
        for m in range(k):
            if out[m] == e:
                seen = True
        if not seen:
            out[k] = e
            k += 1
    return k


@njit(cache=True)
def pair_delta(pos, i, j, width, height, wrap):
    """pos[j] - pos[i], the short way round in a wrap-around world."""
    dx = pos[j, 0] - pos[i, 0]
    dy = pos[j, 1] - pos[i, 1]
    if wrap:
        dx -= width * np.round(dx / width)
        dy -= height * np.round(dy / height)
    return dx, dy


@njit(cache=True)
def edge_push(pos, width, height, grid, weight, r):
    """The runtime's wall repulsion (`World.edge_push`): (r / d)^2 from each edge node,
    a corner node once (the bottom and top sides leave out their end nodes that are
    already the left or right side's)."""
    n = pos.shape[0]
    push = np.zeros((n, 2))
    reach = int(math.ceil(r / grid))
    whole_w = abs(width / grid - math.floor(width / grid + 1e-9)) < 1e-9
    whole_h = abs(height / grid - math.floor(height / grid + 1e-9)) < 1e-9
    for i in range(n):
        for wall in range(4):
            first, last = 0, 0      # end nodes this side leaves to another
            if wall == 2:
                first, last = 1, int(whole_w)
            elif wall == 3:
                first, last = int(whole_h), int(whole_w and whole_h)
            if wall == 0:
                dp, al, sign, length, perp = pos[i, 0], pos[i, 1], 1.0, height, 0
            elif wall == 1:
                dp, al, sign, length, perp = width - pos[i, 0], pos[i, 1], -1.0, height, 0
            elif wall == 2:
                dp, al, sign, length, perp = pos[i, 1], pos[i, 0], 1.0, width, 1
            else:
                dp, al, sign, length, perp = height - pos[i, 1], pos[i, 0], -1.0, width, 1
            if not dp < r:
                continue
            base = np.round(al / grid)
            kmax = math.floor(length / grid + 1e-9)
            for m in range(-reach, reach + 1):
                k = base + m
                diff = al - k * grid
                d2 = dp * dp + diff * diff
                if k >= first and k <= kmax - last and d2 < r * r and d2 > 0:
                    d = math.sqrt(d2)
                    mag = (r / d) ** 2 / d
                    push[i, perp] += sign * dp * mag
                    push[i, 1 - perp] += diff * mag
    for i in range(n):
        push[i, 0] *= weight
        push[i, 1] *= weight
    return push


@njit(cache=True)
def move_walls(pos, vel, width, height):
    """Move by velocity and reflect at the walls (`World.move`), in place."""
    for i in range(pos.shape[0]):
        for axis in range(2):
            size = width if axis == 0 else height
            x = pos[i, axis] + vel[i, axis]
            if x < 0:
                x = -x
                vel[i, axis] = abs(vel[i, axis])
            elif x > size:
                x = 2 * size - x
                vel[i, axis] = -abs(vel[i, axis])
            pos[i, axis] = min(max(x, 0.0), size)


@njit(cache=True)
def move_wrap(pos, vel, width, height):
    for i in range(pos.shape[0]):
        pos[i, 0] = (pos[i, 0] + vel[i, 0]) % width
        pos[i, 1] = (pos[i, 1] + vel[i, 1]) % height


# ---- boids (programs/boids.swarm) ----

@njit(cache=True)
def boids_tick(pos, vel, turn, width, height, radius, cruise, gain, grid, edge_weight,
               edge_range):
    n = pos.shape[0]
    start, order, cx, cy, nx, ny = cell_grid(pos, width, height, radius, False)
    cols = np.empty(3, np.int64)
    rows = np.empty(3, np.int64)
    new = np.empty((n, 2))
    r2 = radius * radius
    for i in range(n):
        sx = sy = kx = ky = ax = ay = 0.0
        count = 0
        kc = around(cx[i], nx, False, cols)
        kr = around(cy[i], ny, False, rows)
        for a in range(kc):
            for b in range(kr):
                c = rows[b] * nx + cols[a]
                for s in range(start[c], start[c + 1]):
                    j = order[s]
                    if j == i:
                        continue
                    dx = pos[j, 0] - pos[i, 0]
                    dy = pos[j, 1] - pos[i, 1]
                    d2 = dx * dx + dy * dy
                    if d2 > r2:
                        continue
                    d = math.sqrt(d2)
                    count += 1
                    if d < 0.4 * radius and d > 0:
                        w = (0.4 * radius / max(d, 0.001)) ** 2 / d
                        sx -= dx * w
                        sy -= dy * w
                    if d > 0.5 * radius:
                        kx += dx / radius
                        ky += dy / radius
                    if d > radius / 3:
                        ax += vel[j, 0] - vel[i, 0]
                        ay += vel[j, 1] - vel[i, 1]
        m = max(count, 1)
        vx = vel[i, 0] + gain * (0.9 * sx + 0.7 * kx + 0.3 * ax) / m
        vy = vel[i, 1] + gain * (0.9 * sy + 0.7 * ky + 0.3 * ay) / m
        norm = math.sqrt(vx * vx + vy * vy)
        if norm > 0:
            vx = vx / norm * cruise
            vy = vy / norm * cruise
        else:
            vx = vy = 0.0
        c, s = math.cos(turn[i]), math.sin(turn[i])
        new[i, 0] = c * vx - s * vy
        new[i, 1] = s * vx + c * vy
    push = edge_push(pos, width, height, grid, edge_weight, edge_range)
    for i in range(n):
        vx = new[i, 0] + push[i, 0]
        vy = new[i, 1] + push[i, 1]
        speed = math.sqrt(vx * vx + vy * vy)
        if speed > cruise:
            vx *= cruise / speed
            vy *= cruise / speed
        vel[i, 0] = vx
        vel[i, 1] = vy
    move_walls(pos, vel, width, height)


class NumbaBoids:
    """`programs/boids.swarm` as serial numba loops (see `reference_boids.ReferenceBoids`)."""

    def __init__(self, pos, vel, width, height, radius=80.0, cruise=3.0, gain=2.0,
                 wander=0.05, seed=0, grid=10.0, edge_weight=1.0):
        self.pos = np.array(pos, dtype=np.float64)
        self.vel = np.array(vel, dtype=np.float64)
        self.width, self.height = float(width), float(height)
        self.radius, self.cruise, self.gain = float(radius), float(cruise), float(gain)
        self.wander = float(wander)
        self.grid, self.edge_weight = float(grid), float(edge_weight)
        self.rng = np.random.default_rng(seed)

    @classmethod
    def from_state(cls, start: dict, params: dict, seed: int) -> NumbaBoids:
        return cls(start["pos"], start["vel"], params["width"], params["height"],
                   wander=params.get("wander", 0.05), seed=seed)

    def state(self) -> dict:
        return {"pos": self.pos, "vel": self.vel}

    def step(self) -> None:
        turn = self.rng.standard_normal(self.pos.shape[0]) * self.wander
        boids_tick(self.pos, self.vel, turn, self.width, self.height, self.radius,
                   self.cruise, self.gain, self.grid, self.edge_weight, 0.4 * self.radius)


# ---- Vicsek (programs/vicsek.swarm) ----

@njit(cache=True)
def vicsek_tick(pos, vel, noise, side, r, v0):
    n = pos.shape[0]
    start, order, cx, cy, nx, ny = cell_grid(pos, side, side, r, True)
    cols = np.empty(3, np.int64)
    rows = np.empty(3, np.int64)
    new = np.empty((n, 2))
    r2 = r * r
    for i in range(n):
        hx = hy = 0.0
        kc = around(cx[i], nx, True, cols)
        kr = around(cy[i], ny, True, rows)
        for a in range(kc):
            for b in range(kr):
                c = rows[b] * nx + cols[a]
                for s in range(start[c], start[c + 1]):
                    j = order[s]
                    if j == i:
                        continue
                    dx, dy = pair_delta(pos, i, j, side, side, True)
                    if dx * dx + dy * dy > r2:
                        continue
                    speed = math.sqrt(vel[j, 0] ** 2 + vel[j, 1] ** 2)
                    if speed > 0:
                        hx += vel[j, 0] / speed
                        hy += vel[j, 1] / speed
        speed = math.sqrt(vel[i, 0] ** 2 + vel[i, 1] ** 2)
        if speed > 0:
            hx += vel[i, 0] / speed
            hy += vel[i, 1] / speed
        a = math.atan2(hy, hx) + noise[i]
        new[i, 0] = math.cos(a) * v0
        new[i, 1] = math.sin(a) * v0
    vel[:] = new
    move_wrap(pos, vel, side, side)


class NumbaVicsek:
    """`programs/vicsek.swarm` as serial numba loops (see `reference_vicsek.ReferenceVicsek`)."""

    def __init__(self, pos, vel, side, r=1.0, v0=0.03, eta=1.0, seed=0):
        self.pos = np.array(pos, dtype=np.float64)
        self.vel = np.array(vel, dtype=np.float64)
        self.side, self.r, self.v0, self.eta = float(side), float(r), float(v0), float(eta)
        self.rng = np.random.default_rng(seed)

    @classmethod
    def from_state(cls, start: dict, params: dict, seed: int) -> NumbaVicsek:
        return cls(start["pos"], start["vel"], params["size"], eta=params.get("eta", 1.0),
                   seed=seed)

    def state(self) -> dict:
        return {"pos": self.pos, "vel": self.vel}

    def step(self) -> None:
        noise = self.rng.uniform(-self.eta / 2, self.eta / 2, self.pos.shape[0])
        vicsek_tick(self.pos, self.vel, noise, self.side, self.r, self.v0)


# ---- swarmalators (benchmarks/models/swarmalators.swarm) ----

@njit(cache=True)
def swarmalators_tick(pos, vel, phase, kick, side, r, jj, kk, dt, top):
    n = pos.shape[0]
    start, order, cx, cy, nx, ny = cell_grid(pos, side, side, r, True)
    cols = np.empty(3, np.int64)
    rows = np.empty(3, np.int64)
    new_phase = np.empty(n)
    r2 = r * r
    for i in range(n):
        px = py = turn = 0.0
        m = 0
        kc = around(cx[i], nx, True, cols)
        kr = around(cy[i], ny, True, rows)
        for a in range(kc):
            for b in range(kr):
                c = rows[b] * nx + cols[a]
                for s in range(start[c], start[c + 1]):
                    j = order[s]
                    if j == i:
                        continue
                    dx, dy = pair_delta(pos, i, j, side, side, True)
                    d2 = dx * dx + dy * dy
                    if d2 > r2:
                        continue
                    d = math.sqrt(d2)
                    if not d > 0.01:
                        continue
                    m += 1
                    diff = phase[j] - phase[i]
                    w = (1 + jj * math.cos(diff)) / d - 1 / d2
                    px += dx * w
                    py += dy * w
                    turn += math.sin(diff) / d
        mm = max(m, 1)
        vx = px * dt / mm
        vy = py * dt / mm
        speed = math.sqrt(vx * vx + vy * vy)
        if speed > top:
            vx *= top / speed
            vy *= top / speed
        vel[i, 0] = vx
        vel[i, 1] = vy
        new_phase[i] = phase[i] + dt * kk * turn / mm + kick[i]
    phase[:] = new_phase
    move_wrap(pos, vel, side, side)


class NumbaSwarmalators:
    """`swarmalators.swarm` as serial numba loops (see `reference_swarmalators`)."""

    def __init__(self, start: dict, params: dict, seed: int):
        self.pos = np.array(start["pos"], dtype=np.float64)
        self.vel = np.array(start["vel"], dtype=np.float64)
        self.phase = np.array(start["phase"], dtype=np.float64)
        p = {"r": 2.0, "j": 0.5, "k": 0.5, "dt": 0.1, "noise": 0.05, "top_speed": 0.5,
             **params}
        self.args = tuple(float(p[x]) for x in ("size", "r", "j", "k", "dt", "top_speed"))
        self.noise = float(p["noise"])
        self.rng = np.random.default_rng(seed)

    from_state = classmethod(lambda cls, start, params, seed: cls(start, params, seed))

    def state(self) -> dict:
        return {"pos": self.pos, "vel": self.vel, "phase": self.phase}

    def step(self) -> None:
        kick = self.rng.standard_normal(self.pos.shape[0]) * self.noise
        swarmalators_tick(self.pos, self.vel, self.phase, kick, *self.args)


# ---- chemotaxis (benchmarks/models/chemotaxis.swarm) ----

@njit(cache=True)
def chemotaxis_tick(pos, vel, chem, angle, side, h, pace, gain, decay, diffusion):
    n = pos.shape[0]
    nx = chem.shape[1]
    new_chem = np.empty_like(chem)
    deposit = np.zeros_like(chem)
    for a in range(n):
        fx = (pos[a, 0] % side) / h
        fy = (pos[a, 1] % side) / h
        lx = math.floor(fx)
        ly = math.floor(fy)
        tx, ty = fx - lx, fy - ly
        x0, y0 = int(lx) % nx, int(ly) % nx
        gx = gy = 0.0
        for corner in range(4):
            i = (x0 + (corner & 1)) % nx
            j = (y0 + (corner >> 1)) % nx
            w = (tx if corner & 1 else 1 - tx) * (ty if corner >> 1 else 1 - ty)
            gx += w * (chem[j, (i + 1) % nx] - chem[j, (i - 1) % nx]) / (2 * h)
            gy += w * (chem[(j + 1) % nx, i] - chem[(j - 1) % nx, i]) / (2 * h)
            deposit[j, i] += w
        vx = vel[a, 0] + gain * gx
        vy = vel[a, 1] + gain * gy
        norm = math.sqrt(vx * vx + vy * vy)
        if norm > 0:
            vx, vy = vx / norm * pace, vy / norm * pace
        else:
            vx = vy = 0.0
        c, s = math.cos(angle[a]), math.sin(angle[a])
        vel[a, 0] = c * vx - s * vy
        vel[a, 1] = s * vx + c * vy
    move_wrap(pos, vel, side, side)
    keep = 1 - decay
    for j in range(nx):
        for i in range(nx):
            v = chem[j, i] + deposit[j, i]
            around = (chem[j, (i - 1) % nx] + deposit[j, (i - 1) % nx]
                      + chem[j, (i + 1) % nx] + deposit[j, (i + 1) % nx]
                      + chem[(j - 1) % nx, i] + deposit[(j - 1) % nx, i]
                      + chem[(j + 1) % nx, i] + deposit[(j + 1) % nx, i])
            new_chem[j, i] = keep * (1 - 4 * diffusion) * v + keep * diffusion * around
    chem[:] = new_chem


class NumbaChemotaxis:
    """`chemotaxis.swarm` as serial numba loops (see `reference_chemotaxis`)."""

    def __init__(self, start: dict, params: dict, seed: int):
        self.pos = np.array(start["pos"], dtype=np.float64)
        self.vel = np.array(start["vel"], dtype=np.float64)
        p = {"spacing": 1.0, "pace": 1.0, "gain": 2.0, "turn": 0.3, "decay": 0.1,
             "diffusion": 0.2, **params}
        nx = round(float(p["size"]) / float(p["spacing"]))
        self.chem = np.zeros((nx, nx))
        self.args = tuple(float(p[x]) for x in ("size", "spacing", "pace", "gain", "decay",
                                                 "diffusion"))
        self.turn = float(p["turn"])
        self.rng = np.random.default_rng(seed)

    from_state = classmethod(lambda cls, start, params, seed: cls(start, params, seed))

    def state(self) -> dict:
        return {"pos": self.pos, "vel": self.vel}

    def step(self) -> None:
        angle = self.rng.standard_normal(self.pos.shape[0]) * self.turn
        chemotaxis_tick(self.pos, self.vel, self.chem, angle, *self.args)
