"""Properties checked inside the whole-tick kernel (`compiled/tick_checks.py`): which
compile and why the others do not, and that a checked run's results (violations,
agent-ticks checked, premise ticks, exercised, the state) are the same whether its
ticks ran whole or one by one, on both backends.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

from swarmdsl import load_program  # noqa: E402
from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.runtime.compiled import tick_run  # noqa: E402
from swarmdsl.runtime.compiled.tick_checks import plan_checks  # noqa: E402
from swarmdsl.runtime.compiled.tick_plan import plan_tick  # noqa: E402
from swarmdsl.runtime.driver import Driver, Watch  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402
from swarmdsl.testing.monitor import Monitor  # noqa: E402
from swarmdsl.testing.runner import run_program  # noqa: E402

PROGRAMS = Path(__file__).resolve().parents[1] / "programs"

# Every shape of property: per agent and for the swarm, with and without a premise,
# two kinds, `tick`, the swarm aggregates the kernel takes, and the ones it does not
# (`previous`, a neighbour query, a swarm mean), an `eventually` and a property that
# starts failing at tick 45.
RICH = """
param n = 20 in 2..30
param cap = 3
world { size 30 x 30; edges wrap; steps 60 }
agent walker {
  count n
  sense 4
  velocity random_direction() * 0.5
  var boost = 1
  status roaming {
    let near = neighbors()
    boost = min(boost + 0.25 + 0.1 * count(near), cap)
    velocity = rotate(velocity, normal(0, 0.3))
    when boost >= cap -> resting
  }
  status resting {
    boost = 1
    when random() < 0.3 -> roaming
  }
  invariant capped: boost <= cap
  invariant calm: status != resting or boost >= cap or boost == 1
  invariant steady: not (status == resting) or speed < 10
  invariant late: tick < 40 or boost < 3.5
  invariant drains: boost >= previous(boost) - 10
  invariant alone: count(neighbors(2)) < 50
  metric mean_boost = mean(boost)
}
agent rock {
  count 3
  status still { }
}
invariant everyone: count() == n + 3
invariant few_resting: count(status == resting) <= n
invariant inside: min(pos.x) >= 0 and max(pos.y) <= 30
invariant moving: any(speed > 0) and all(kind != rock or speed == 0)
invariant early: tick < 45
invariant slow: mean(speed) < 100 and length(sum(vel)) >= 0
invariant monotone: count(status == resting) <= previous(count(status == resting)) + n
eventually someone_rests within 20: any(status == resting)
metric resting = count(status == resting) / n
metric drift = length(mean(vel))
metric spread = max(pos.x) - min(pos.x)
"""
COMPILED = ["walker.capped", "walker.calm", "walker.steady", "walker.late", "everyone",
            "few_resting", "inside", "moving", "early", "slow"]


def _rich(params=None):
    return compile_source(RICH, "rich.swarm", {k: str(v) for k, v in (params or {}).items()})


def test_boids_invariants_compile_into_its_kernel():
    prog = load_program(PROGRAMS / "boids.swarm")
    checks = plan_checks(prog, plan_tick(prog))
    assert [c.name for c in checks.checks] == ["inside_world", "boid.at_most_cruise"]
    assert checks.refused == {}
    assert all(c.premise is None for c in checks.checks)


def test_each_property_compiles_or_says_why():
    prog = _rich()
    checks = plan_checks(prog, plan_tick(prog))
    assert sorted(c.name for c in checks.checks) == sorted(COMPILED)
    assert "`previous(...)` at line 24" in checks.refused["walker.drains"]
    assert "a neighbour query at line 25" in checks.refused["walker.alone"]
    assert "`previous(...)` at line 38" in checks.refused["monotone"]
    assert "`eventually`" in checks.refused["someone_rests"]
    premised = {c.name for c in checks.checks if c.premise is not None}
    assert premised == {"walker.calm", "walker.steady"}     # `late` is no implication
    # numbers are constants, not part of the kernel's shape
    other = _rich({"n": 7, "cap": 5})
    assert plan_checks(other, plan_tick(other)).key == checks.key


def test_the_monitor_asks_only_for_what_it_still_checks():
    monitor = Monitor(_rich(), COMPILED + ["someone_rests"])
    assert monitor.watchable(0) is None        # the `eventually` is open
    assert sorted(monitor.watchable(20)) == sorted(COMPILED)   # ... and past its tick 20
    monitor._done["someone_rests"] = True
    assert sorted(monitor.watchable(3)) == sorted(COMPILED)
    always = compile_source("""
world { size 10 x 10 }
agent a { count 2; var e = 1; status s { e -= 1 }
  always low: e < 0 -> eventually e < -5 within 3 }
""", "a.swarm")
    assert Monitor(always).watchable(50) is None


@pytest.mark.parametrize("seed", [1, 4])
def test_boids_checked_runs_are_the_same_whole_or_per_tick(backend, seed, monkeypatch):
    """The tester's run of boids (both properties, premise counting on): the same
    counts, exercised properties and state whether its ticks ran whole with the
    properties checked in the kernel or one by one; and the same as the reference's."""
    prog = load_program(PROGRAMS / "boids.swarm", {"n": 30})
    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1")
    if backend == "numba":
        Simulation(prog, 0, backend="numba").advance(2)      # the kernel at hand
    whole = run_program(prog, 50, seed=seed, coverage=True)
    line = tick_run.summary(whole.sim.backend)
    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "0")
    stepped = run_program(prog, 50, seed=seed, coverage=True)
    monkeypatch.setenv("SWARMDSL_BACKEND", "numpy")
    reference = run_program(prog, 50, seed=seed, coverage=True)
    for other in (stepped, reference):
        assert _outcome(whole) == _outcome(other)
    assert whole.agent_ticks == {"inside_world": 51, "boid.at_most_cruise": 51 * 30}
    if backend == "numba":
        # (the first tick steps: the driver times one before any whole ticks)
        assert "properties checked in the kernel at" in line[0], line


def test_the_hunt_says_how_its_runs_ticked(monkeypatch):
    """`swarmdsl test -v`: each run's whole-tick line, counted over the runs."""
    from swarmdsl.testing.search import search

    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1")
    monkeypatch.setenv("SWARMDSL_BACKEND", "numba")
    prog = load_program(PROGRAMS / "boids.swarm", {"n": 12})
    Simulation(prog, 0, backend="numba").advance(2)
    report = search(prog, max_examples=3, steps=30, seeds=1, hypothesis_seed_value=1,
                    verbose=True)
    assert report.ticking.get("whole-tick kernel: yes (properties checked in the kernel "
                              "at N ticks)", 0) >= 1, report.ticking
    assert sum(report.ticking.values()) == report.examples


def test_the_hunt_says_which_property_kept_its_ticks_in_python(monkeypatch):
    """An `eventually` still open is watched in Python every tick: `test -v` says so,
    rather than that the backend could not run whole ticks."""
    from swarmdsl.testing.search import search

    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1")
    monkeypatch.setenv("SWARMDSL_BACKEND", "numba")
    text = (PROGRAMS / "boids.swarm").read_text() + \
        "\neventually settled within 25: tick >= 20\n"
    prog = compile_source(text, "boids.swarm", {"n": "12"})
    Simulation(prog, 0, backend="numba").advance(2)
    report = search(prog, max_examples=3, steps=30, seeds=1, hypothesis_seed_value=1,
                    verbose=True)
    said = "ticks checked one by one in Python while `eventually settled` is watched in " \
           "Python until it holds or its tick 25 passes"
    assert report.ticking.get(said, 0) >= 1, report.ticking
    assert report.ticking.get("whole-tick kernel: yes (properties checked in the kernel "
                              "at N ticks)", 0) >= 1, report.ticking


@pytest.mark.parametrize("line, alike", [
    ("whole-tick kernel: yes (1,500 ticks in 1 call)", "whole-tick kernel: yes"),
    ("whole-tick kernel: yes (1 tick in 1 call)", "whole-tick kernel: yes"),
    ("whole-tick kernel: yes (60 ticks in 3 calls; properties checked in the kernel at "
     "1,060 ticks)", "whole-tick kernel: yes (properties checked in the kernel at N ticks)"),
    ("whole-tick kernel: yes (9 ticks in 2 calls; 1 stopped at a check, that tick ran per "
     "tick)", "whole-tick kernel: yes (N stopped at a check, that tick ran per tick)"),
    ("whole-tick kernel: no (fewer than two agents)",
     "whole-tick kernel: no (fewer than two agents)"),
])
def test_runs_that_ticked_alike_are_counted_together(line, alike):
    from swarmdsl.testing.search import ticked_alike

    assert ticked_alike(line) == alike


def _outcome(r) -> tuple:
    state = {k: v.tobytes() for k, v in r.state.items() if not k.endswith("_name")}
    return (r.ticks, r.violations, r.fault, r.agent_ticks, r.premise_ticks,
            r.exercised, r.premised, state)


def test_a_property_the_kernel_cannot_check_keeps_the_run_per_tick(monkeypatch):
    """Its run goes tick by tick, the monitor checking each: stepped, or, where the
    whole-tick kernel is already at hand (kept on disk by an earlier run of this
    program), one tick to a call; and `-v` says which property and why."""
    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1")
    monkeypatch.setenv("SWARMDSL_BACKEND", "numba")
    prog = _rich()
    got = run_program(prog, 5, seed=0, properties=["walker.drains", "walker.capped"])
    assert got.ticks == 5 and got.ok
    why = ("(the property `walker.drains`: `previous(...)` at line 24 (the monitor keeps "
           "what it saw last))")
    lines = tick_run.summary(got.sim.backend)
    if lines[0].startswith("whole-tick kernel: yes"):
        ticks = re.fullmatch(r"whole-tick kernel: yes \((\d) ticks? in (\d) calls?\)", lines[0])
        assert ticks and ticks[1] == ticks[2]   # one tick a call, each checked after it
        assert lines[1:] == [f"properties checked in the kernel: no {why}"]
    else:
        assert lines == [f"whole-tick kernel: no {why}"]


@pytest.mark.parametrize("name,every", [("boids", 1), ("vicsek", 7)])
def test_metrics_sampled_in_the_kernel_are_the_reference_samples(backend, name, every,
                                                                 monkeypatch):
    """A run recording only metrics (no `out`) takes whole ticks, the kernel sampling
    the metrics at the ticks the run records (`every`, and its last); the samples are
    the reference's, bit for bit, and the stepped run's on the same backend."""
    from swarmdsl.runtime.runner import Run

    prog = load_program(PROGRAMS / f"{name}.swarm", {"n": 40})
    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1")
    if backend == "numba":
        Simulation(prog, 0, backend="numba").advance(2)
    samples = {}
    for label, whole, on in (("run", "1", backend), ("stepped", "0", backend),
                             ("reference", "0", "numpy")):
        monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", whole)
        run = Run(prog, seed=2, steps=45, every=every, backend=on)
        run.show_progress = False
        assert run.execute() == "completed"
        ticks, values = run.metrics.pending()
        samples[label] = (ticks.tolist(), values.tobytes())
        if label == "run" and backend == "numba":
            line = tick_run.summary(run.sim.backend)[0]
            assert "metrics sampled in the kernel over" in line, line
    assert samples["run"] == samples["stepped"] == samples["reference"]
    assert samples["run"][0] == sorted({*range(0, 45, every), 45})


def test_a_kernel_kept_on_disk_runs_in_another_process(tmp_path):
    """The kernel with its observations, compiled here and kept on disk, is loaded and
    run by a fresh process (numba cannot keep a recursive function in its cache: a
    kernel calling one crashed when loaded)."""
    import subprocess
    import sys

    prog = load_program(PROGRAMS / "vicsek.swarm", {"n": 40})
    Simulation(prog, 0, backend="numba").advance(2)
    script = (
        "import sys\n"
        "from swarmdsl import load_program\n"
        "from swarmdsl.runtime.runner import Run\n"
        "from swarmdsl.runtime.compiled import tick_run\n"
        f"prog = load_program({str(PROGRAMS / 'vicsek.swarm')!r}, {{'n': 40}})\n"
        "run = Run(prog, seed=2, steps=30, every=7, backend='numba')\n"
        "run.show_progress = False\n"
        "assert run.execute() == 'completed'\n"
        "print(tick_run.summary(run.sim.backend)[0], run.sim.backend.compile_seconds)\n")
    env = {**__import__("os").environ, "SWARMDSL_WHOLE_TICKS": "1"}
    got = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env=env, timeout=600)
    assert got.returncode == 0, got.stderr[-2000:]
    assert "metrics sampled in the kernel over" in got.stdout, got.stdout


def test_sums_of_numbers_add_in_numpys_order():
    """`np.sum` and `np.mean` of a contiguous float64 array add pairwise in blocks; the
    kernel's `_pairwise` adds in that order (sizes across its block and halving
    thresholds, values of every magnitude and sign, zeros of both signs)."""
    from swarmdsl.runtime.compiled.tick_checks import _pairwise

    rng = np.random.default_rng(3)
    for n in [*range(0, 140), 255, 256, 257, 1000, 4099, 9000]:
        a = rng.normal(size=n) * 10.0 ** rng.integers(-8, 9, size=n)
        a[rng.random(n) < 0.05] = -0.0
        S = np.ascontiguousarray(np.stack([rng.random(n), a], axis=1))
        got = 0.0 + _pairwise(S, 1, 0, n)
        assert np.float64(got).tobytes() == np.sum(a).tobytes(), n
        if n:
            assert np.float64(got / n).tobytes() == np.mean(a).tobytes(), n


class _Ticks:
    """A simulation whose backend runs ticks whole with a watch (or refuses watches),
    and whose property 'fails' at tick 7 (the backend stops the call there, as the
    kernel would)."""

    def __init__(self, refuse_watches=False):
        self.tick = 0
        self.program = None
        self.backend = self
        self.compile_seconds = 0.0
        self.calls = []         # (tick, ticks, watched)
        self.refuse = refuse_watches

    def step(self):         # far slower a tick than whole ticks: they pay
        time.sleep(0.002)
        self.tick += 1

    def whole_ticks_ready(self, sim, left=0.0, watch=None):
        return not (self.refuse and watch is not None)

    def advance(self, *args):
        if len(args) == 1:          # `Simulation.advance(ticks)`: nothing watched
            self.calls.append((self.tick, args[0], False))
            self.tick += args[0]
            return args[0]
        _sim, ticks, watch = args
        self.calls.append((self.tick, ticks, True))
        stop = 7 - self.tick if self.tick < 7 <= self.tick + ticks else ticks
        self.tick += stop
        watch.failed = self.tick == 7
        watch.agent_ticks = {p: 10 * (stop - watch.failed) for p in watch.properties}
        return stop


class _Observer:
    def __init__(self, props):
        self.props, self.seen, self.counts = props, [], {}

    def start(self, driver):
        pass

    def tick(self, driver):
        self.seen.append(driver.sim.tick)

    def close(self, driver, outcome):
        pass

    def watch(self, driver):
        return Watch(self.props)

    def watched(self, driver, watch):
        for p in self.props:
            self.counts[p] = self.counts.get(p, 0) + watch.agent_ticks[p]


def test_the_driver_hands_watched_ticks_over_and_shows_a_failing_tick():
    """Observers that offer a watch see tick 0 and the first tick (stepped: the driver
    times one), then only the tick where a check failed; the ticks checked in the
    call are counted through `watched`, each observer its own properties."""
    sim = _Ticks()
    driver = Driver(sim, 20, every=1)
    a, b = _Observer(("p",)), _Observer(("q", "p"))
    driver.observers += [a, b]
    assert driver.drive() == "completed"
    assert sim.tick == 20
    assert a.seen == b.seen == [0, 1, 7]
    assert a.counts == {"p": 180} and b.counts == {"q": 180, "p": 180}
    assert sim.calls == [(1, 19, True), (7, 13, True)]
    # an observer without a watch: every tick is its own again, each still one call
    # of whole ticks after the first (stepped: the driver times one)
    sim = _Ticks()
    driver = Driver(sim, 5, every=1)
    driver.observers += [_Observer(("p",)), type("Plain", (_Observer,), {"watch": None})(())]
    driver.drive()
    assert sim.calls == [(t, 1, False) for t in (1, 2, 3, 4)]
    assert driver.observers[0].seen == [0, 1, 2, 3, 4, 5]
    # a backend that cannot compute the watch: whole ticks between the observed ones
    sim = _Ticks(refuse_watches=True)
    driver = Driver(sim, 12, every=5)
    driver.observers.append(_Observer(("p",)))
    driver.drive()
    assert sim.calls == [(1, 4, False), (5, 5, False), (10, 2, False)]
    assert driver.observers[0].seen == [0, 5, 10, 12]


@pytest.mark.slow   # the program's kernel compiles for tens of seconds
@pytest.mark.parametrize("stop", [True, False])
def test_every_property_shape_counts_alike_whole_or_per_tick(stop, monkeypatch):
    """The rich program on numba with its properties checked in the kernel (until
    tick 20 the open `eventually` keeps ticks one by one), against the reference
    stepped: the violation at tick 45 found (a run that goes on past it finds one at
    every later tick), every count the same."""
    checked = COMPILED + ["someone_rests"]
    for n in (2, 17):
        prog = _rich({"n": n})
        monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1")
        Simulation(prog, 0, backend="numba").advance(2)
        monkeypatch.setenv("SWARMDSL_BACKEND", "numba")
        whole = run_program(prog, 60, seed=n, coverage=True, properties=checked,
                            stop_at_first=stop)
        line = tick_run.summary(whole.sim.backend)[0]
        assert "properties checked in the kernel" in line, line
        monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "0")
        monkeypatch.setenv("SWARMDSL_BACKEND", "numpy")
        reference = run_program(prog, 60, seed=n, coverage=True, properties=checked,
                                stop_at_first=stop)
        assert _outcome(whole) == _outcome(reference)
        assert whole.violations[0].name == "early" and whole.violations[0].tick == 45
        assert whole.ticks == (45 if stop else 60)
        assert whole.premise_ticks.keys() == {"walker.calm", "walker.steady"}
        assert np.all(np.array(list(whole.agent_ticks.values())) > 0)


@pytest.mark.slow   # the rich program's kernel (compiled once for both slow tests)
def test_every_metric_shape_is_sampled_alike(monkeypatch):
    """Swarm and per-kind metrics (count, mean of numbers and vectors, min, max) of two
    kinds, sampled in the kernel every 3 ticks: the reference's samples, bit for bit."""
    from swarmdsl.runtime.runner import Run

    prog = _rich({"n": 23})
    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1")
    Simulation(prog, 0, backend="numba").advance(2)
    got = []
    for whole, backend in (("1", "numba"), ("0", "numpy")):
        monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", whole)
        run = Run(prog, seed=5, steps=40, every=3, backend=backend)
        run.show_progress = False
        assert run.execute() == "completed"
        ticks, values = run.metrics.pending()
        got.append((ticks.tolist(), values.tobytes()))
        if backend == "numba":
            line = tick_run.summary(run.sim.backend)[0]
            assert "metrics sampled in the kernel over" in line, line
    assert got[0] == got[1]
    assert values.shape == (15, 4)
