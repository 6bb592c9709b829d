"""Sensing models at run time: what an agent's sensors let through, per robot profile.

A neighbour is sensed when it is within the profile's range and field of view (a cone
about the heading, or the thesis' front half-circle plus two side wedges); then it may
drop out (per pair, per tick), and what is sensed of it, its offset `other.pos - pos`
and so `dist`, gets additive noise and is rounded to the profile's resolution. A field
reading gets the same three treatments, and a reading at a point out of range or out
of view reads 0. Every draw comes from the run's seeded source, keyed by agent (and
neighbour) id, so a run is reproducible and independent of agent order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.ops import portable

FOV_CODES = {"all": 0, "cone": 1, "front": 2}


@dataclass(frozen=True)
class SensingSpec:
    """Per kind index ``(K,)`` arrays of the profiles' sensing settings."""

    range: np.ndarray
    fov: np.ndarray            # FOV_CODES
    fov_angle: np.ndarray
    fov_reach: np.ndarray
    neighbor_noise: np.ndarray
    neighbor_dropout: np.ndarray
    neighbor_resolution: np.ndarray
    field_noise: np.ndarray
    field_dropout: np.ndarray
    field_resolution: np.ndarray

    def view(self, k: int) -> View | None:
        """Kind `k`'s sensing as a `View` when it only selects neighbours by where
        they are (no dropout, noise or resolution), else None."""
        if self.neighbor_dropout[k] > 0 or self.neighbor_noise[k] > 0 \
                or self.neighbor_resolution[k] > 0:
            return None
        return View(int(self.fov[k]), float(self.fov_angle[k]), float(self.fov_reach[k]),
                    float(self.range[k]))

    @property
    def views_only(self) -> bool:
        """Whether every kind's sensing is a `View` and field readings are exact (out
        of view they read 0, which needs no draw): nothing of it needs Python, so a
        whole-tick kernel may test the views in its pair loops."""
        return all(self.view(k) is not None for k in range(self.fov.size)) and not (
            self.field_noise.any() or self.field_dropout.any()
            or self.field_resolution.any())


def in_view(offset: np.ndarray, heading: np.ndarray, fov: int, angle: float,
            reach: float, rng: float, dist: np.ndarray | None = None) -> np.ndarray:
    """``(P,)`` which offsets ``(P, 2)`` (from agents heading ``(P,)``) are in view.

    ``fov`` 0 sees all round, 1 a cone of half angle ``angle`` about the heading,
    2 the front half-circle plus, on each side, a wedge ``angle`` wide behind it that
    reaches ``reach``. Everything is limited to ``rng``. The agent's own position
    (a zero offset) is in view. ``dist``: the offsets' lengths as the pairs have them
    (a neighbour's `dist`, so that one in range reads `dist <= range`); else taken.
    """
    if dist is None:
        dist = portable.hypot_array(offset[:, 0], offset[:, 1])
    ok = dist <= rng
    if fov == 0:
        return ok
    bearing = portable.atan2_array(offset[:, 1], offset[:, 0]) - heading
    off_axis = np.abs((bearing + np.pi) % (2 * np.pi) - np.pi)      # in [0, pi]
    if fov == 1:
        return ok & ((off_axis <= angle) | (dist == 0))
    front = off_axis <= np.pi / 2
    wedge = (off_axis <= np.pi / 2 + angle) & (dist <= reach)
    return ok & (front | wedge | (dist == 0))


# `in_view` of a pair as a condition, for a backend that tests it as it searches the
# cells (the numba kernels' scalar trees, compiled/plan.py's vocabulary): the same
# operations on the same values, so the same pairs. Leaves `("s", c)` are the owner's
# columns `VIEW_COLUMNS` in that order (`View.columns`), `("d",)`, `("dx",)`, `("dy",)`
# the pair's `dist` and offset; `d <= limit` (the `neighbors(r)` radius and the sense
# range) is and-ed in.
VIEW_COLUMNS = ("limit", "heading", "range", "pi", "two_pi", "half_pi", "angle",
                "half_pi_angle", "reach")


def _col(name: str) -> tuple:
    return ("s", VIEW_COLUMNS.index(name))


def view_tree(fov: int) -> tuple:
    """`in_view`'s condition for field of view `fov`, and the `neighbors(r)` limit. The
    tests are nested (`if`: only the branch taken is evaluated) so that a pair out of
    reach costs no `atan2`; the pairs kept are `in_view`'s."""
    dist = ("d",)
    no = ("not", ("true",))

    def within(rest):
        return ("if", ("le", dist, _col("limit")),
                ("if", ("le", dist, _col("range")), rest, no), no)

    if fov == 0:
        return within(("true",))
    bearing = ("sub", ("atan2", ("dy",), ("dx",)), _col("heading"))
    off_axis = ("abs", ("sub", ("mod", ("add", bearing, _col("pi")), _col("two_pi")),
                        _col("pi")))
    if fov == 1:
        seen = ("le", off_axis, _col("angle"))
    else:
        seen = ("or", ("le", off_axis, _col("half_pi")),
                ("and", ("le", off_axis, _col("half_pi_angle")), ("le", dist, _col("reach"))))
    return within(("if", ("eq", dist, ("zero",)), ("true",), seen))


@dataclass(frozen=True)
class View:
    """What a kind's sensing lets through when it only looks at where the neighbour is
    (no dropout, noise or resolution): `in_view`'s settings."""

    fov: int
    angle: float
    reach: float
    range: float

    @property
    def everything(self) -> bool:
        """Whether it lets every pair of the table through (all round, no range)."""
        return self.fov == 0 and not np.isfinite(self.range)

    def columns(self, limit, heading) -> list:
        """The owner's values of `VIEW_COLUMNS` (`limit`, `heading`: one per owner or
        one for all), computed as `in_view` computes them."""
        return [limit, heading, self.range, np.pi, 2 * np.pi, np.pi / 2, self.angle,
                np.pi / 2 + self.angle, self.reach]


def _rounded(values: np.ndarray, step: float) -> np.ndarray:
    return np.round(values / step) * step if step > 0 else values


class Sensing:
    """Runtime extension: filters neighbour sets and field readings by sensing model."""

    def __init__(self, sim, spec: SensingSpec):
        sim.sensing = self
        self.spec = spec

    def state_dict(self, sim) -> dict:
        return {}   # draws are keyed by (seed, id, tick): nothing to keep

    def load_state(self, sim, state: dict) -> None:
        pass

    # ---- neighbours ----
    @property
    def views_only(self) -> bool:
        return self.spec.views_only

    def view(self, frame) -> View | None:
        """`frame`'s kind's sensing as a `View` when it only selects neighbours by
        where they are (a backend may then test it while it searches), else None: its
        draws and sensed offsets need `neighbors`."""
        k = getattr(frame.kind, "index", None)
        return None if k is None else self.spec.view(k)

    def neighbors(self, frame, pairs):
        """The part of ``pairs`` (a NeighborSet) that ``frame``'s agents perceive."""
        from swarmdsl.runtime.frame import NeighborSet

        k = getattr(frame.kind, "index", None)
        s = self.spec
        if k is None or pairs.seg.size == 0:
            return pairs
        fov, dropout = int(s.fov[k]), float(s.neighbor_dropout[k])
        noise, res = float(s.neighbor_noise[k]), float(s.neighbor_resolution[k])
        rng_limit = float(s.range[k])
        if fov or np.isfinite(rng_limit):
            heading = np.take(frame.state("heading"), pairs.seg)
            keep = in_view(pairs.delta, heading, fov, float(s.fov_angle[k]),
                           float(s.fov_reach[k]), rng_limit, pairs.dist)
            if not keep.all():
                pairs = pairs.subset(keep)
        if dropout > 0 and pairs.seg.size:
            draw = pairs.pair_frame().rng.at("sensing dropout").random(pairs.seg.size)
            pairs = pairs.subset(draw >= dropout)
        if (noise > 0 or res > 0) and pairs.seg.size:
            delta = np.array(pairs.delta, dtype=np.float64)
            if noise > 0:
                draw = pairs.pair_frame().rng.at("sensing noise")
                delta += noise * draw.standard_normal((pairs.seg.size, 2))
            dist = portable.hypot_array(delta[:, 0], delta[:, 1])
            if res > 0:
                sensed = _rounded(dist, res)
                scale = np.divide(sensed, dist, out=np.zeros_like(dist), where=dist > 0)
                delta *= scale[:, None]
                dist = sensed
            perceived = NeighborSet(frame, pairs.seg, pairs.j, dist, delta)
            perceived.perceived = True
            return perceived
        return pairs

    # ---- fields ----
    def field_reading(self, frame, values: np.ndarray, site: str,
                      points: np.ndarray | None = None) -> np.ndarray:
        """``values`` ``(M,)`` or ``(M, 2)`` as ``frame``'s agents read them.

        ``points`` ``(M, 2)``: where each reading was taken (None: at the agent), so
        readings out of range or out of view read 0.
        """
        k = getattr(frame.kind, "index", None)
        if k is None:
            return values
        s = self.spec
        values = np.array(np.broadcast_to(values, (frame.n, *np.shape(values)[1:])),
                          dtype=np.float64)
        lost = np.zeros(frame.n, dtype=bool)
        if points is not None:
            offset = points - np.asarray(frame.state("pos"), dtype=np.float64)
            lost |= ~in_view(offset, frame.state("heading"), int(s.fov[k]),
                             float(s.fov_angle[k]), float(s.fov_reach[k]), float(s.range[k]))
        rng = frame.rng.at(f"sensing {site}")
        if s.field_dropout[k] > 0:
            lost |= rng.at("dropout").random(frame.n) < s.field_dropout[k]
        if s.field_noise[k] > 0:
            values += s.field_noise[k] * rng.at("noise").standard_normal(values.shape)
        values = _rounded(values, float(s.field_resolution[k]))
        values[lost] = 0.0
        return values
