"""Output paths are checked before the first tick (exit 2, the option named, nothing
created), and run folders hold one run: files put in place whole, the old run's removed
before the new one writes, part files that a resumed run continues."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import swarmdsl
from swarmdsl.cli import main
from swarmdsl.compiler.errors import SwarmOptionError
from swarmdsl.runtime.runner import Run

pq = pytest.importorskip("pyarrow.parquet")

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
ACO = str(PROGRAMS / "aco.swarm")
ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


@pytest.fixture
def afile(tmp_path) -> Path:
    path = tmp_path / "afile"
    path.write_text("x")
    return path


def _bad(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize(("option", "where", "says"), [
    ("--out", "{f}", "is a file, not a folder"),
    ("--out", "{f}/sub/dir", "is under"),
    ("--record", "{d}", "is a folder; give a file name"),
    ("--record", "{f}/x.mp4", "is under"),
])
def test_run_outputs_are_checked_before_the_program_is_even_compiled(
        tmp_path, afile, capsys, option, where, says):
    bad_program = tmp_path / "bad.swarm"
    bad_program.write_text("agent a { count oops }\n")      # never reached
    target = where.format(f=afile, d=tmp_path)
    if option == "--record" and target == str(tmp_path):
        (tmp_path / "clip.mp4").mkdir()
        target = str(tmp_path / "clip.mp4")
    err = _bad(capsys, ["run", str(bad_program), "--headless", "--steps", "5",
                        option, target])
    assert err.startswith(f"error: {option} {target}: ") and says in err


def test_an_unwritable_folder_is_refused_and_nothing_is_created(tmp_path, capsys):
    if ROOT:                            # permissions do not bind root: a kernel folder
        if not Path("/proc/self").exists():
            pytest.skip("needs /proc")
        locked = Path("/proc/self")
    else:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
    try:
        for option, target in (("--out", locked / "a" / "b"),
                               ("--record", locked / "v.mp4")):
            err = _bad(capsys, ["run", ACO, "--headless", "--steps", "5", option,
                                str(target)])
            assert f"{option} {target}: cannot write in {locked}" in err
        assert not (locked / "a").exists()
    finally:
        if not ROOT:
            locked.chmod(0o700)


def test_a_checked_out_folder_is_not_created_when_the_program_fails(tmp_path, capsys):
    bad = tmp_path / "bad.swarm"
    bad.write_text("agent a { count oops }\n")
    _bad(capsys, ["run", str(bad), "--headless", "--out", str(tmp_path / "o" / "p")])
    assert not (tmp_path / "o").exists()


def test_the_python_api_refuses_the_same_paths(tmp_path, afile):
    from swarmdsl import load_program
    from swarmdsl.runtime.runner import Run

    program = load_program(ACO)
    with pytest.raises(SwarmOptionError, match="is under"):
        Run(program, out=afile / "x")
    with pytest.raises(SwarmOptionError, match="is a folder"):
        (tmp_path / "v.gif").mkdir()
        Run(program, record=tmp_path / "v.gif")


def test_other_commands_check_their_outputs_first(tmp_path, afile, capsys):
    err = _bad(capsys, ["graph", ACO, "-o", str(tmp_path)])
    assert "is a folder" in err
    err = _bad(capsys, ["sweep", ACO, "--out", str(afile / "s"), "--steps", "2"])
    assert "--out" in err and "is under" in err
    err = _bad(capsys, ["plot", "time", str(tmp_path), "-o", str(afile / "p.png")])
    assert "-o" in err and "is under" in err
    err = _bad(capsys, ["test", ACO, "--save-example", str(tmp_path), "--quiet"])
    assert "--save-example" in err and "is a folder" in err
    pytest.importorskip("torch")
    err = _bad(capsys, ["train", "spring1d", "--out", str(afile / "m.pt")])
    assert "--out" in err and "is under" in err


def test_outputs_into_missing_folders_create_them(backend, tmp_path, capsys):
    """As --out does: a video, and a graph, whose folders do not exist yet."""
    import imageio.v3 as iio

    gif = tmp_path / "new" / "videos" / "aco.gif"
    assert main(["run", ACO, "--headless", "--steps", "2", "--record", str(gif)]) == 0
    assert f"video {gif}" in capsys.readouterr().out
    assert iio.imread(gif, index=None).shape[0] == 3
    graph = tmp_path / "new" / "graphs" / "aco.dot"
    assert main(["graph", ACO, "-o", str(graph)]) == 0
    assert graph.read_text().startswith("digraph")


def _run(out: Path, *extra: str) -> dict:
    assert main(["run", ACO, "--headless", *extra, "--out", str(out)]) == 0
    return json.loads((out / "run.json").read_text())


def test_a_new_run_replaces_the_old_runs_outputs_whole(backend, tmp_path, capsys):
    out = tmp_path / "o"
    _run(out, "--steps", "30", "--checkpoint-every", "10")
    assert (out / "checkpoint").is_dir()
    run = _run(out, "--steps", "4", "--seed", "3")
    assert run["seed"] == 3 and run["finished"] == "completed"
    assert not (out / "checkpoint").exists()        # the old run's: resuming it would mix
    ticks = pq.read_table(out / "agents.parquet")["tick"].to_pylist()
    assert sorted(set(ticks)) == [0, 1, 2, 3, 4]
    assert sorted(p.name for p in out.rglob("*")) == [
        "agents.parquet", "fields.npz", "part-000000.parquet", "run.json"]


def test_run_json_says_running_while_the_run_goes(backend, tmp_path):
    from swarmdsl import load_program
    from swarmdsl.runtime.runner import Run

    seen = []

    class Watched(Run):
        def step(self):
            seen.append(json.loads((tmp_path / "run.json").read_text())["finished"])
            super().step()

    run = Watched(load_program(ACO), steps=3, out=tmp_path)
    run.show_progress = False
    assert run.execute() == "completed"
    assert seen == ["running"] * 3
    assert json.loads((tmp_path / "run.json").read_text())["finished"] == "completed"


def test_rows_are_flushed_as_parts_that_read_back_as_one_table(backend, tmp_path, monkeypatch):
    from swarmdsl.runtime.record import Recorder

    monkeypatch.setattr(Recorder, "flush_seconds", 0.0)      # a part per recorded tick
    _run(tmp_path / "parts", "--steps", "12", "--every", "3")
    monkeypatch.setattr(Recorder, "flush_seconds", 1e9)
    _run(tmp_path / "one", "--steps", "12", "--every", "3")
    parts = sorted((tmp_path / "parts" / "agents.parquet").iterdir())
    assert [p.name for p in parts] == [f"part-{i:06d}.parquet" for i in range(5)]
    a = pq.read_table(tmp_path / "parts" / "agents.parquet")
    b = pq.read_table(tmp_path / "one" / "agents.parquet")
    assert a.equals(b)
    import pandas as pd

    frame = pd.read_parquet(tmp_path / "parts" / "agents.parquet")
    assert list(frame.tick.unique()) == [0, 3, 6, 9, 12]


def test_fields_npz_streamed_from_the_spool_matches_the_run(backend, tmp_path):
    from swarmdsl import load_program
    from swarmdsl.runtime.runner import Run

    program = load_program(ACO)
    run = Run(program, steps=6, out=tmp_path, every=2)
    run.show_progress = False
    frames = []
    real = run.recorder.record

    def record():
        real()
        frames.append(run.sim.environment.fields["pheromone"].values.copy())
    run.recorder.record = record
    run.execute()
    with np.load(tmp_path / "fields.npz") as data:
        assert list(data["ticks"]) == [0, 2, 4, 6]
        assert np.array_equal(data["pheromone"], np.stack(frames))
    assert not (tmp_path / "fields.npy").exists()       # streamed into fields.npz


WALK = """world { size 60 x 40; grid 5; steps 100 }
field scent { decay 0.1; diffuse 0.1 }
agent walker {
  count 9
  velocity random_direction() * 2
  var laps = 0
  status walking { laps += 1; deposit(scent, laps) }
}
metric mean_laps = mean(laps)
metric total = sum(laps)
"""


def test_each_flush_leaves_every_recorded_tick_readable_as_the_run_goes(backend, tmp_path,
                                                                        monkeypatch):
    """What a kill at any moment would leave: after each flush, `fields.npy/` holds
    every frame recorded so far as plain `.npy` files, and `metrics.parquet` every
    sample, while the run goes on writing."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.record import Recorder
    from swarmdsl.runtime.runner import Run

    monkeypatch.setattr(Recorder, "flush_seconds", 0.0)      # flush at every record
    run = Run(compile_source(WALK, "walk.swarm"), steps=12, out=tmp_path, every=3)
    run.show_progress = False
    frames, seen = [], []
    real = run.recorder.record

    def record():
        frames.append(run.sim.environment.fields["scent"].values.copy())
        real()
        folder = tmp_path / "fields.npy"
        ticks = np.load(folder / "ticks.npy")
        assert np.array_equal(np.load(folder / "scent.npy"), np.stack(frames))
        assert list(ticks) == [3 * i for i in range(len(frames))]
        assert np.load(folder / "grid_x.npy").shape == (13,)
        metrics = pq.read_table(tmp_path / "metrics.parquet").to_pandas()
        assert list(metrics.tick.unique()) == list(ticks)
        seen.append(run.sim.tick)
    run.recorder.record = record
    assert run.execute() == "completed"
    assert seen == [0, 3, 6, 9, 12]
    assert len(list((tmp_path / "metrics.parquet").glob("part-*.parquet"))) == 5
    metrics = pq.read_table(tmp_path / "metrics.parquet").to_pandas()
    assert list(metrics[metrics.name == "mean_laps"].value) == [0, 3, 6, 9, 12]
    summary = json.loads((tmp_path / "run.json").read_text())["metrics"]
    assert summary["total"] == {"last": 108.0, "mean": 81.0, "min": 0.0, "max": 108.0}
    with np.load(tmp_path / "fields.npz") as data:
        assert np.array_equal(data["scent"], np.stack(frames))


@given(shape=st.lists(st.integers(0, 10**6), max_size=3),
       count=st.integers(0, 10**15),
       dtype=st.sampled_from(["<f8", "<f4", "<i8", "|b1", ">f8"]))
def test_a_spool_header_is_the_header_numpy_reads_whatever_the_count(shape, count, dtype):
    from swarmdsl.runtime.spool import _HEADER, _header

    header = _header(np.dtype(dtype), (count, *shape))
    assert len(header) == _HEADER        # rewritten in place as the count grows
    import io

    f = io.BytesIO(header)
    assert np.lib.format.read_magic(f) == (1, 0)
    assert np.lib.format.read_array_header_1_0(f) == ((count, *shape), False,
                                                      np.dtype(dtype))


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_stop_while_closing_is_held_until_the_files_are_whole(backend, tmp_path):
    """A second Ctrl-C inside `close()` is noted, not raised: every file is written."""
    import signal

    from swarmdsl import load_program, stopping
    from swarmdsl.runtime.record import Recorder
    from swarmdsl.runtime.runner import Run

    old = stopping.install()
    try:
        real_close = Recorder.close

        def close(self, steps, status="completed"):
            os.kill(os.getpid(), signal.SIGINT)       # arrives mid-close
            real_close(self, steps, status)

        Recorder.close = close
        run = Run(load_program(ACO), steps=5, out=tmp_path)
        run.show_progress = False
        assert run.execute() == "completed"
    finally:
        Recorder.close = real_close
        stopping.restore(old)
    assert json.loads((tmp_path / "run.json").read_text())["finished"] == "completed"
    assert pq.read_table(tmp_path / "agents.parquet").num_rows == 6 * 7


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_ctrl_c_while_a_scripts_run_closes_lets_its_files_close(tmp_path):
    """In a script (Python's own SIGINT handler) a Ctrl-C inside `close()` escaped from
    the middle of it, leaving run.json saying `running`: now the files close whole and
    the KeyboardInterrupt comes after."""
    import signal

    from swarmdsl import load_program
    from swarmdsl.runtime.record import Recorder
    from swarmdsl.runtime.runner import Run

    real_close = Recorder.close

    def close(self, steps, status="completed"):
        os.kill(os.getpid(), signal.SIGINT)       # arrives mid-close
        real_close(self, steps, status)

    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        Recorder.close = close
        run = Run(load_program(ACO), steps=5, out=tmp_path, backend="numpy")
        run.show_progress = False
        with pytest.raises(KeyboardInterrupt):
            run.execute()
        # Python's own handler is back (this process's own may be SIG_IGN: a job started
        # in the background ignores SIGINT, so it is set above and put back below)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        Recorder.close = real_close
        signal.signal(signal.SIGINT, old)
    assert json.loads((tmp_path / "run.json").read_text())["finished"] == "completed"
    assert pq.read_table(tmp_path / "agents.parquet").num_rows == 6 * 7


def test_a_running_runs_json_counts_the_ticks_its_files_hold(backend, walk, tmp_path,
                                                              monkeypatch):
    """A killed run's run.json said `recorded_ticks: 0`, `last_tick: 0` beside an
    agents.parquet of thousands of flushed ticks: it was written once, at tick 0."""
    from swarmdsl import load_program
    from swarmdsl.runtime.record import Recorder
    from swarmdsl.runtime.runner import Run

    monkeypatch.setattr(Recorder, "flush_seconds", 0.0)     # a flush per recorded tick
    seen = []

    class Watched(Run):
        def step(self):
            if self.sim.tick == 6:      # as a SIGKILL here would leave the folder
                run = json.loads((tmp_path / "run.json").read_text())
                ticks = pq.read_table(tmp_path / "agents.parquet")["tick"].to_pylist()
                seen.append((run["finished"], run["recorded_ticks"], run["last_tick"],
                             len(set(ticks)), max(ticks)))
            super().step()

    run = Watched(load_program(walk), steps=10, out=tmp_path, every=2)
    run.show_progress = False
    assert run.execute() == "completed"
    assert seen == [("running", 4, 6, 4, 6)]


def test_outputs_go_where_they_were_named_when_the_run_was_made(backend, tmp_path, monkeypatch):
    """A notebook's `%cd` between `Run(out="runs/a", record="a.gif")` and `execute()`
    left an empty runs/a in the first folder and wrote the run and its video in the
    second; both now go where the Run was made, as they were checked there."""
    first, second = tmp_path / "first", tmp_path / "second"
    first.mkdir()
    second.mkdir()
    monkeypatch.chdir(first)
    program = swarmdsl.load_program(PROGRAMS / "boids.swarm", {"n": 3})
    run = Run(program, steps=2, out="runs/a", record="a.gif", video_px=32)
    run.show_progress = False
    monkeypatch.chdir(second)
    assert run.execute() == "completed"
    assert (first / "runs" / "a" / "run.json").is_file()
    assert (first / "a.gif").is_file()
    assert not any(second.iterdir())


def test_making_a_run_creates_no_folder_until_it_executes(backend, tmp_path):
    """`Run(program, out="runs/a")` made runs/a at once, so a Run built only to look
    at (or refused later) left an empty folder; it is made when the run begins, as
    the outputs doc says ("created when the output is written")."""
    program = swarmdsl.load_program(PROGRAMS / "boids.swarm", {"n": 3})
    run = Run(program, steps=1, out=tmp_path / "runs" / "a")
    run.show_progress = False
    assert not (tmp_path / "runs").exists()
    assert run.execute() == "completed"
    assert (tmp_path / "runs" / "a" / "run.json").is_file()


@pytest.mark.parametrize("folder", [None, 3, "missing"])
def test_open_fields_of_no_run_folder_is_an_option_error(tmp_path, folder):
    """`open_fields(None)` was a TypeError and a folder without a run a bare
    FileNotFoundError; both are option errors naming run_dir."""
    from swarmdsl.runtime.spool import open_fields

    with pytest.raises(SwarmOptionError, match="run_dir"):
        open_fields(tmp_path / folder if isinstance(folder, str) else folder)


def test_parts_dictionary_encode_repeating_columns_and_not_floats(tmp_path):
    """Dictionaries of positions and velocities (which hardly repeat) made writing a
    part 4x slower and the file larger; ticks, ids, kinds, statuses and metric names
    repeat and keep theirs. Both read back as the table written."""
    import pyarrow as pa

    from swarmdsl.runtime.spool import write_part

    rng = np.random.default_rng(0)
    table = pa.table({"tick": np.repeat(np.arange(50), 40), "id": np.tile(np.arange(40), 50),
                      "status": pa.array(["go", "stop"] * 1000), "x": rng.random(2000)})
    write_part(table, tmp_path / "p.parquet")
    meta = pq.ParquetFile(tmp_path / "p.parquet").metadata.row_group(0)
    dictionary = {meta.column(i).path_in_schema: any("DICTIONARY" in e for e in
                                                     meta.column(i).encodings)
                  for i in range(meta.num_columns)}
    assert dictionary == {"tick": True, "id": True, "status": True, "x": False}
    assert pq.read_table(tmp_path / "p.parquet").equals(table)
