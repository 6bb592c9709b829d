"""How a spread of replicate runs is drawn: the line, the bands, the runs as points,
colours that do not repeat, a legend that fits, axes within what a metric can take.

The default is what a paper's reader can check: the median with the middle half of the
runs (25-75 %) and nearly all of them (5-95 %, or min-max) as bands, and every run as a
point, so a bimodal outcome (13 runs at 0, 4 at 1) shows as two clusters of points
instead of a mean halfway with a band past both ends. Everything here works on plain
arrays (runs x positions) and a matplotlib Axes; `figures.py` reads the files.
"""

from __future__ import annotations

import math

import numpy as np

# band name -> (what the title says, the inner band's quantiles, the outer band's);
# "sd" is the mean +- 1 standard deviation (one band), "minmax" the outer band min-max
BANDS = {
    "quantiles": "median; bands 25-75 % and 5-95 % of runs",
    "minmax": "median; bands 25-75 % and min-max of runs",
    "sd": "mean; band ± 1 sd",
}
TIME_BANDS = {
    "quantiles": "median and 25-75 % of runs",
    "minmax": "median and min-max of runs",
    "sd": "mean ± 1 sd",
}


def spread(values: np.ndarray, band: str, outer: bool = True):
    """The centre line and bands of `values` (runs x positions, NaN where a run has no
    value): (centre, [(low, high), ...] inner band first, the outer one only when
    `outer`), each (positions,); NaN where no run has a value. Positions with one run
    get a band of zero width."""
    values = np.asarray(values, dtype=float)
    have = np.isfinite(values)
    counts = have.sum(axis=0)
    some = counts > 0
    m = values.shape[1]
    centre = np.full(m, np.nan)
    if not some.any():
        return centre, []
    v = values[:, some]
    if band == "sd":
        mean = np.nanmean(v, axis=0)
        n = counts[some]
        # the sample sd (ddof 1) as pandas and papers give it; 0 for a single run
        sq = np.nansum((v - mean) ** 2, axis=0)
        sd = np.sqrt(np.divide(sq, np.maximum(n - 1, 1)))
        centre[some] = mean
        lo, hi = np.full(m, np.nan), np.full(m, np.nan)
        lo[some], hi[some] = mean - sd, mean + sd
        return centre, [(lo, hi)]
    qs = [0.5, 0.25, 0.75] + ([0.05, 0.95] if band == "quantiles" and outer else [])
    got = np.nanquantile(v, qs, axis=0)
    full = np.full((len(qs), m), np.nan)
    full[:, some] = got
    centre = full[0]
    bands = [(full[1], full[2])]
    if outer and band == "quantiles":
        bands.append((full[3], full[4]))
    elif outer and band == "minmax":
        lo, hi = np.full(m, np.nan), np.full(m, np.nan)
        lo[some], hi[some] = np.nanmin(v, axis=0), np.nanmax(v, axis=0)
        bands.append((lo, hi))
    return centre, bands


def clip(a: np.ndarray, bounds) -> np.ndarray:
    """`a` within the metric's bounds (low, high; None: open)."""
    lo, hi = bounds
    return np.clip(a, -np.inf if lo is None else lo, np.inf if hi is None else hi)


def limits(data: list[np.ndarray], bounds) -> tuple[float, float] | None:
    """The y range: the data's, padded by 5 %, never past a bound the metric has (a
    fraction's axis ends at 0 and 1); None when there is no finite value."""
    finite = [np.asarray(d, dtype=float)[np.isfinite(d)] for d in data]
    finite = [d for d in finite if d.size]
    if not finite:
        return None
    lo, hi = min(float(d.min()) for d in finite), max(float(d.max()) for d in finite)
    pad = (hi - lo) * 0.05 or abs(hi) * 0.05 or 0.05
    low, high = lo - pad, hi + pad
    if bounds[0] is not None:
        low = max(low, bounds[0])
    if bounds[1] is not None:
        high = min(high, bounds[1])
    if not low < high:          # a constant at a bound: open the other side
        low, high = (low, low + pad) if bounds[0] is not None and low == bounds[0] \
            else (high - pad, high)
    return low, high


def colours(n: int) -> list:
    """`n` distinct colours: matplotlib's ten, then its twenty, then as many as wanted
    spread along a sequential map (groups of a swept param read in order)."""
    import matplotlib

    if n <= 10:
        return [matplotlib.colormaps["tab10"](i) for i in range(n)]
    if n <= 20:
        cmap = matplotlib.colormaps["tab20"]
        return [cmap(i) for i in (list(range(0, 20, 2)) + list(range(1, 20, 2)))[:n]]
    cmap = matplotlib.colormaps["viridis"]
    return [cmap(i / (n - 1) * 0.92) for i in range(n)]


def jitter(x: np.ndarray, width: float, seed: int = 0) -> np.ndarray:
    """`x` spread sideways by up to +-width, the same spread every time the figure is
    drawn (a fixed seed): runs at one param value stay readable as separate points."""
    rng = np.random.default_rng(seed)
    return x + rng.uniform(-width, width, size=len(x))


def jitter_width(xs: np.ndarray) -> float:
    """A fifth of the smallest gap between the x positions (0.2 for one position)."""
    u = np.unique(np.asarray(xs, dtype=float))
    if u.size < 2:
        return 0.2 if u.size else 0.0
    return float(np.diff(u).min()) * 0.2


def place_legend(fig, ax, entries: int) -> None:
    """A legend of `entries` lines that fits: inside the axes when a few, else beside
    them in as many columns as keep it within the figure's height, the figure widened
    to hold it."""
    if entries <= 6:
        ax.legend(fontsize="small", frameon=False)
        return
    rows = max(1, int(fig.get_figheight() * 72 / 13))     # ~13 pt a small-font line
    ncol = math.ceil(entries / rows)
    width = fig.get_figwidth()
    fig.set_figwidth(width + 1.9 * ncol)
    ax.legend(fontsize="small", frameon=False, loc="upper left",
              bbox_to_anchor=(1.01, 1.0), ncol=ncol, borderaxespad=0.0)
