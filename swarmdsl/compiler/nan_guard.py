"""NaN caught where it is made: in a `let`, in a comparison of a `when` condition, and in
an agent's initial values (there infinities too).

NaN passes silently through arithmetic and compares false, so `when x > 0 -> s` would
simply never fire and a recorded column would fill with NaN. One vectorised `isnan` per
guarded value per tick (no loop over agents) turns that into a located
SwarmRuntimeError naming the agent, kind, status and tick.
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.compiler import ast
from swarmdsl.compiler.facts import NodeTable
from swarmdsl.errors import SwarmRuntimeError


def guarded_compares(cond: ast.Expr) -> NodeTable:
    """The comparisons a `when` condition makes itself (not inside a neighbour
    aggregate, where each pair is its own value)."""
    out = NodeTable()
    stack = [cond]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Call):
            continue
        if isinstance(node, ast.Compare):
            out[node] = True
        stack.extend(node.children())
    return out


def nan_rows(value, f) -> np.ndarray | None:
    """Rows of the frame's running agents whose `value` holds a NaN, or None."""
    return _rows(value, f, False)


def nonfinite_rows(value, f) -> np.ndarray | None:
    """Rows of the frame's running agents whose `value` holds a NaN or an infinity."""
    return _rows(value, f, True)


def _rows(value, f, infinities: bool) -> np.ndarray | None:
    arr = value if type(value) is np.ndarray else np.asarray(value)
    if arr.dtype.kind != "f" or not arr.size:
        return None
    # Fast path: the maximum is NaN whenever a value is (and the minimum -inf whenever
    # one is): one pass, which unlike a sum cannot overflow, so it needs no errstate
    # block (a third of the cost on the few values a small swarm's frame holds).
    hi = float(np.maximum.reduce(arr, axis=None))
    if not infinities:
        if hi == hi:
            return None
        bad = np.isnan(arr)
    else:
        if hi < math.inf and float(np.minimum.reduce(arr, axis=None)) > -math.inf:
            return None
        bad = ~np.isfinite(arr)
    if bad.ndim == 2:
        bad = bad.any(axis=1)
    if bad.ndim == 0:
        return np.zeros(1, dtype=np.int64) if bool(bad) else None
    active = getattr(f, "active", None)
    if active is not None and active.shape == bad.shape:
        bad = bad & active
    rows = np.flatnonzero(bad)
    return rows if rows.size else None


def describe(f, row: int) -> str:
    """`agent 7 (kind `a`, status `s`) at tick 3`, as far as the frame knows."""
    kind = getattr(getattr(f, "kind", None), "name", "?")
    status = getattr(f, "status_name", None)
    try:
        agent = int(f.sim.agents.cols["id"][f.idx[row]])
    except (AttributeError, IndexError, KeyError, TypeError):
        agent = row
    if status is None:
        return f"agent {agent} of `{kind}` while placing agents"
    return f"agent {agent} (kind `{kind}`, status `{status}`) at tick {f.tick}"


def nan_error(f, row: int, span, what: str, hint: str, badness: str = "NaN"
              ) -> SwarmRuntimeError:
    """The located error for `what` being NaN (or `badness`) at frame row `row`."""
    return SwarmRuntimeError(f"{what} is {badness} for {describe(f, row)}", span, hint)


def guard(fn, span, what: str, hint: str):
    """Wrap closure `fn` so a NaN it returns for a running agent raises, located."""
    def guarded(f):
        value = fn(f)
        rows = nan_rows(value, f)
        if rows is not None:
            raise nan_error(f, int(rows[0]), span, what, hint)
        return value
    return guarded


def finite_guard(fn, span, what: str, hint: str):
    """Wrap closure `fn` so a NaN or an infinity it returns raises, located.

    For values an agent keeps (its initial position, velocity and variables): an
    infinite velocity does not fault later, it carries the agent from wall to wall every
    tick, and an infinite variable nobody assigns is recorded as it is.
    """
    def guarded(f):
        value = fn(f)
        rows = nonfinite_rows(value, f)
        if rows is not None:
            row = int(rows[0])
            arr = np.asarray(value)
            at = arr if arr.ndim == 0 else arr[row]
            badness = "NaN" if np.isnan(at).any() else "infinite"
            raise nan_error(f, row, span, what, hint, badness)
        return value
    return guarded
