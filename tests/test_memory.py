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


def test_new_columns_keep_their_fill_bits_including_negative_zero():
    """Zero-filled columns come from the system's zeroed pages; any other fill, -0.0
    among them (its sign bit is a different value to `copysign` and the outputs),
    is written out."""
    store = AgentStore({"a": ((), np.float64, -0.0), "b": ((2,), np.float64, 0.0),
                        "c": ((), np.int64, 3), "d": ((), np.bool_, False)})
    store.append(3, {"a", "b", "c", "d"})
    store.append(2, {"a"})
    assert np.signbit(store.cols["a"]).all()
    assert not np.signbit(store.cols["b"]).any() and not store.cols["b"].any()
    assert store.cols["c"].tolist() == [3] * 5 and not store.cols["d"].any()
    store.check_lengths()


def test_placing_many_agents_with_long_path_memories_takes_no_memory_yet():
    """10^4 ants with a 2,000-point path memory each would fill 320 MB at placement
    (it took 7 s to place aco's ants at 10^4); their memories' pages are taken only as
    the ants remember."""
    def resident_mb():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096 / 2**20

    store = AgentStore({})
    mem = PathMemory(store, "trail", 2000)     # declared before the agents are placed
    before = resident_mb()
    store.append(10_000, set())
    assert store.cols["trail:pts"].shape == (10_000, 2000, 2)
    assert resident_mb() - before < 100
    mem.push(store.cols, np.arange(10_000), np.ones((10_000, 2)))
    assert list(mem.length(store.cols, np.array([0, 9_999]))) == [1, 1]
    assert not store.cols["trail:pts"][:, 1:].any()
