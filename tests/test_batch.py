"""A batch of replicas (`runtime/batch.py`) is each replica's solo run, bit for bit.

Every test compares a `BatchedSimulation` of R seeds on the test's backend with R solo
`Simulation`s of the same program after as many ticks: every agent column and every
metric must be equal to the last bit (not close: equal), or the batch is not a faster
way to run the same experiment. What a batch cannot run exactly it refuses, naming the
construct and its line.

The solo runs are the reference backend's (`SOLO`): a numba solo run has the same bits
(`tests/test_compiled.py` holds the two backends to that), so a numba batch equal to
them is equal to its numba solo runs, and the test compiles only the batch's kernels,
not a second set for the solo runs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import backend_names
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from swarmdsl import load_program
from swarmdsl.compiler import compile_source
from swarmdsl.compiler.lang_properties import along_replicas
from swarmdsl.errors import SwarmError, SwarmOptionError, SwarmRuntimeError
from swarmdsl.runtime.batch import BatchedSimulation, ReplicaFault, batch_refusal
from swarmdsl.runtime.metrics import MetricLog
from swarmdsl.runtime.simulation import MAX_SEED, Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
# Small swarms of the shipped programs a batch runs (the others are refused below).
SMALL = {"vicsek": {"n": 30}, "boids": {"n": 20}, "boids_leader": {"n": 12},
         "spring1d": {"turn_noise": 0.1, "pace_noise": 0.1}, "matrix2d": {}}
# The backend of the solo runs a batch is compared with (module docstring).
SOLO = "numpy"


def assert_replicas_are_solo_runs(program, seeds, backend, ticks):
    """Step a batch and a solo run per seed `ticks` times: equal columns, metrics."""
    batch = BatchedSimulation(program, seeds, backend=backend)
    batch.run(ticks)
    rows = batch.metric_rows()
    assert rows.shape == (len(seeds), len(program.metrics))
    for r, seed in enumerate(seeds):
        solo = Simulation(program, seed, backend=SOLO)
        solo.run(ticks)
        view = batch.replica(r)
        assert view.seed == seed and view.tick == solo.tick == batch.tick
        assert set(view.agents.cols) == set(solo.agents.cols)
        for col, values in solo.agents.cols.items():
            got = view.agents.cols[col]
            assert got.dtype == values.dtype and got.tobytes() == values.tobytes(), \
                f"replica {r} (seed {seed}): column {col} differs"
        log = MetricLog(program)
        log.sample(solo)
        want = log.pending()[1].reshape(-1)   # (k,): no metrics, no values
        assert want.tobytes() == rows[r].tobytes(), f"replica {r} metrics"
        assert view.status_counts() == solo.status_counts()
        mine, theirs = vars(view.snapshot()), vars(solo.snapshot())   # links, LEDs...
        assert mine.keys() == theirs.keys()
        for key, value in theirs.items():
            assert _same(mine[key], value), key


def _same(a, b) -> bool:
    """Equal to the bit: arrays, and dicts of them (a snapshot's fields by name)."""
    if isinstance(b, dict):
        return isinstance(a, dict) and a.keys() == b.keys() and all(
            _same(a[k], v) for k, v in b.items())
    return np.array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("name", sorted(SMALL))
def test_shipped_programs_batch_to_their_solo_runs(name, backend):
    program = load_program(PROGRAMS / f"{name}.swarm", SMALL[name] or None)
    assert batch_refusal(program) is None
    assert_replicas_are_solo_runs(program, [3, 7, 2**40 + 5], backend, 30)


def test_a_batch_big_enough_for_threads_is_its_solo_runs(backend):
    """25 x 100 agents: past `threads.MIN_PARALLEL`, the replicas' search and the
    fused kernels split over numba's threads (results identical for any count)."""
    from swarmdsl.runtime.compiled import threads

    program = load_program(PROGRAMS / "vicsek.swarm", {"n": 100})
    seeds = list(range(25))
    assert 100 * len(seeds) >= threads.MIN_PARALLEL
    batch = BatchedSimulation(program, seeds, backend=backend)
    batch.run(4)
    for r in (0, 13, 24):
        solo = Simulation(program, seeds[r], backend=SOLO)
        solo.run(4)
        for col in ("pos", "vel", "heading"):
            assert batch.replica(r).agents.cols[col].tobytes() == \
                solo.agents.cols[col].tobytes(), (r, col)


def test_every_shipped_program_is_batched_or_refused_in_words():
    for path in sorted(PROGRAMS.glob("*.swarm")):
        why = batch_refusal(load_program(path))
        assert why is None or ("not batched yet" in why and "line" in why), (path, why)


def test_a_call_no_row_declares_is_refused_not_batched(monkeypatch):
    """Batch eligibility is the rows' (`compiler/batching.py`): a call whose row is
    withdrawn is refused, located, rather than batched by default."""
    from swarmdsl.compiler.builtins import CALLS

    program = load_program(PROGRAMS / "aco.swarm")
    assert batch_refusal(program) is None
    monkeypatch.delitem(CALLS, "choose")
    why = batch_refusal(program)
    assert why is not None and why.startswith("`choose()` is not batched yet (`choose(...)`, "
                                              "line "), why


def test_bad_arguments_name_themselves():
    program = load_program(PROGRAMS / "vicsek.swarm", {"n": 5})
    with pytest.raises(SwarmOptionError, match="at least one seed"):
        BatchedSimulation(program, [], backend="numpy")
    with pytest.raises(SwarmError, match="seed"):
        BatchedSimulation(program, [1, -2], backend="numpy")
    batch = BatchedSimulation(program, [1, 2], backend="numpy")
    with pytest.raises(SwarmOptionError, match="replica must be 0 to 1"):
        batch.replica(2)


# A program whose only agent faults at tick 0 in about half of the seeds: `chance`
# picks the agents that take a square root of -1 (a NaN, a located fault).
_FAULTY = """world { size 20 x 20 }
agent a { count 1
  var got = 0
  status s { let q = sqrt(if chance(0.5) then -1 else 1)
    got = q }
}
"""


def _solo_fault(program, seed, backend, ticks=1):
    """(tick, message) of the solo run's fault within `ticks` (-1: placing), or None."""
    sim = None
    try:
        sim = Simulation(program, seed, backend=backend)
        sim.run(ticks)
    except SwarmRuntimeError as err:
        return (-1 if sim is None else sim.tick), str(err)
    return None


def test_a_fault_names_the_replica_and_is_its_solo_fault(backend):
    program = compile_source(_FAULTY, "faulty.swarm")
    outcomes = {s: _solo_fault(program, s, SOLO) for s in range(12)}
    outcomes = {s: f and f[1] for s, f in outcomes.items()}
    good = [s for s, f in outcomes.items() if f is None]
    bad = [s for s, f in outcomes.items() if f is not None]
    assert good and bad
    batch = BatchedSimulation(program, [good[0], bad[0], good[1]], backend=backend)
    with pytest.raises(ReplicaFault) as got:
        batch.step()
    assert got.value.replica == 1 and got.value.seed == bad[0]
    assert str(got.value.error) == outcomes[bad[0]]
    assert f"replica 1 (seed {bad[0]})" in str(got.value)


# Robots whose sensing drops, blurs and rounds neighbours, whose messages get lost and
# mismeasured, and whose motion is noisy for one kind only: every draw of a replica must
# be its solo draw even where another replica draws and it does not (no pairs in view,
# nobody noisy moving), and a stream drawn twice a tick (two neighbour sets) counts per
# replica.
_ROBOTS = """param noise = 0.2
robot eye { like kilobot; speed 2; heading_noise noise; speed_noise noise; loss 0.3
            distance_noise 0.5; neighbor_dropout 0.3; neighbor_noise 0.4
            neighbor_resolution 0.5; fov cone 1.2; comm_range 30 }
robot still { like kilobot; speed 2 }
world { size 60 x 60; edges wall }
agent a {
  robot eye
  count 5
  var seen = 0
  var got = 0
  message level num
  status look {
    let near = neighbors(8)
    let far = neighbors(20) where dist > 4
    seen = count(near) + 10 * count(far)
    got = sum(heard() : msg.level) + count(heard())
    broadcast(level, seen + uniform(0, 1))
    velocity = (uniform(-1, 1), uniform(-1, 1))
    when seen > 30 -> rest
  }
  status rest { velocity = (0, 0); when chance(0.2) -> look }
}
agent b {
  robot still
  count 3
  status go { velocity = (cos(tick / 5 + index), sin(tick / 5)) }
}
metric looking = count(status == look)
metric mean_seen = mean(seen)
"""


def test_robot_sensing_messages_and_noise_batch_to_their_solo_runs(backend):
    program = compile_source(_ROBOTS, "robots.swarm")
    assert batch_refusal(program) is None
    assert_replicas_are_solo_runs(program, [0, 1, 5, 99], backend, 25)


# Behaviour trees: memory and reactive composites, repeat, timeout, cooldown, long
# actions, a named tree used twice (one call site drawing twice a tick), draws in
# leaves; their state is agent columns the batch lays out per replica.
_TREES = """world { size 200 x 200; edges wall }
tree visit(p, tol) {
  sequence { move_to(p, tol, 2); wait(2) }
}
agent a {
  count 6
  var target = (uniform(10, 190), uniform(10, 190))
  var k = 0
  status roam {
    tree reactive fallback {
      sequence { chance(0.05); visit((100, 100), 3) }
      sequence { timeout 20 visit(target, 2); target = (uniform(10, 190), uniform(10, 190)) }
      cooldown 3 repeat 2 k = k + uniform(0, 1)
    }
    when tree failed -> rest
  }
  status rest { k = k + 1; when k > 5 -> roam }
}
metric mean_k = mean(k)
"""


def test_behaviour_trees_batch_to_their_solo_runs(backend):
    program = compile_source(_TREES, "trees.swarm")
    assert batch_refusal(program) is None
    assert_replicas_are_solo_runs(program, [0, 3, 7], backend, 40)


# Internal maps: notes where the agent stands and at sensed points, read back with
# recall, age, known and best; every map is agent columns, origins set when placed.
_MAPS = """world { size 100 x 100; edges wall }
agent a {
  count 5
  sense 15
  map seen 5 12
  var got = 0
  var old = 0
  velocity random_direction()
  status look {
    note(seen, uniform(0, 1) + pos.x / 100)
    note(seen, uniform(0, 1), pos + unit(heading) * 10)
    got = recall(seen, best(seen)) + (if known(seen, pos + (5, 0)) then 1 else 0)
    old = age(seen, pos - (5, 5))
    velocity = normalize(best(seen) - pos + (uniform(-1, 1), uniform(-1, 1)))
  }
}
metric mean_got = mean(got)
"""


def test_internal_maps_batch_to_their_solo_runs(backend):
    program = compile_source(_MAPS, "maps.swarm")
    assert batch_refusal(program) is None
    assert_replicas_are_solo_runs(program, [2, 4, 6], backend, 25)


# Path memories and direction choice: an environment without fields or regions.
_MEMORIES = """world { size 100 x 100; edges wall }
agent a {
  count 5
  memory trail 6
  velocity random_direction()
  var n = 0
  status out {
    remember(trail)
    velocity = unit(choose(8, 0.6)) * 2
    n = len(trail)
    when len(trail) >= 5 or at_edge(3) -> back
  }
  status back {
    retrace(trail)
    when len(trail) == 0 -> out
  }
}
"""


def test_path_memories_and_choices_batch_to_their_solo_runs(backend):
    program = compile_source(_MEMORIES, "memories.swarm")
    assert batch_refusal(program) is None
    assert_replicas_are_solo_runs(program, [1, 5, 9], backend, 30)


# Objectives toward points (per agent); toward another kind: tests/test_batch_nn.py.
_OBJECTIVES = """world { size 100 x 100; edges wall }
agent a {
  count 4
  var gy = uniform(10, 90)
  objective goal = (80, gy)
  status go {
    velocity = approach(goal, 3) + toward(goal) * uniform(0, 0.1)
    when arrived(goal, 2) -> wait
  }
  status wait { gy = uniform(10, 90); when chance(0.3) -> go }
}
"""


def test_objectives_toward_points_batch_to_their_solo_runs(backend):
    program = compile_source(_OBJECTIVES, "objectives.swarm")
    assert batch_refusal(program) is None
    assert_replicas_are_solo_runs(program, [3, 6, 12], backend, 30)


def test_run_any_answers_per_replica():
    """What a robot body asks before it draws motion noise: whether any agent of the
    run moves noisily, answered per replica in a batch (for each agent row)."""
    program = load_program(PROGRAMS / "vicsek.swarm", {"n": 3})
    batch = BatchedSimulation(program, [1, 2, 3], backend="numpy")
    mask = np.zeros(9, bool)
    mask[4] = True
    assert batch.run_any(mask).tolist() == [False] * 3 + [True] * 3 + [False] * 3
    solo = Simulation(program, 1, backend="numpy")
    assert solo.run_any(np.array([False, True, False])).tolist() == [True] * 3


# Metrics of every form: swarm and per-kind aggregates, vectors, conditions, statuses
# nobody is in in some replicas, `else` (evaluated replica by replica), a kind with no
# agents, constants.
_METRICS = """param k = 2
world { size 30 x 30; edges wrap }
agent a {
  count 7
  var e = 0
  velocity random_direction()
  status s { e = e + uniform(0, 1); when chance(0.1) -> t }
  status t { e = e * 0.5 }
  metric mean_e = mean(e)
  metric spread = max(pos.x) - min(pos.x)
  metric lowest = min(e else -1)
}
agent b {
  count 3
  velocity (uniform(-1, 1), 0)
  status u { }
}
agent c {
  count 0
  status w { }
  metric none = max(index else -7)
  metric many = count(index >= 0)
}
metric resting = count(status == t)
metric order = length(mean(normalize(vel)))
metric total = length(sum(vel)) + sum(index)
metric all_left = all(pos.x < 15)
metric any_left = any(pos.x < 15)
metric resting_e = mean(if status == t then e else 0 else -1)
metric constant = k * 3
metric ticks = tick
"""


def test_metrics_of_every_form_are_each_replicas(backend):
    program = compile_source(_METRICS, "metrics.swarm")
    assert len(program.metrics) == 13
    assert_replicas_are_solo_runs(program, [4, 8, 15, 16], backend, 12)


# ---- generated programs ----

from test_compiled import generated_programs  # noqa: E402
from welltyped import programs as welltyped_programs  # noqa: E402

SEEDS = st.lists(st.integers(0, MAX_SEED), min_size=1, max_size=3)


def assert_batch_is_its_solo_runs_or_faults_alike(text, seeds, backend, ticks):
    """`text` batched over `seeds` is each seed's solo run, or, when a solo run faults,
    the batch raises the first faulting replica's own fault."""
    try:
        program = compile_source(text, "gen.swarm")
    except SwarmError:
        assume(False)
    assume(batch_refusal(program) is None)
    faults = [_solo_fault(program, s, SOLO, ticks) for s in seeds]
    if any(faults):   # the batch faults as the first replica to fault does
        first = min((f[0], r) for r, f in enumerate(faults) if f)[1]
        with pytest.raises(ReplicaFault) as got:
            BatchedSimulation(program, seeds, backend=backend).run(ticks)
        assert (got.value.replica, str(got.value.error)) == (first, faults[first][1])
        return
    assert_replicas_are_solo_runs(program, seeds, backend, ticks)


@settings(max_examples=3, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(generated_programs(), SEEDS)
def test_generated_neighbour_programs_batch_to_their_solo_runs(backend, text, seeds):
    assert_batch_is_its_solo_runs_or_faults_alike(text, seeds, backend, 4)


@settings(max_examples=2, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(welltyped_programs(), SEEDS)
def test_well_typed_programs_batch_to_their_solo_runs(backend, text, seeds):
    assert_batch_is_its_solo_runs_or_faults_alike(text, seeds, backend, 3)


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.one_of(generated_programs(), welltyped_programs()), SEEDS)
def test_generated_programs_batch_long(backend, text, seeds):
    assert_batch_is_its_solo_runs_or_faults_alike(text, seeds, backend, 6)


# ---- the compiled search of replicas ----

from test_compiled import layouts  # noqa: E402


def assert_same_table(a, b):
    for name in ("offsets", "i", "j", "dist", "delta"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), name


@settings(max_examples=80, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.lists(layouts(), min_size=1, max_size=4), st.data())
def test_the_replica_search_is_each_replicas_solo_table(replicas, data):
    """Replicas of one world (the first layout's radius and box), each with its own
    agents (cell borders, world edges, -0.0): the one-call search gives the row-order
    table of the solo cell list, replica by replica, rows shifted."""
    from swarmdsl.runtime.backends import make as make_backend
    from swarmdsl.runtime.batch import _joined_pairs

    _pos, radius, box = replicas[0]
    parts = [pos for pos, _r, _b in replicas]
    bounds = np.zeros(len(parts) + 1, np.int64)
    np.cumsum([p.shape[0] for p in parts], out=bounds[1:])
    backend = make_backend(data.draw(st.sampled_from(backend_names())))
    got = backend.replica_pairs(np.concatenate(parts), bounds, radius, box)
    assume(got is not None)   # numpy: a window the whole way round searches per replica
    want = _joined_pairs(radius, [backend.pairs_table(p, radius, box) for p in parts],
                         bounds)
    assert_same_table(got, want)


def test_the_batch_benchmark_runs_and_reports_its_gain():
    from benchmarks.bench_batch import bench

    program = load_program(PROGRAMS / "vicsek.swarm", {"n": 4})
    got = bench(program, replicas=3, ticks=2, backend="numpy")
    assert got["agents"] == 4 and got["replicas"] == 3 and got["gain"] > 0
    assert got["batch_steps"] == pytest.approx(3 * 4 * got["batch_ticks"])


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 50), st.sampled_from([1, 2, 6, 8, 9, 24, 100, 127, 128, 129, 400]),
       st.integers(0, 2**32 - 1), st.sampled_from([1e-6, 1.0, 1e9]))
def test_reductions_along_replicas_are_the_solo_reductions(reps, n, seed, scale):
    """A batch's metrics reduce every replica's (n,) or (n, 2) values as one (R, n, ...)
    array along axis 1 (`along_replicas`: vectors laid out agent-major first); each row
    must round exactly as the solo run's own array does (`np.add.reduceat` does not: it
    sums in another order)."""
    rng = np.random.default_rng(seed)
    for shape in ((reps * n,), (reps * n, 2)):
        values = rng.standard_normal(shape) * scale
        grid = values.reshape(reps, n, *shape[1:])
        for reduce in (np.sum, np.mean, np.min, np.max):
            rows = along_replicas(reduce, grid)
            assert rows.tobytes() == reduce(grid, axis=1).tobytes()
            for r in range(reps):
                solo = reduce(values[r * n:(r + 1) * n].copy(), axis=0)
                assert np.asarray(solo).tobytes() == rows[r].tobytes(), (reduce, shape)


def test_a_trees_recorded_leaf_columns_are_each_replicas():
    """`record_active_leaf` on a batch (what `run --tree-leaf` asks of a run) tracks
    every replica's leaves; each view offers the recorder its own rows of them."""
    from swarmdsl.runtime.trees import record_active_leaf

    program = compile_source(_TREES, "trees.swarm")
    batch = BatchedSimulation(program, [1, 2], backend="numpy")
    record_active_leaf(batch)
    batch.run(6)
    for r, seed in enumerate([1, 2]):
        solo = Simulation(program, seed, backend="numpy")
        record_active_leaf(solo)
        solo.run(6)
        view = batch.replica(r)
        assert view.record_columns.keys() == solo.record_columns.keys()
        for name, (_type, read) in solo.record_columns.items():
            mine, theirs = view.record_columns[name][1](view), read(solo)
            assert mine[0] == theirs[0] and np.array_equal(mine[1], theirs[1]), name
