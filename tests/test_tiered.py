"""The tiered start: a run that starts on numpy and takes numba between two ticks gives
the bits of a run on either backend throughout (agents, metrics, fields, checkpoints);
a compile that fails or is killed leaves the run on numpy, saying so; the default takes
the tiered start for a first long run, and `--backend` still means one backend."""

from __future__ import annotations

import functools
import json
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

from swarmdsl.compiler import compile_file, compile_source  # noqa: E402
from swarmdsl.runtime import backends, checkpoint  # noqa: E402
from swarmdsl.runtime.compiled import tiered  # noqa: E402
from swarmdsl.runtime.compiled.tiered import TieredBackend  # noqa: E402
from swarmdsl.runtime.metrics import evaluate  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
TICKS = 9
# boids draws, aco deposits and samples a field and changes status, vicsek is chaotic
NAMES = ("boids.swarm", "aco.swarm", "vicsek.swarm", "mas_environment.swarm")


class _Ready:
    """A stand-in compile that is done at the `k`-th tick's end (None: never), with
    numba's shared kernels ready from the `shared`-th (None: only with the rest)."""

    def __init__(self, k, shared=None):
        self.k, self.shared, self.polls, self.seconds, self.reason = k, shared, 0, 0.0, ""

    def poll(self) -> str:
        self.polls += 1
        if self.k is not None and self.polls > self.k:
            return "done"
        return "shared" if self.shared is not None and self.polls > self.shared else \
            "running"


class _Failing(_Ready):
    def poll(self) -> str:
        self.polls += 1
        if self.polls > self.k:
            self.reason = "it broke"
            return "failed"
        return "running"


def _program(name: str):
    return compile_file(PROGRAMS / name, {"n": "60"} if name == "boids.swarm" else {})


def _state(sim) -> dict:
    out = {f"col/{k}": np.array(v) for k, v in sim.agents.cols.items()}
    for i, ext in enumerate(sim.extensions):
        for k, v in ext.state_dict(sim).items():
            out[f"ext/{i}/{k}"] = v
    out["tick"] = sim.tick
    out["rng"] = json.dumps(sim.rng.state(), sort_keys=True)
    return out


def _trace(program, backend: str, ticks: int = TICKS, seed: int = 3, sim=None) -> dict:
    """The state after `ticks` ticks and every tick's metrics."""
    sim = sim or Simulation(program, seed, backend=backend)
    rows = []
    for _ in range(ticks):
        sim.step()
        rows.append(evaluate(program.metrics, sim))
    out = _state(sim)
    out["metrics"] = np.array(rows)
    return out, sim


@functools.cache
def _reference(name: str, backend: str, ticks: int = TICKS):
    return _trace(_program(name), backend, ticks)[0]


def _assert_identical(a: dict, b: dict, what: str) -> None:
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], np.ndarray):
            assert a[k].dtype == b[k].dtype, k
            assert a[k].tobytes() == b[k].tobytes(), f"{k} differs from the {what} run"
        else:
            assert a[k] == b[k], k


def _stand_in(monkeypatch, compile_) -> None:
    monkeypatch.setattr(tiered, "compile_for", lambda program, argv=None: compile_)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("switch", [0, 4, None, (2, 6), (1, None)])
def test_a_tiered_run_is_bit_identical_to_numpy_and_to_numba(monkeypatch, name, switch):
    """Switching at any tick, straight to numba or through numba's shared kernels
    first (`switch` = (shared from, numba from)), gives the same bits."""
    shared, done = switch if isinstance(switch, tuple) else (None, switch)
    _stand_in(monkeypatch, _Ready(done, shared))
    got, sim = _trace(_program(name), "tiered")
    why = getattr(sim.backend, "why", "")
    if shared is not None:
        assert isinstance(sim.backend, tiered.SharedFirst)
        assert f"ticks 0-{shared} on numpy, " in why
        if done is None:
            assert f"numba's shared kernels from tick {shared + 1}" in why
            assert "the program's aggregates and statements on the reference" in why
            parts = [ln for ln in sim.backend.summary(sim.program) if ln[0].isdigit()]
            assert parts and not any(": compiled" in ln for ln in parts)
            assert all(ln.endswith(": the reference closures (its kernels were not on "
                                   "disk yet)") for ln in parts if ": numpy (" not in ln)
        else:
            assert f"ticks {shared + 1}-{done} on numba's shared kernels" in why
            assert f"numba from tick {done + 1}" in why
    elif done is None:
        assert isinstance(sim.backend, TieredBackend)
    else:
        assert sim.backend.name == "numba"
        assert f"numba from tick {done + 1}" in why
    _assert_identical(got, _reference(name, "numpy"), "numpy")
    _assert_identical(got, _reference(name, "numba"), "numba")


def test_fields_of_a_tiered_run_take_the_compiled_class_when_it_switches(monkeypatch):
    from swarmdsl.runtime.compiled.fields import CompiledField
    from swarmdsl.runtime.fields import Field

    own = {n for n, v in vars(CompiledField).items() if callable(v)}
    assert own == set(tiered.FIELD_METHODS)
    _stand_in(monkeypatch, _Ready(2))
    sim = Simulation(_program("aco.swarm"), 1, backend="tiered")
    fields = list(sim.environment.fields.values())
    assert fields and all(type(f) is not CompiledField for f in fields)
    sim.run(2)
    assert all(isinstance(f, Field) and type(f) is not CompiledField for f in fields)
    sim.run(2)
    assert all(type(f) is CompiledField for f in fields)


def test_a_tiered_run_resumes_from_a_checkpoint_bit_identical(monkeypatch, tmp_path):
    """A checkpoint taken on numpy, before the switch, resumes into a run that switches
    later; one taken after the switch resumes as well."""
    program = _program("aco.swarm")
    whole = _reference("aco.swarm", "numpy", 12)
    for first_switch, stop in ((None, 3), (1, 6)):
        _stand_in(monkeypatch, _Ready(first_switch))
        first = Simulation(program, 3, backend="tiered")
        _trace(program, "tiered", stop, sim=first)
        folder = tmp_path / f"ck{stop}"
        checkpoint.save(first, folder)
        _stand_in(monkeypatch, _Ready(2))
        resumed = Simulation(program, 99, backend="tiered")
        checkpoint.load(resumed, folder)
        got, sim = _trace(program, "tiered", 12 - stop, sim=resumed)
        assert sim.backend.name == "numba"
        got["metrics"] = whole["metrics"]   # those of the ticks it ran are checked above
        _assert_identical(got, whole, "numpy")


def test_a_failed_compile_leaves_the_run_on_numpy_and_says_so(monkeypatch, capsys):
    _stand_in(monkeypatch, _Failing(2))
    got, sim = _trace(_program("boids.swarm"), "tiered")
    assert isinstance(sim.backend, TieredBackend)
    assert "numpy from here on: the compile in another process failed (it broke)" in \
        capsys.readouterr().err
    assert "it broke" in sim.backend.summary(sim.program)[0]
    _assert_identical(got, _reference("boids.swarm", "numpy"), "numpy")


def test_a_compile_that_fails_after_the_shared_kernels_keeps_them_and_says_so(
        monkeypatch, capsys):
    class _SharedThenFailing(_Ready):
        def poll(self) -> str:
            self.polls += 1
            if self.polls > 4:
                self.reason = "it broke"
                return "failed"
            return "shared" if self.polls > 1 else "running"

    _stand_in(monkeypatch, _SharedThenFailing(None))
    got, sim = _trace(_program("boids.swarm"), "tiered")
    assert isinstance(sim.backend, tiered.SharedFirst)
    assert "the program's parts on the reference closures: the compile in another " \
        "process failed (it broke)" in capsys.readouterr().err
    sim.backend.finished(sim.program, sim.tick)
    assert "it broke" in sim.backend.summary(sim.program)[0]
    _assert_identical(got, _reference("boids.swarm", "numpy"), "numpy")


def test_a_compile_process_that_fails_or_is_killed_is_reported():
    failing = tiered.Compile({}, [sys.executable, "-c", "import sys; print('no kernels');"
                                  " sys.exit(3)"])
    killed = tiered.Compile({}, [sys.executable, "-c", "import time; time.sleep(60)"])
    killed._proc.kill()
    deadline = time.monotonic() + 60
    while "running" in (failing.poll(), killed.poll()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert (failing.state, failing.reason) == ("failed", "no kernels")
    assert (killed.state, killed.reason) == ("failed", "killed by signal 9")


_LEAVES = """
import sys
from swarmdsl.compiler import compile_source
from swarmdsl.runtime.compiled import tiered
program = compile_source("agent a {{ count 2; status s {{ }} }}", "p.swarm")
tiered.compile_for(program, [sys.executable, "-c",
                             "import pathlib, time; time.sleep(1); "
                             "pathlib.Path({done!r}).write_text('kept')"])
"""


@pytest.mark.parametrize("after_exit, kept", [("1", True), ("0", False)])
def test_a_compile_goes_on_after_its_process_exits_for_later_runs(tmp_path, monkeypatch,
                                                                  after_exit, kept):
    """A run shorter than its compile exits first; its kernels are still kept for
    later runs, as the backend line says (unless `SWARMDSL_COMPILE_AFTER_EXIT=0`)."""
    import subprocess

    done = tmp_path / "done"
    monkeypatch.setenv("SWARMDSL_COMPILE_AFTER_EXIT", after_exit)
    subprocess.run([sys.executable, "-c", _LEAVES.format(done=str(done))], check=True,
                   timeout=120)
    assert not done.exists()   # the process exited before its compile finished
    deadline = time.monotonic() + (30 if kept else 3)
    while not done.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert done.exists() == kept


@pytest.mark.parametrize("shared_kept", [True, False])
def test_the_compile_process_hands_its_kernels_over(monkeypatch, tmp_path, shared_kept):
    """The real warm-up process: where an earlier one kept numba's shared kernels, the
    run takes those first, then the program's own once they are on disk; where none
    did, it goes straight to numba and the warm-up keeps the shared ones for next
    time. Always to the same bits."""
    from swarmdsl.runtime.compiled import warm

    monkeypatch.setenv("SWARMDSL_CACHE_DIR", str(tmp_path))   # markers of its own
    if shared_kept:
        warm.note_shared(threaded=False)
    program = _program("boids.swarm")
    tiered._stop_all()
    tiered._COMPILES.clear()
    sim = Simulation(program, 3, backend="tiered")
    deadline = time.monotonic() + 600
    stages = []
    while "numba from tick" not in sim.backend.why and time.monotonic() < deadline:
        sim.step()
        assert not getattr(sim.backend, "failed", "")
        if not stages or stages[-1] is not type(sim.backend):
            stages.append(type(sim.backend))
        time.sleep(0.01)
    assert sim.backend.name == "numba" and "numba from tick" in sim.backend.why
    compile_ = tiered._COMPILES[tiered._key(program)]
    assert stages[0] is TieredBackend
    if shared_kept:   # the shared kernels' stage, unless both words came between ticks
        assert compile_.started < compile_.shared_at <= compile_.finished_at
    else:
        assert compile_.shared_at is None and tiered.SharedFirst not in stages
        compile_._proc.wait(timeout=600)     # the shared kernels' ticks, after READY
        assert warm.shared_here(threaded=False)
    ticks = sim.tick + 3
    sim.run(3)
    assert sim.backend.compile_seconds < 30    # loaded, not compiled here (generous)
    _assert_identical(_state(sim), {k: v for k, v in _reference(
        "boids.swarm", "numpy", ticks).items() if k != "metrics"}, "numpy")
    tiered._stop_all()      # it went on to the whole-tick kernel: not needed here


def test_the_default_starts_a_first_long_run_tiered(monkeypatch, tmp_path):
    monkeypatch.delenv("SWARMDSL_BACKEND", raising=False)
    monkeypatch.setenv("SWARMDSL_CACHE_DIR", str(tmp_path))     # nothing marked warm
    _stand_in(monkeypatch, _Ready(None))
    program = compile_source("world { size 100 x 100 }\nagent a { count 1000\n"
                             "  status s { velocity = (1, 0) } }\n", "t.swarm")
    long = backends.make(None, 10**7, program, tiered=True)
    assert isinstance(long, TieredBackend) and long.choice.tiered
    assert long.choice.line.startswith("backend: numpy now, numba from the tick")
    assert backends.make(None, 100, program, tiered=True).name == "numpy"   # short
    assert not isinstance(backends.make(None, 10**7, program), TieredBackend)  # a batch
    assert type(backends.make("numba")).__name__ == "NumbaBackend"   # exactly numba
    assert "tiered" not in backends.names()
    monkeypatch.setenv("SWARMDSL_TIERED", "0")
    assert backends.make(None, 10**7, program, tiered=True).name == "numba"


def test_a_swarm_too_dense_for_a_numpy_tick_waits_for_the_compile(monkeypatch, tmp_path):
    """boids_leader at 10^4 agents in its 600 x 600 world sees ~2,000 neighbours each:
    one numpy tick took 10-40 s and GBs of pairs, longer than compiling, so its first
    run compiles first and says why; at 1,000 agents (~220 each) it starts tiered."""
    monkeypatch.delenv("SWARMDSL_BACKEND", raising=False)
    monkeypatch.setenv("SWARMDSL_CACHE_DIR", str(tmp_path))     # nothing marked warm
    _stand_in(monkeypatch, _Ready(None))
    dense = compile_file(PROGRAMS / "boids_leader.swarm", {"n": "10000"})
    got = backends.make(None, 10**4 * 800, dense, tiered=True)
    assert got.name == "numba" and not isinstance(got, TieredBackend)
    assert got.choice.line.startswith("backend: numba (compiling kernels before the "
                                      "first tick, ~")
    assert "one numpy tick of ~2,234 neighbours each would take" in got.choice.line
    fewer = compile_file(PROGRAMS / "boids_leader.swarm", {"n": "1000"})
    assert isinstance(backends.make(None, 1000 * 800, fewer, tiered=True), TieredBackend)
