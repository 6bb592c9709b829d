"""Path memories and label sets against plain-Python oracles (a deque per agent)."""

from __future__ import annotations

from collections import deque

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from swarmdsl.runtime.agents import AgentStore
from swarmdsl.runtime.memory import LabelSet, PathMemory

OPS = st.lists(st.tuples(st.sampled_from(["push", "pop", "clear"]),
                         st.lists(st.booleans(), min_size=4, max_size=4)), max_size=40)


@given(capacity=st.integers(1, 6), ops=OPS)
def test_path_memory_matches_a_bounded_deque_per_agent(capacity, ops):
    store = AgentStore({})
    store.append(4, set())
    mem = PathMemory(store, "trail", capacity)
    oracle = [deque(maxlen=capacity) for _ in range(4)]
    for step, (op, mask) in enumerate(ops):
        rows = np.flatnonzero(mask)
        if op == "push":
            pts = np.column_stack([rows * 100.0 + step, np.full(rows.size, step)])
            mem.push(store.cols, rows, pts)
            for r, p in zip(rows, pts, strict=True):
                oracle[r].append(tuple(p))
        elif op == "pop":
            got, had = mem.pop(store.cols, rows)
            for r, g, h in zip(rows, got, had, strict=True):
                assert h == bool(oracle[r])
                if h:
                    assert tuple(g) == oracle[r].pop()
        else:
            mem.clear(store.cols, rows)
            for r in rows:
                oracle[r].clear()
        assert list(mem.length(store.cols, np.arange(4))) == [len(q) for q in oracle]


def test_columns_stay_aligned_through_appends_and_removals():
    store = AgentStore({})
    store.append(3, set())
    mem = PathMemory(store, "trail", 4)
    labels = LabelSet(store, "known")
    mem.push(store.cols, np.arange(3), np.array([[0.0, 0], [1, 1], [2, 2]]))
    labels.add(store.cols, np.arange(3), np.array([0, 5, -1]))
    store.append(2, set())
    store.remove(np.array([True, False, False, False, False]))
    store.check_lengths()
    assert list(mem.length(store.cols, np.arange(4))) == [1, 1, 0, 0]
    assert list(labels.size(store.cols, np.arange(4))) == [1, 0, 0, 0]
    assert list(labels.contains(store.cols, np.arange(4), np.full(4, 5))) == [
        True, False, False, False]
