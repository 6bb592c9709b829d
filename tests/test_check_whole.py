"""`swarmdsl run --check` in whole ticks: the check extension hands its invariants to
the whole-tick kernel (`driver.Watch`, `testing/monitor._CheckExtension.watch`), and
the run ends as the run checked tick by tick does: the same violation at the same tick
with the same message and exit code, the same outputs, the same checkpoint; what the
kernel cannot check keeps the run per tick, and `-v` says which and why.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from swarmdsl.cli import main
from swarmdsl.runtime.driver import Driver, Watch

PROGRAMS = Path(__file__).resolve().parents[1] / "programs"
BOIDS = PROGRAMS / "boids.swarm"

# Vicsek's particles with properties: an age that grows by a random amount each tick
# (so the first agents over the bound depend on every draw), the speed bound, a swarm
# invariant, an `eventually` decided early and an `always` (never whole).
AGEING = """
param n = 30
world { size 10 x 10; edges wrap; steps 120 }
agent particle {
  count n
  velocity random_direction() * 0.03
  var age = 0
  status moving {
    let near = neighbors(1)
    let heading_sum = sum(near : normalize(other.vel)) + normalize(vel)
    velocity = unit(angle(heading_sum) + uniform(-0.5, 0.5)) * 0.03
    age = age + uniform(0, 1)
  }
  invariant young: age < 31
  invariant cruising: speed <= 0.03 * 1.000001
  always aged: age > 40 -> eventually age < 0 within 5
}
invariant inside: all(pos.x >= 0 and pos.x <= 10)
eventually started within 20: any(age > 3)
metric oldest = max(age)
"""


@pytest.fixture(autouse=True)
def _whole_ticks_pay(monkeypatch):
    """Whole ticks taken as soon as one tick stepped was timed, whatever the timings
    (which decide only the pace, never a result: on a loaded machine a slow whole
    call could otherwise put a run back on stepping before the tick a test is
    about)."""
    from swarmdsl.runtime import driver

    monkeypatch.setattr(driver._Pace, "whole_may_pay",
                        lambda self: self.ticks[False] + self.ticks[True] > 0)


def _warm(path: Path, sets=()) -> None:
    """The program's whole-tick kernel compiled (or loaded) in this process."""
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.simulation import Simulation

    prog = compile_file(path, dict(s.split("=") for s in sets))
    Simulation(prog, 0, backend="numba").advance(2)


def _run(capsys, monkeypatch, argv: list[str], whole: bool) -> tuple[int, list[str]]:
    """`swarmdsl run ARGV`, whole ticks allowed or not: its exit code and the lines
    of its error output that are not progress or timing."""
    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1" if whole else "0")
    code = main(["run", *argv])
    err = capsys.readouterr().err
    return code, [line for line in err.splitlines() if not line.startswith("tick ")]


def _outputs(out: Path) -> dict:
    """What a run wrote, timing left out: rows, metrics, run.json's outcome."""
    got = {"agents": pq.read_table(out / "agents.parquet").to_pydict()}
    if (out / "metrics.parquet").exists():
        got["metrics"] = pq.read_table(out / "metrics.parquet").to_pydict()
    meta = json.loads((out / "run.json").read_text())
    got["run"] = {k: meta.get(k) for k in ("finished", "violation", "last_tick",
                                          "recorded_ticks", "metrics", "status_counts")}
    return got


def _verbose(lines: list[str]) -> list[str]:
    return [line for line in lines if line.startswith(("whole-tick kernel", "--check"))]


def test_a_clean_checked_boids_run_is_the_unchecked_run_and_says_whole(
        tmp_path, capsys, monkeypatch, backend):
    """Boids' invariants hold: `--check` records what the unchecked run records, bit
    for bit, whole ticks or not; on numba its ticks ran whole, checked in the kernel
    at every tick (`-v`)."""
    if backend == "numba":
        _warm(BOIDS, ["n=30"])
    common = [str(BOIDS), "--headless", "--steps", "60", "--set", "n=30", "--seed", "4",
              "--backend", backend]
    runs = {}
    for label, extra, whole in (("checked", ["--check"], True),
                                ("unchecked", [], True),
                                ("stepped", ["--check"], False)):
        out = tmp_path / label
        code, lines = _run(capsys, monkeypatch, [*common, *extra, "--out", str(out),
                                                 "--every", "7", "-v"], whole)
        assert code == 0, lines
        runs[label] = _outputs(out)
        if label == "checked" and backend == "numba":
            line = _verbose(lines)[0]
            # every tick that ran whole checked in the kernel, however few the run
            # records (the first ticks step while the driver times them)
            got = re.match(r"whole-tick kernel: yes \(([\d,]+) ticks in .*; properties "
                           r"checked in the kernel at ([\d,]+) ticks", line)
            assert got and got[1] == got[2] and int(got[1]) >= 40, lines
    assert runs["checked"] == runs["unchecked"] == runs["stepped"]
    # without --out the metrics are sampled in the kernel too, every 7 ticks, while
    # the properties are checked at every tick: the unchecked run's samples
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.runner import Run
    from swarmdsl.testing.monitor import enable_checks

    samples = []
    for checked in (True, False):
        prog = compile_file(BOIDS, {"n": "30"})
        if checked:
            enable_checks(prog)
        monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1" if checked else "0")
        run = Run(prog, seed=4, steps=60, every=7, backend=backend)
        run.show_progress = False
        assert run.execute() == "completed"
        ticks, values = run.metrics.pending()
        samples.append((ticks.tolist(), values.tobytes()))
        if checked and backend == "numba":
            from swarmdsl.runtime.compiled import tick_run

            line = tick_run.summary(run.sim.backend)[0]
            got = re.match(r"whole-tick kernel: yes \(([\d,]+) ticks in .*; properties "
                           r"checked in the kernel at ([\d,]+) ticks; metrics sampled",
                           line)
            assert got and got[1] == got[2], line
    assert samples[0] == samples[1]
    assert samples[0][0] == [*range(0, 60, 7), 60]


def test_a_resumed_checked_boids_run_checks_and_records_as_one_run(
        tmp_path, capsys, monkeypatch, backend):
    """Checkpointed at tick 20 and resumed to 50 with ticks whole: the checkpoint
    keeps the check's state (what it had exercised), the resumed run checks the same
    properties, and its outputs are those of one run of 50 ticks."""
    if backend == "numba":
        _warm(BOIDS, ["n=30"])
    common = [str(BOIDS), "--headless", "--set", "n=30", "--seed", "2", "--check",
              "--backend", backend]
    one, split = tmp_path / "one", tmp_path / "split"
    assert _run(capsys, monkeypatch, [*common, "--steps", "50", "--out", str(one)],
                False)[0] == 0
    assert _run(capsys, monkeypatch, [*common, "--steps", "20", "--out", str(split),
                                      "--checkpoint-every", "10"], True)[0] == 0
    meta = json.loads((split / "checkpoint" / "meta.json").read_text())
    assert meta["check"] == "all"
    check = meta["extensions"]["0:_CheckExtension"]
    assert check["exercised"] == ["boid.at_most_cruise", "inside_world"]
    # (no more checkpoints: they would keep the resumed run per tick)
    code, lines = _run(capsys, monkeypatch, [*common, "--steps", "50", "--resume",
                                             str(split), "--checkpoint-every", "0", "-v"],
                       True)
    assert code == 0, lines
    if backend == "numba":
        assert _verbose(lines)[0].startswith("whole-tick kernel: yes"), lines
    mine, theirs = _outputs(split), _outputs(one)
    assert mine["agents"] == theirs["agents"]
    assert mine["metrics"] == theirs["metrics"]


class _Sim:
    """A simulation whose backend runs whole ticks with a watch, its property failing
    at tick 7 (the call stops there, as the kernel does), and whose one extension
    checks properties (`run --check`'s): tick by tick in `end_tick`, or whole."""

    def __init__(self):
        self.tick = 0
        self.program = None
        self.backend = self
        self.compile_seconds = 0.0
        self.calls = []             # (tick, ticks, covered)
        self.extensions = [_Check()]

    def step(self):                 # far slower a tick than whole ticks: they pay
        time.sleep(0.002)
        self.tick += 1
        self.extensions[0].end_tick(self)

    def whole_ticks_ready(self, sim, left=0.0, watch=None):
        return watch is not None and any(e is self.extensions[0] for e in watch.covers)

    def advance(self, _sim, ticks, watch):
        self.calls.append((self.tick, ticks))
        stop = 7 - self.tick if self.tick < 7 <= self.tick + ticks else ticks
        self.tick += stop
        watch.failed = self.tick == 7
        watch.agent_ticks = {p: stop - watch.failed for p in watch.properties}
        return stop


class _Check:
    def __init__(self):
        self.seen, self.counted, self.found = [], 0, None

    def end_tick(self, sim):
        self.seen.append(sim.tick)
        self.found = sim.tick if sim.tick == 7 else None

    def watch(self, sim):
        return Watch(("p",), each_tick=True)

    def watched(self, sim, watch):
        self.counted += watch.agent_ticks["p"]
        if watch.failed:        # the tick where the kernel stopped, checked here
            self.end_tick(sim)


class _Recorder:
    def __init__(self):
        self.seen = []

    def start(self, driver):
        pass

    def tick(self, driver):
        self.seen.append(driver.sim.tick)

    def close(self, driver, outcome):
        pass


def test_the_driver_runs_a_checking_extensions_ticks_whole_up_to_each_record():
    """An extension that offers a watch (and a check that stops the run on what it
    found): its ticks go whole with the watch, cut at each tick the observers see
    (they offer none: they see those as usual); the check stops the run after the
    failing tick, which the extension checked itself."""
    sim = _Sim()
    driver = Driver(sim, 20, every=5)
    rec = _Recorder()
    driver.observers.append(rec)

    def stop_at_violation(d):
        if sim.extensions[0].found is not None:
            raise RuntimeError(f"violated at {sim.extensions[0].found}")

    driver.checks.append(stop_at_violation)
    assert driver.drive() == "fault"
    assert sim.tick == 7 and "violated at 7" in str(driver.error)
    # tick 1 stepped (the driver times one first), then whole up to the record at 5
    assert sim.calls == [(1, 4), (5, 5)]
    assert sim.extensions[0].seen == [1, 7]
    assert sim.extensions[0].counted == 4 + 1
    assert rec.seen == [0, 5]


def test_without_a_watch_a_check_sees_every_tick():
    """An extension whose watch is None (an `always`): every tick steps."""
    sim = _Sim()
    sim.extensions[0].watch = lambda s: None
    driver = Driver(sim, 6, every=3)
    driver.observers.append(_Recorder())
    driver.checks.append(lambda d: None)
    assert driver.drive() == "completed"
    assert sim.calls == [] and sim.extensions[0].seen == [1, 2, 3, 4, 5, 6]


@pytest.mark.slow   # a kernel of its own: compiles for tens of seconds
@pytest.mark.parametrize("out", [False, True])
def test_a_violation_found_whole_is_the_one_found_tick_by_tick(tmp_path, capsys,
                                                               monkeypatch, out):
    """The particles' `young` fails at a tick and for agents every draw decides: in
    whole ticks (the open `eventually` steps the first ticks, then the kernel checks)
    the run stops at the same tick with the same located message and exit code, and
    records the same outputs, as the run checked tick by tick on numba and on the
    reference; `-v` says ticks ran whole. With the `always` checked too, the run
    steps, and `-v` says why."""
    path = tmp_path / "ageing.swarm"
    path.write_text(AGEING)
    _warm(path)
    props = ["--property", "particle.young", "--property", "inside",
             "--property", "started", "--property", "particle.cruising"]
    got = {}
    for label, backend, whole in (("whole", "numba", True), ("stepped", "numba", False),
                                  ("reference", "numpy", False)):
        folder = tmp_path / label
        argv = [str(path), "--headless", "--seed", "3", "--backend", backend, *props,
                "-v"] + (["--out", str(folder), "--every", "4"] if out else [])
        code, lines = _run(capsys, monkeypatch, argv, whole)
        errors = [line for line in lines if "error:" in line or line.startswith(" ")]
        got[label] = (code, errors, _outputs(folder) if out else None)
        if label == "whole":
            ticking = _verbose(lines)
            assert ticking[0].startswith("whole-tick kernel: yes"), lines
            assert "stopped at a property that failed" in ticking[0], ticking
            assert ticking[1].startswith("--check: ticks checked one by one while "
                                         "`eventually started`"), ticking
    assert got["whole"] == got["stepped"] == got["reference"]
    code, errors, _ = got["whole"]
    assert code == 1
    assert "error: invariant `particle.young` violated at tick" in errors[0]
    # the `always` is checked in Python every tick: the run steps, and says why
    code, lines = _run(capsys, monkeypatch, [str(path), "--headless", "--seed", "3",
                                             "--backend", "numba", "--check", "-v"], True)
    assert code == 1
    assert _verbose(lines) == ["whole-tick kernel: no (--check: `always particle.aged` "
                               "is watched in Python every tick)"], lines


def test_a_property_the_kernel_cannot_check_keeps_the_run_per_tick_and_says_why(
        tmp_path, capsys, monkeypatch, backend):
    """Vicsek with an invariant reading `previous(X)`: nothing compiles (the kernel
    refuses the property before it would compile), the run steps, and `-v` names the
    property and why; the run still checks it and passes."""
    text = (PROGRAMS / "vicsek.swarm").read_text().replace(
        "  metric speed = mean(speed)\n",
        "  metric speed = mean(speed)\n  invariant steady: speed >= previous(speed) - 1\n")
    path = tmp_path / "vicsek_previous.swarm"
    path.write_text(text)
    code, lines = _run(capsys, monkeypatch, [str(path), "--headless", "--steps", "12",
                                             "--set", "n=30", "--check", "--backend",
                                             backend, "-v"], True)
    assert code == 0, lines
    if backend == "numba":
        assert _verbose(lines) == [
            "whole-tick kernel: no (the property `particle.steady`: "
            "`previous(...)` at line 29 (the monitor keeps what it saw last))"], lines
    else:
        assert _verbose(lines) == []


def test_a_violation_not_yet_raised_offers_no_watch(backend):
    """A check extension holding a violation (found at tick 0 here) lets the next tick
    step, so that `begin_tick` raises it, whoever drives the simulation."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.errors import SwarmRuntimeError
    from swarmdsl.runtime.simulation import Simulation
    from swarmdsl.testing.monitor import enable_checks

    prog = compile_source("world { size 10 x 10 }\nagent a { count 3; var e = 1\n"
                          "  status s { e = e + 1 }\n  invariant low: e < 1\n}\n", "t.swarm")
    enable_checks(prog)
    sim = Simulation(prog, 0, backend=backend)
    ext = sim.extensions[0]
    assert ext.pending and ext.watch(sim) is None
    with pytest.raises(SwarmRuntimeError, match="invariant `a.low` violated at tick 0"):
        sim.run(5, on_tick=lambda s: None)     # a driver that asks for watches
    assert sim.tick == 0
