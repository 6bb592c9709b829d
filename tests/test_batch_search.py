"""A numba batch's sums search every replica's own cell list directly
(`compiled/replica_cells.py`): no pair is written, and every replica keeps the bits of
its solo run; a reader of the pairs gets each replica's in its solo order."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings

pytest.importorskip("numba")

from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.compiler.errors import SwarmError  # noqa: E402
from swarmdsl.runtime import spatial  # noqa: E402
from swarmdsl.runtime.batch import BatchedSimulation  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402
from test_direct_search import FLOCK, direct_programs  # noqa: E402

SEEDS = [5, 11, 2**33 + 1]


def _batch(text, steps=4, monkeypatch=None, written=False, threads=None):
    if written:
        monkeypatch.setattr(spatial.CellPairs, "filled", property(lambda self: True))
    if threads:
        from swarmdsl.runtime.compiled import threads as pool

        monkeypatch.setattr(pool, "MIN_PARALLEL", 0)
        monkeypatch.setattr(pool, "count", lambda: threads)
    batch = BatchedSimulation(compile_source(text, "test.swarm"), SEEDS, backend="numba")
    batch.run(steps)
    if monkeypatch is not None:
        monkeypatch.undo()
    return batch


def assert_replicas_solo(batch, steps):
    """Every replica has the bits of its solo run. The solo runs are the reference
    backend's: a numba solo run has the same bits (tests/test_compiled.py), and it
    would compile a second set of kernels besides the batch's."""
    for r, seed in enumerate(batch.seeds):
        solo = Simulation(batch.program, seed, backend="numpy")
        solo.run(steps)
        for col, want in solo.agents.cols.items():
            got = batch.replica(r).agents.cols[col]
            assert got.tobytes() == want.tobytes(), (r, col)


@pytest.mark.parametrize("edges", ["wrap", "wall"])
def test_a_batchs_sums_search_each_replicas_cells_and_keep_solo_bits(edges):
    """In a world without edges each replica's grid follows its own agents' spread."""
    batch = _batch(FLOCK.format(edges=edges, extra=""))
    assert batch.backend.search_directly and not batch.pairs.filled
    assert batch.pairs.batch
    assert batch.agents.cols["n"].max() > 3   # every replica's agents have neighbours
    report = "\n".join(batch.backend.summary(batch.program))
    assert "in 4 of 4 ticks the sums searched the cells themselves" in report
    assert_replicas_solo(batch, 4)


def test_a_reader_of_a_batchs_pairs_gets_each_replicas_in_solo_order(monkeypatch):
    """`min` reads the written pairs (in cell order, replica by replica), the sums read
    them from the next tick on; the same bits as the sums searching."""
    text = FLOCK.format(edges="wall", extra="u = min(near : dist)")
    batch = _batch(text, steps=1)
    assert batch.pairs.filled
    batch.run(3)
    assert_replicas_solo(batch, 4)
    written = _batch(text, monkeypatch=monkeypatch, written=True)
    for col, want in written.agents.cols.items():
        assert np.array_equal(batch.agents.cols[col], want), col


def test_a_batchs_search_on_two_threads_gives_the_serial_bits(monkeypatch):
    """A reader of the pairs in a world with walls, the sums searching the cells in a
    world that wraps: on two threads, the serial batch's bits (the programs of the tests
    above, whose serial kernels are compiled once)."""
    text = FLOCK.format(edges="wall", extra="u = min(near : dist)")
    serial = _batch(text)
    threaded = _batch(text, monkeypatch=monkeypatch, threads=2)
    assert threaded.pairs.filled
    for col, want in serial.agents.cols.items():
        assert threaded.agents.cols[col].tobytes() == want.tobytes(), col
    plain = FLOCK.format(edges="wrap", extra="")
    threaded = _batch(plain, monkeypatch=monkeypatch, threads=2)
    assert not threaded.pairs.filled
    assert_replicas_solo(threaded, 4)


@settings(max_examples=2, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(direct_programs())
def test_generated_programs_batch_searched_to_their_solo_runs(text):
    """Sums searching beside filtered sets, narrower sets and aggregates over written
    pairs, replica by replica as their solo runs."""
    try:
        compile_source(text, "test.swarm")
    except SwarmError:
        assume(False)
    assert_replicas_solo(_batch(text, steps=3), 3)


# ---- the threads a batch ticks on ----

@pytest.mark.parametrize("load, agents, env, want", [
    (6.0, 10_000, None, 1),     # every core busy: threaded kernels wait for them
    (0.4, 10_000, None, 2),     # this process alone: both cores
    (1.8, 10_000, None, 1),
    (0.4, 500, None, 1),        # too few agents to repay joining the pool
    (6.0, 10_000, "2", 2),      # the user's NUMBA_NUM_THREADS decides
])
def test_a_batch_takes_threads_only_on_idle_cores(monkeypatch, load, agents, env, want):
    from swarmdsl.runtime.compiled import threads

    monkeypatch.setattr(threads, "count", lambda: 2)
    monkeypatch.setattr(threads.os, "getloadavg", lambda: (load, load, load))
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    if env:
        monkeypatch.setenv("NUMBA_NUM_THREADS", env)
    got, why = threads.for_batch(agents)
    assert got == want
    assert why.startswith(f"{want} ")
    if env is None and agents > threads.MIN_PARALLEL:
        assert f"load average {load:.1f} on 2 cores" in why


def test_a_batch_on_a_busy_machine_runs_its_kernels_serially(monkeypatch):
    """Past MIN_PARALLEL but with no idle core: every kernel of the tick is serial (one
    chunk), and the replicas keep their solo bits."""
    from swarmdsl.runtime.compiled import threads

    monkeypatch.setattr(threads, "MIN_PARALLEL", 0)
    monkeypatch.setattr(threads, "count", lambda: 2)
    monkeypatch.setattr(threads.os, "getloadavg", lambda: (7.0, 7.0, 7.0))
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    seen = []
    chunks = threads.chunks
    monkeypatch.setattr(threads, "chunks", lambda n: seen.append(chunks(n)) or seen[-1])
    batch = BatchedSimulation(compile_source(FLOCK.format(edges="wrap", extra=""),
                                             "test.swarm"), SEEDS, backend="numba")
    assert batch.threads == 1 and "load average 7.0" in batch.threads_why
    batch.run(2)
    assert seen and set(seen) == {1}
    assert threads.chunks(10_000) > 1   # outside the batch's tick: numba's own count
    monkeypatch.undo()
    assert_replicas_solo(batch, 2)


def test_sweep_v_says_which_threads_a_batch_takes(monkeypatch, tmp_path, capsys):
    from pathlib import Path

    from swarmdsl.cli import main
    from swarmdsl.runtime.compiled import threads

    monkeypatch.setattr(threads.os, "getloadavg", lambda: (5.0, 5.0, 5.0))
    monkeypatch.setattr(threads, "count", lambda: 2)
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    vicsek = Path(__file__).resolve().parent.parent / "programs" / "vicsek.swarm"
    args = ["sweep", str(vicsek), "--set", "n=10", "--seeds", "2", "--steps", "2",
            "--out", str(tmp_path / "s"), "-v"]
    assert main([*args, "--workers", "1"]) == 0
    assert ("threads: a numba batch of 2,000 agents or more ticks on 1 of 2 threads "
            "(load average 5.0 on 2 cores") in capsys.readouterr().err
