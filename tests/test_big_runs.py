"""What makes a big run fast on the numba backend without changing a bit: the choice
between threads and one thread tick by tick (`threads.Pace`), statements split over
threads, and whole ticks only for small swarms."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

from conftest import PROGRAMS  # noqa: E402

from swarmdsl import load_program  # noqa: E402
from swarmdsl.runtime.compiled import threads  # noqa: E402


def _pace(monkeypatch, threads_n=2):
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    monkeypatch.setattr(threads, "count", lambda: threads_n)
    return threads.Pace()


def _tick(pace, n, cost):
    """One tick of n agents timed `cost[choice]` seconds; the choice made."""
    choice = pace.pick(n)
    if choice is not None:
        pace.took(choice, cost[choice])
    return choice


def test_pace_keeps_the_faster_choice_and_tries_the_other_less_and_less(monkeypatch):
    """Threads slower (a busy machine): after the first ticks of each, one thread; the
    threads are tried again on the 16th tick, then the 32nd after, the 64th."""
    pace = _pace(monkeypatch)
    cost = {2: 0.04, 1: 0.003}
    got = [_tick(pace, 10_000, cost) for _ in range(4 + 16 + 32 + 64 + 1)]
    assert got[:4] == [2, 2, 1, 1]
    tries = [k for k, c in enumerate(got) if c == 2 and k >= 4]
    assert tries[0] == 4 + 15 and np.diff(tries).tolist() == [32, 64]
    cost = {2: 0.001, 1: 0.003}   # the machine is free again: threads win their next try
    got = [_tick(pace, 10_000, cost) for _ in range(140)]
    assert got[-1] == 2 and got[-10:] == [2] * 10


def test_pace_makes_no_choice_when_it_is_not_its_to_make(monkeypatch):
    """A small swarm, one core, a user's NUMBA_NUM_THREADS, or a batch's own limit:
    `chunks` decides as before."""
    pace = _pace(monkeypatch)
    assert pace.pick(threads.PACE_FROM - 1) is None
    assert _pace(monkeypatch, 1).pick(10**6) is None
    with threads.limited(1):
        assert pace.pick(10**6) is None
    monkeypatch.setenv("NUMBA_NUM_THREADS", "2")
    assert pace.pick(10**6) is None


def test_a_tick_with_one_thread_has_the_bits_of_a_threaded_one(monkeypatch):
    """The same run with its ticks on threads, on one, and as Pace chooses: the same
    columns (vicsek's kernels are compiled by other tests already)."""
    monkeypatch.setattr(threads, "MIN_PARALLEL", 0)
    monkeypatch.setattr(threads, "count", lambda: 2)
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    prog = load_program(PROGRAMS / "vicsek.swarm", {"n": 60})
    from swarmdsl.runtime.simulation import Simulation

    runs = []
    for limit in (None, 1, "paced"):
        if limit == "paced":
            monkeypatch.setattr(threads, "PACE_FROM", 0)
        sim = Simulation(prog, 4, backend="numba")
        if limit == 1:
            with threads.limited(1):
                sim.run(8)
        else:
            sim.run(8)
        runs.append(sim.agents.cols)
    for col in runs[0]:
        for other in runs[1:]:
            assert np.array_equal(runs[0][col], other[col]), col


def test_whole_ticks_are_refused_for_a_big_swarm_and_v_says_why():
    from swarmdsl.runtime.compiled import WHOLE_TICKS_MAX, tick_run
    from swarmdsl.runtime.simulation import Simulation

    prog = load_program(PROGRAMS / "vicsek.swarm", {"n": WHOLE_TICKS_MAX + 1})
    sim = Simulation(prog, 0, backend="numba")
    assert not sim.backend.whole_ticks_ready(sim, 1e9)
    assert sim.backend.advance(sim, 3) == -1
    assert sim.advance(2) == 2 and sim.tick == 2   # stepped instead
    line = tick_run.summary(sim.backend)[0]
    assert f"{WHOLE_TICKS_MAX + 1:,} agents" in line


@pytest.mark.slow
def test_threaded_statements_find_the_first_failing_agent(monkeypatch):
    """A statement split over threads gives the serial loop's values and stops at the
    same agent (the first failing one over every run of agents)."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.errors import SwarmRuntimeError
    from swarmdsl.runtime.compiled import stmt_kernels
    from swarmdsl.runtime.simulation import Simulation

    text = """
param n = 40
world { size 10 x 10; edges wrap }
agent a {
  count n
  var acc = 0
  status s {
    acc = acc + 1 / (index - 30)
  }
}
"""
    prog = compile_source(text, "t.swarm")
    errors = []
    for split in (False, True):
        monkeypatch.setattr(stmt_kernels, "THREADS_FROM", 0 if split else 10**9)
        monkeypatch.setattr(threads, "MIN_PARALLEL", 0 if split else 10**9)
        monkeypatch.setattr(threads, "count", lambda: 2)
        sim = Simulation(prog, 0, backend="numba")
        with pytest.raises(SwarmRuntimeError) as err:
            sim.run(2)
        errors.append(str(err.value))
    assert errors[0] == errors[1]


@pytest.mark.parametrize("name", ["vicsek.swarm", "boids.swarm"])
def test_tables_built_block_by_block_have_the_references_bits(monkeypatch, name):
    """The owner tables of a big swarm are gathered into cell order a block of rows at a
    time (`fused._owner_blocks`); with blocks of 16 rows a small run takes that path,
    and keeps the numpy backend's bits."""
    from swarmdsl.runtime.compiled import fused
    from swarmdsl.runtime.simulation import Simulation

    monkeypatch.setattr(fused, "_BLOCK", 16)
    prog = load_program(PROGRAMS / name, {"n": 60})
    runs = []
    for backend in ("numpy", "numba"):
        sim = Simulation(prog, 2, backend=backend)
        sim.run(5)
        runs.append(sim.agents.cols)
    for col in runs[0]:
        assert np.array_equal(runs[0][col], runs[1][col]), col
