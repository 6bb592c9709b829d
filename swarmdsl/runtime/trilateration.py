"""Trilateration (thesis §3.3, docs/experiments.md), vectorised over agents.

Results are `(M, 3)` float64 rows `(x, y, ok)`: `ok` is 1.0 for a fix and 0.0 for "no
fix" (fewer than three references, or references on one line), in which case x and y are
0. Never NaN.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from swarmdsl.ops import portable

# A triple counts as collinear when the sine of the angle between its two sides is
# below this.
MIN_SINE = 1e-6
# ... or when two references coincide, up to this fraction of the triangle's longest side.
MIN_SIDE = 1e-9
# How many nearest references per agent the set form considers (all triples of them).
MAX_REFERENCES = 6


def solve3(p1, r1, p2, r2, p3, r3) -> np.ndarray:
    """The §3 linear system for three references per row.

    Args:
        p1, p2, p3: `(M, 2)` reference points (or `(2,)`, broadcast).
        r1, r2, r3: `(M,)` measured distances.

    Returns:
        `(M, 3)` rows `(x, y, ok)`.
    """
    p1, p2, p3 = (np.asarray(p, dtype=np.float64) for p in (p1, p2, p3))
    r1, r2, r3 = (np.asarray(r, dtype=np.float64) for r in (r1, r2, r3))
    p1, p2, p3 = np.broadcast_arrays(p1, p2, p3)
    origin = p1                       # solve relative to p1: smaller numbers, less rounding
    q2, q3 = p2 - origin, p3 - origin
    x1 = y1 = 0.0
    x2, y2, x3, y3 = q2[..., 0], q2[..., 1], q3[..., 0], q3[..., 1]
    a, b = x2 - x1, y2 - y1
    c = (r1 ** 2 - r2 ** 2 - x1 ** 2 + x2 ** 2 - y1 ** 2 + y2 ** 2) / 2
    d, e = x3 - x2, y3 - y2
    f = (r2 ** 2 - r3 ** 2 - x2 ** 2 + x3 ** 2 - y2 ** 2 + y3 ** 2) / 2
    den = b * d - a * e
    lu, lv = portable.hypot_array(a, b), portable.hypot_array(d, e)
    scale = lu * lv
    longest = np.maximum(np.maximum(lu, lv), portable.hypot_array(x3 - x1, y3 - y1))
    # Two references (nearly) coincide: relative to the triangle, or relative to where the
    # references are (a side of 1e-12 at coordinates near 1 has a direction only rounding
    # decides, so its sine test would pass on noise).
    where = np.max(np.abs(np.stack([p1, p2, p3])), axis=(0, -1))
    short = np.minimum(lu, lv) <= MIN_SIDE * np.maximum(longest, where)
    ok = np.isfinite(den) & (np.abs(den) > MIN_SINE * scale) & (scale > 0) & ~short
    ok &= np.isfinite(c) & np.isfinite(f)
    safe = np.where(ok, den, 1.0)
    x = np.where(ok, (b * f - c * e) / safe, 0.0)
    y = np.where(ok, (c * d - a * f) / safe, 0.0)
    x = np.where(ok, x + origin[..., 0], 0.0)
    y = np.where(ok, y + origin[..., 1], 0.0)
    return np.stack(np.broadcast_arrays(x, y, ok.astype(np.float64)), axis=-1)


def solve_sets(points: np.ndarray, dist: np.ndarray, seg: np.ndarray, m: int,
               k: int = MAX_REFERENCES) -> np.ndarray:
    """Trilaterate each of `m` agents from its references (pairs sorted by `seg`).

    Each agent uses its `k` nearest references and, of all their triples, the one whose
    triangle is least degenerate (largest |det|). No loop over agents: the triples are a
    fixed table of at most C(k, 3) index columns.

    Args:
        points: `(P,)`-row `(P, 2)` known reference coordinates.
        dist: `(P,)` measured distances to them.
        seg: `(P,)` owning agent (0..m-1) of each reference, sorted.
        m: number of agents.

    Returns:
        `(m, 3)` rows `(x, y, ok)`.
    """
    out = np.zeros((m, 3))
    if seg.size < 3 or m == 0:
        return out
    order = np.lexsort((dist, seg))
    seg, pts, r = seg[order], np.asarray(points, float)[order], np.asarray(dist, float)[order]
    counts = np.bincount(seg, minlength=m)
    first = np.cumsum(counts) - counts
    rank = np.arange(seg.size) - first[seg]
    keep = rank < k
    seg, pts, r, rank = seg[keep], pts[keep], r[keep], rank[keep]
    grid_pts = np.zeros((m, k, 2))
    grid_r = np.zeros((m, k))
    valid = np.zeros((m, k), dtype=bool)
    grid_pts[seg, rank] = pts
    grid_r[seg, rank] = r
    valid[seg, rank] = True
    ia, ib, ic = (np.asarray(t) for t in zip(*combinations(range(k), 3), strict=True))
    a, b, c = grid_pts[:, ia], grid_pts[:, ib], grid_pts[:, ic]          # (m, T, 2)
    u, v = b - a, c - b
    det = np.abs(u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])
    norm = portable.hypot_array(u[..., 0], u[..., 1]) * portable.hypot_array(v[..., 0], v[..., 1])
    usable = valid[:, ia] & valid[:, ib] & valid[:, ic] & (det > MIN_SINE * norm)
    score = np.where(usable, det, -1.0)
    best = np.argmax(score, axis=1)                                      # (m,)
    rows = np.arange(m)
    fix = solve3(a[rows, best], grid_r[rows, ia[best]], b[rows, best],
                 grid_r[rows, ib[best]], c[rows, best], grid_r[rows, ic[best]])
    fix[~usable[rows, best]] = 0.0
    return fix
