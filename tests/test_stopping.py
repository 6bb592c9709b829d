"""Stopping a real `swarmdsl run --out` process: SIGTERM, SIGHUP and SIGINT at any
moment (and a second Ctrl-C while it closes), SIGKILL after a flush, and the memory of a
long run. The outputs are read back as a user would and must agree with `run.json`.

The signal is sent a drawn delay after the command has taken over its stop signals
(its handlers for all three show in /proc/PID/status), so "the first half second" is
measured from the command's own start, not from the interpreter's. Timeouts only bound
a hang: a loaded machine makes every step slower, never another verdict.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_same_outputs
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pq = pytest.importorskip("pyarrow.parquet")

pytestmark = pytest.mark.skipif(not Path("/proc/self/status").exists(),
                                reason="needs Linux /proc to see the handlers installed")

PROGRAM = """param n = 20
world { size 100 x 100; grid 10; steps 1000000 }
field scent { decay 0.1; diffuse 0.1 }
agent walker {
  count n
  place uniform
  velocity random_direction() * 2
  var laps = 0
  status walking {
    laps += 1
    deposit(scent, 1)
  }
}
metric mean_laps = mean(laps)
metric spread = max(pos.x) - min(pos.x)
"""
STOPS = {"SIGTERM": signal.SIGTERM, "SIGHUP": signal.SIGHUP, "SIGINT": signal.SIGINT}


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))


def _start(args, *, python_code: str | None = None, quiet=False) -> subprocess.Popen:
    cmd = ([sys.executable, "-c", python_code, *args] if python_code
           else [sys.executable, "-m", "swarmdsl", *args])
    pipe = subprocess.DEVNULL if quiet else subprocess.PIPE
    return subprocess.Popen(cmd, stdout=pipe, stderr=pipe, env=_env())


def _wait_for_handlers(proc: subprocess.Popen, timeout: float = 300.0) -> None:
    """Until the command catches every stop signal (installed at the start of its
    main(), one after another: a command preempted after SIGTERM's would still die of
    a SIGHUP by its default action)."""
    bits = sum(1 << (sig - 1) for sig in STOPS.values())
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        try:
            status = Path(f"/proc/{proc.pid}/status").read_text()
        except OSError:
            break
        caught = int(next(line.split()[1] for line in status.splitlines()
                          if line.startswith("SigCgt:")), 16)
        if (caught & bits) == bits:
            return
        time.sleep(0.005)
    raise AssertionError("the command never installed its stop signal handlers")


_OLD_RUNS: dict[str, Path] = {}     # backend -> the folder of a finished earlier run


def _old_run(factory, program: Path, out: Path) -> dict:
    """OUT holds a finished earlier run (seed 1, 3 ticks), as a user's folder would:
    made once per backend and copied for each example (a process of its own for
    each cost a second or two, more than the run it makes)."""
    backend = os.environ.get("SWARMDSL_BACKEND", "")
    if backend not in _OLD_RUNS:
        first = factory.mktemp("old") / "out"
        done = subprocess.run([sys.executable, "-m", "swarmdsl", "run", str(program),
                               "--headless", "--steps", "3", "--seed", "1", "--out",
                               str(first)], capture_output=True, text=True, env=_env(),
                              timeout=600)
        assert done.returncode == 0, done.stderr
        _OLD_RUNS[backend] = first
    shutil.copytree(_OLD_RUNS[backend], out)
    return json.loads((out / "run.json").read_text())


def _check_outputs(out: Path, old: dict | None) -> dict:
    """The folder holds one consistent run: its rows and frames agree with run.json."""
    run = json.loads((out / "run.json").read_text())      # standard JSON, always
    table = pq.read_table(out / "agents.parquet")
    ticks = np.unique(table["tick"].to_numpy())
    if old is not None and run["created"] == old["created"] and run["seed"] == 1:
        assert run == old                   # stopped before its first tick: untouched
    else:
        assert run["seed"] == 7
    if run["finished"] == "running":        # killed: the rows flushed so far
        assert len(ticks) == 0 or ticks[0] == 0
        return run
    assert len(ticks) == run["recorded_ticks"]
    assert table.num_rows == run["recorded_ticks"] * run["agents"]
    assert run["last_tick"] == run["steps"] == (ticks[-1] if len(ticks) else 0)
    with np.load(out / "fields.npz") as fields:
        assert list(fields["ticks"]) == list(ticks)
        assert fields["scent"].shape[0] == len(ticks)
    metrics = pq.read_table(out / "metrics.parquet").to_pandas()
    assert list(np.unique(metrics["tick"])) == list(ticks)
    assert run["metrics"]["mean_laps"]["last"] == (ticks[-1] if len(ticks) else None)
    assert not any(p.name.startswith(".") for p in out.rglob("*"))    # no leftovers
    assert not (out / "fields.npy").exists()     # streamed into fields.npz, removed
    return run


def assert_stop_leaves_one_consistent_run(factory, name: str, delay: float,
                                          second: float | None) -> None:
    tmp = factory.mktemp("stop")
    program = tmp / "walk.swarm"
    program.write_text(PROGRAM)
    out = tmp / "out"
    old = _old_run(factory, program, out)
    # `--every 3`: the tick the run stops at is mostly off the grid, and still recorded
    with _start(["run", str(program), "--headless", "--seed", "7", "--out", str(out),
                 "--every", "3"]) as proc:
        try:
            _wait_for_handlers(proc)
            time.sleep(delay)
            proc.send_signal(STOPS[name])
            if second is not None:
                time.sleep(second)
                proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=600)
        finally:
            proc.kill()
    err = err.decode()
    assert "Traceback" not in err, err
    # Two signals pending at once are handled in signal-number order: SIGINT may win.
    names = {name} if second is None else {name, "SIGINT"}
    assert proc.returncode in {128 + STOPS[n] for n in names}, err
    run = _check_outputs(out, old)
    if run["seed"] == 7:
        assert run["finished"] == "interrupted" and run["signal"] in names


@settings(max_examples=4, deadline=None, suppress_health_check=list(HealthCheck))
@given(name=st.sampled_from(sorted(STOPS)), delay=st.floats(0, 1.0),
       second=st.none() | st.floats(0, 0.3))
def test_a_stop_signal_at_any_moment_leaves_one_consistent_run(backend, tmp_path_factory, name,
                                                               delay, second):
    assert_stop_leaves_one_consistent_run(tmp_path_factory, name, delay, second)


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(name=st.sampled_from(sorted(STOPS)), delay=st.floats(0, 3.0),
       second=st.none() | st.floats(0, 1.0))
def test_a_stop_signal_at_any_moment_long(backend, tmp_path_factory, name, delay, second):
    assert_stop_leaves_one_consistent_run(tmp_path_factory, name, delay, second)


def test_the_tick_a_stop_signal_ends_at_is_recorded_off_the_every_grid(backend, tmp_path,
                                                                       monkeypatch):
    """A stop takes effect between ticks: the run's last tick is a whole state, and it is
    recorded as the last tick is, whatever `--every` says (run.json's `last_tick`)."""
    from swarmdsl import stopping
    from swarmdsl.cli import main
    from swarmdsl.runtime.runner import Run

    program = tmp_path / "walk.swarm"
    program.write_text(PROGRAM.replace("param n = 20", "param n = 4"))
    step = Run.step

    def stop_after_13(run):
        step(run)
        if run.sim.tick == 13:
            raise stopping.Stopped(signal.SIGTERM)
    monkeypatch.setattr(Run, "step", stop_after_13)
    out = tmp_path / "out"
    assert main(["run", str(program), "--headless", "--seed", "2", "--every", "5",
                 "--out", str(out)]) == 128 + signal.SIGTERM
    run = json.loads((out / "run.json").read_text())
    assert (run["finished"], run["last_tick"], run["recorded_ticks"]) == ("interrupted", 13, 4)
    ticks = np.unique(pq.read_table(out / "agents.parquet")["tick"].to_numpy())
    assert list(ticks) == [0, 5, 10, 13]
    with np.load(out / "fields.npz") as fields:
        assert list(fields["ticks"]) == [0, 5, 10, 13]
    assert run["metrics"]["mean_laps"]["last"] == 13


def _swallowed(stopping):
    """The signal lands in code that swallows the stop the handler raises; a second
    signal is then only noted, as the stop seems under way."""
    try:
        stopping._handler(signal.SIGHUP, None)
    except KeyboardInterrupt:
        pass
    stopping._handler(signal.SIGINT, None)


def _stranded(stopping):
    """The signal lands in a step that must not be cut, which then fails with another
    error that its caller handles: the noted signal was never raised."""
    try:
        with stopping.uncut():
            stopping._handler(signal.SIGHUP, None)
            raise ValueError("a step that failed")
    except ValueError:
        pass


@pytest.mark.parametrize("lose", [_swallowed, _stranded])
def test_a_stop_lost_on_its_way_still_stops_the_run_at_its_next_tick(backend, tmp_path,
                                                                    monkeypatch, lose):
    """A stop the handler raised inside code that swallowed it (a C library clearing a
    callback's error, an optional import catching the ImportError it became), or noted
    in a step that then failed otherwise, is raised where the next tick starts: the run
    ends interrupted by that signal (it once ran on to its last tick and exited 0, and
    later signals were only noted)."""
    from swarmdsl import stopping
    from swarmdsl.cli import main
    from swarmdsl.runtime import simulation

    program = tmp_path / "walk.swarm"
    program.write_text(PROGRAM.replace("param n = 20", "param n = 4")
                       .replace("steps 1000000", "steps 40"))
    init = simulation.Simulation.__init__

    def init_losing_a_stop(sim, *args, **kwargs):
        init(sim, *args, **kwargs)
        lose(stopping)
    monkeypatch.setattr(simulation.Simulation, "__init__", init_losing_a_stop)
    out = tmp_path / "out"
    assert main(["run", str(program), "--headless", "--seed", "2",
                 "--out", str(out)]) == 128 + signal.SIGHUP
    run = json.loads((out / "run.json").read_text())
    assert (run["finished"], run["signal"], run["last_tick"]) == ("interrupted", "SIGHUP", 0)
    assert list(np.unique(pq.read_table(out / "agents.parquet")["tick"])) == [0]


def test_a_stopped_gif_recording_keeps_every_frame_recorded(backend, tmp_path):
    """A GIF reaches the disk as the run goes, so a stop finishes it at once, and it
    holds a frame for every tick recorded, up to the one the run stopped at."""
    import imageio.v3 as iio

    program = tmp_path / "walk.swarm"
    program.write_text(PROGRAM)
    out, gif = tmp_path / "out", tmp_path / "walk.gif"
    with _start(["run", str(program), "--headless", "--out", str(out), "--every", "2",
                 "--record", str(gif)]) as proc:
        try:
            _wait_for_handlers(proc)
            partial = tmp_path / ".walk.partial.gif"
            end = time.monotonic() + 60     # its first frame is written at tick 0
            while time.monotonic() < end and proc.poll() is None and not partial.exists():
                time.sleep(0.01)
            first = partial.stat().st_size if partial.exists() else 0
            end = time.monotonic() + 60         # frames stream in: wait for a second
            while (time.monotonic() < end and proc.poll() is None and partial.exists()
                   and partial.stat().st_size <= first):
                time.sleep(0.05)
            proc.send_signal(signal.SIGINT)
            stdout, err = proc.communicate(timeout=600)
        finally:
            proc.kill()
    assert proc.returncode == 130, err.decode()
    assert f"video {gif}" in stdout.decode()
    run = json.loads((out / "run.json").read_text())
    assert run["finished"] == "interrupted" and run["recorded_ticks"] > 1
    assert len(iio.imread(gif, index=None)) == run["recorded_ticks"]
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.parametrize("command", [
    ["test", "{program}", "--examples", "100000", "--quiet"],
    ["check", "{program}"],
])
def test_ctrl_c_early_in_other_commands_is_no_traceback(tmp_path, command):
    program = tmp_path / "walk.swarm"
    program.write_text(PROGRAM.replace("status walking {", "invariant laps >= 0\n"
                                       "  status walking {"))
    with _start([c.format(program=program) for c in command]) as proc:
        try:
            _wait_for_handlers(proc)
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=120)
        finally:
            proc.kill()
    assert "Traceback" not in err.decode()
    assert proc.returncode in (0, 130)      # `check` may finish first


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_stop_inside_an_import_is_a_stop_not_a_traceback(monkeypatch, capsys, signum):
    """A stop that lands while numpy, pyarrow or numba load their C parts reaches the
    command as those modules' ImportError; it must still end as the stop it was."""
    from swarmdsl import cli, stopping

    def importing(argv):
        try:
            raise stopping.Stopped(signum)
        except KeyboardInterrupt as stop:
            raise ImportError("PyCapsule_Import could not import module") from stop

    monkeypatch.setattr(cli, "_main", importing)
    assert cli.main(["check", "x.swarm"]) == 128 + signum
    err = capsys.readouterr().err
    assert f"stopped by {signal.Signals(signum).name}" in err and "Traceback" not in err
    monkeypatch.setattr(cli, "_main", lambda argv: (_ for _ in ()).throw(
        ImportError("a real missing module")))
    monkeypatch.delenv("SWARMDSL_DEBUG", raising=False)
    assert cli.main(["check", "x.swarm"]) == 3      # a bug in swarmdsl, not a stop
    assert "internal error: ImportError: a real missing module" in capsys.readouterr().err
    monkeypatch.setenv("SWARMDSL_DEBUG", "1")
    with pytest.raises(ImportError, match="a real missing module"):
        cli.main(["check", "x.swarm"])



def test_a_stop_lost_inside_an_import_is_still_the_stop(monkeypatch, capsys):
    """numpy's own import catches the error its C part raised and raises an ImportError
    of its own with the stop nowhere in its chain (a Ctrl-C in the first 30 ms of a
    run): the stop raised since the handlers were installed is still what ended it."""
    from swarmdsl import cli, stopping

    def importing(argv):
        try:
            stopping._handler(signal.SIGINT, None)      # the signal arrives
        except KeyboardInterrupt:
            pass                                        # ... and the C part drops it
        raise ImportError("Importing the numpy C-extensions failed.")

    monkeypatch.setattr(cli, "_main", importing)
    assert cli.main(["check", "x.swarm"]) == 128 + signal.SIGINT
    err = capsys.readouterr().err
    assert "stopped by SIGINT" in err and "internal error" not in err


def test_checking_an_output_folder_leaves_nothing_in_it_whenever_a_stop_lands(
        tmp_path, monkeypatch):
    """The folder is probed by creating and removing a hidden file: a stop that lands
    between the two is raised once the file is gone."""
    from swarmdsl import stopping
    from swarmdsl.runtime import outputs

    removed = []
    real_unlink = os.unlink

    def unlink(name):
        stopping._handler(signal.SIGTERM, None)         # lands just before the removal
        removed.append(name)
        real_unlink(name)

    monkeypatch.setattr(outputs.os, "unlink", unlink)
    old = stopping.install()
    try:
        with pytest.raises(stopping.Stopped):
            outputs.check_folder(tmp_path / "out", "--out")
    finally:
        stopping.restore(old)
    assert removed and list(tmp_path.iterdir()) == []

_FAST_FLUSH = """
import sys
from swarmdsl.cli import main
from swarmdsl.runtime.record import Recorder
Recorder.flush_seconds = 0.05
sys.exit(main(sys.argv[1:]))
"""


def _flushed_frames(path: Path) -> int:
    """Frames the header of a `.npy` file counts (what numpy.load returns)."""
    return np.load(path, mmap_mode="r").shape[0] if path.exists() else 0


def test_sigkill_after_a_flush_leaves_the_flushed_rows_readable(backend, tmp_path):
    """Nothing closes the files: what was flushed is all there is. Rows, metric samples
    and field frames read back with pyarrow and plain numpy, every tick whole and in
    order, and equal to what an unkilled run of the same seed records."""
    program = tmp_path / "walk.swarm"
    program.write_text(PROGRAM)
    out = tmp_path / "out"
    args = ["run", str(program), "--headless", "--seed", "7", "--backend", backend]
    with _start([*args, "--out", str(out)], python_code=_FAST_FLUSH, quiet=True) as proc:
        try:
            end = time.monotonic() + 600
            while _flushed_frames(out / "fields.npy" / "ticks.npy") < 3:
                assert time.monotonic() < end and proc.poll() is None
                time.sleep(0.02)
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=30)
        finally:
            proc.kill()
    run = json.loads((out / "run.json").read_text())
    assert run["finished"] == "running"     # says the run did not end
    assert not (out / "fields.npz").exists()
    table = pq.read_table(out / "agents.parquet").to_pandas()
    ticks = np.unique(table["tick"])
    assert len(ticks) >= 3
    assert list(ticks) == list(range(len(ticks)))             # every flushed tick, whole
    assert (table.groupby("tick").size() == 20).all()
    assert table["laps"].max() == ticks[-1]

    metrics = pq.read_table(out / "metrics.parquet").to_pandas()
    laps = metrics[metrics.name == "mean_laps"]
    assert len(laps) >= 3 and list(laps.tick) == list(range(len(laps)))
    assert list(laps.value) == list(laps.tick)            # mean(laps) is the tick
    assert list(metrics.groupby("tick").size().unique()) == [2]   # both, every tick

    field_ticks = np.load(out / "fields.npy" / "ticks.npy")
    scent = np.load(out / "fields.npy" / "scent.npy")
    assert len(field_ticks) >= 3 and list(field_ticks) == list(range(len(field_ticks)))
    assert scent.shape[0] >= len(field_ticks)      # `ticks` is counted last
    assert scent.shape[1:] == (11, 11)

    # the same seed run unkilled to the last tick any file kept records the same
    last = int(max(ticks[-1], laps.tick.iloc[-1], field_ticks[-1]))
    whole = tmp_path / "whole"
    done = subprocess.run([sys.executable, "-m", "swarmdsl", *args, "--steps", str(last),
                           "--out", str(whole)], capture_output=True, env=_env(),
                          timeout=600)
    assert done.returncode == 0, done.stderr
    ref = pq.read_table(whole / "agents.parquet").to_pandas()
    assert ref[ref.tick.isin(ticks)].reset_index(drop=True).equals(table)
    ref_metrics = pq.read_table(whole / "metrics.parquet").to_pandas()
    assert ref_metrics[ref_metrics.tick.isin(metrics.tick)].reset_index(drop=True).equals(
        metrics)
    with np.load(whole / "fields.npz") as ref_fields:
        n = len(field_ticks)
        assert np.array_equal(ref_fields["scent"][:n], scent[:n])
        assert np.array_equal(ref_fields["grid_x"], np.load(out / "fields.npy" / "grid_x.npy"))

    from swarmdsl.analysis.picture import snapshot_of_run

    snap = snapshot_of_run(out)     # the repo's own reader takes the killed run too
    assert snap.tick == field_ticks[-1]
    assert np.array_equal(snap.fields["scent"], scent[len(field_ticks) - 1])


ONE_AGENT = """world { size 100 x 100; steps 1000000 }
agent walker {
  count 1
  place uniform
  velocity random_direction() * 2
  var laps = 0
  status walking { laps += 1 }
}
"""


def _peak_rss_mb(tmp: Path, steps: int, flush_bytes: int | None,
                 text: str = ONE_AGENT) -> float:
    tmp.mkdir(parents=True, exist_ok=True)
    program = tmp / "one.swarm"
    program.write_text(text)
    setting = f"Recorder.flush_bytes = {flush_bytes}\n" if flush_bytes else ""
    # VmHWM, the peak RSS of this process's own memory: getrusage's ru_maxrss can
    # carry the peak of the (large) pytest process the child was forked from.
    code = ("import sys\nfrom pathlib import Path\nfrom swarmdsl.cli import main\n"
            "from swarmdsl.runtime.record import Recorder\n" + setting +
            "code = main(sys.argv[1:])\n"
            "hwm = [l for l in Path('/proc/self/status').read_text().splitlines()\n"
            "       if l.startswith('VmHWM:')][0].split()[1]\n"
            "print('RSS', hwm)\n"
            "sys.exit(code)\n")
    out = tmp / "out"
    done = subprocess.run([sys.executable, "-c", code, "run", str(program), "--headless",
                           "--steps", str(steps), "--out", str(out), "--backend", "numpy"],
                          capture_output=True, text=True, env=_env(), timeout=900)
    assert done.returncode == 0, done.stderr
    assert pq.read_table(out / "agents.parquet", columns=["tick"]).num_rows == steps + 1
    return int(done.stdout.split("RSS")[-1]) / 1024


def _peak_growth_mb(tmp: Path, short: int, long: int, text: str) -> float:
    """How far a run of LONG ticks raises the peak resident memory of a process that
    has already made a run of SHORT ticks of the same program: the first run pays
    every import, compile and memory pool, so what the second adds is what grows
    with a run's length. One process: two processes' peaks differ by up to ~11 MB
    (imports, allocator), which hid a leak unless the runs were thousands of ticks."""
    tmp.mkdir(parents=True, exist_ok=True)
    program = tmp / "one.swarm"
    program.write_text(text)
    # VmHWM is this process's own peak; writing 5 to clear_refs resets it to the
    # resident set of the moment (Linux), so it then counts the second run only.
    code = ("import sys\nfrom pathlib import Path\nfrom swarmdsl.cli import main\n"
            "from swarmdsl.runtime.record import Recorder\n"
            "Recorder.flush_bytes = 2**20\n"
            "def kb(key):\n"
            "    return int([l for l in Path('/proc/self/status').read_text().splitlines()\n"
            "                if l.startswith(key)][0].split()[1])\n"
            "args, short, long = sys.argv[1:-2], sys.argv[-2], sys.argv[-1]\n"
            "if main([*args, '--steps', short, '--out', short + '.out']) != 0:\n"
            "    sys.exit(1)\n"
            "Path('/proc/self/clear_refs').write_text('5')\n"
            "before = kb('VmRSS')\n"
            "code = main([*args, '--steps', long, '--out', 'out'])\n"
            "print('GROWTH', kb('VmHWM') - before)\n"
            "sys.exit(code)\n")
    done = subprocess.run([sys.executable, "-c", code, "run", str(program), "--headless",
                           "--backend", "numpy", str(short), str(long)], cwd=tmp,
                          capture_output=True, text=True, env=_env(), timeout=900)
    assert done.returncode == 0, done.stderr
    assert pq.read_table(tmp / "out" / "agents.parquet", columns=["tick"]).num_rows == long + 1
    return int(done.stdout.split("GROWTH")[-1]) / 1024


def test_a_long_one_agent_run_keeps_its_memory_bounded(tmp_path):
    """Every tick of one agent recorded: rows go to disk as they come (flushed by
    size), so a run of 3,000 ticks after one of 500 in the same process raises the
    peak by well under a MB. Rows kept until the end (the bug) took about 3 kB a tick
    with their table: 10 MB more here."""
    growth = _peak_growth_mb(tmp_path, 500, 3000, ONE_AGENT)
    assert growth < 5, f"the longer run raised the peak RSS by {growth:.1f} MB"


def test_a_long_run_with_many_metrics_keeps_its_memory_bounded(tmp_path):
    """Metric samples go to disk with the rows, and the summaries in run.json are read
    back from there: a run of 4,000 ticks of 200 metrics after one of 500 in the same
    process raises the peak by a few MB (up to ~10: the summaries' reading; 16.5 seen
    once in a full suite beside another worker). Samples kept until the end (the bug)
    took some 50 bytes a value with their table: about 35 MB more here. All but one metric are constants, which cost next to nothing to
    evaluate and take the same room a sample as any other."""
    text = (ONE_AGENT + "metric m3 = sum(laps) + 3\n"
            + "".join(f"metric c{i} = {i}\n" for i in range(199)))
    growth = _peak_growth_mb(tmp_path, 500, 4000, text)
    assert growth < 22, f"the longer run raised the peak RSS by {growth:.1f} MB"
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert run["metrics"]["m3"] == {"last": 4003.0, "mean": 3003.0, "min": 3.0,
                                    "max": 4003.0}
    assert run["metrics"]["c7"] == {"last": 7.0, "mean": 7.0, "min": 7.0, "max": 7.0}
    metrics = pq.read_table(tmp_path / "out" / "metrics.parquet")
    assert metrics.num_rows == 4001 * 200


@pytest.mark.slow
def test_a_120k_tick_one_agent_run_with_default_flushing(tmp_path):
    rss_mb = _peak_rss_mb(tmp_path, 120_000, flush_bytes=None)
    assert rss_mb < 450, f"peak RSS {rss_mb:.0f} MB"     # was 1.2 GB


def test_a_run_killed_after_a_checkpoint_resumes_to_the_same_outputs(backend, tmp_path):
    """SIGKILL: no closing at all. The checkpoint, the parts flushed before it and the
    field spool are enough for --resume to finish the run exactly as an unkilled one."""
    from swarmdsl.cli import main

    program = tmp_path / "walk.swarm"
    program.write_text(PROGRAM.replace("param n = 20", "param n = 5"))
    args = ["run", str(program), "--headless", "--seed", "3", "--steps", "4000",
            "--every", "7"]
    killed = tmp_path / "killed"
    with _start([*args, "--out", str(killed), "--checkpoint-every", "150"],
                python_code=_FAST_FLUSH, quiet=True) as proc:
        try:
            end = time.monotonic() + 600     # ends a hung run only
            while not (killed / "checkpoint" / "meta.json").exists():
                assert time.monotonic() < end and proc.poll() is None
                time.sleep(0.01)
            time.sleep(0.3)
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=30)
        finally:
            proc.kill()
    assert json.loads((killed / "run.json").read_text())["finished"] == "running"
    assert main(["run", str(program), "--headless", "--resume", str(killed)]) == 0
    whole = tmp_path / "whole"
    assert main([*args, "--out", str(whole)]) == 0
    assert_same_outputs(killed, whole)
    assert (killed / "metrics.parquet").is_dir()
    summary = [json.loads((d / "run.json").read_text())["metrics"] for d in (killed, whole)]
    assert summary[0] == summary[1]
