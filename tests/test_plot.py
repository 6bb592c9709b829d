"""`swarmdsl plot`: the files are written and are valid images of the asked format."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from conftest import cli_error

from swarmdsl.cli import main

pytest.importorskip("matplotlib")

PROGRAM = """
param n = 15
param noise = 0.1
world { size 40 x 40; edges wrap }
agent a {
  count n
  velocity random_direction()
  status s { velocity = rotate(velocity, normal(0, noise)) }
}
metric order = length(mean(normalize(vel)))
metric moving = count(speed > 0)
metric slow_share = count(speed < 0.5) / n
"""


def _valid(path, fmt):
    data = path.read_bytes()
    if fmt == "png":
        import matplotlib.image as mpimg

        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        img = mpimg.imread(path)
        assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100
        assert img[..., :3].std() > 0.01            # not a blank canvas
    elif fmt == "svg":
        root = ET.fromstring(data)
        assert root.tag.endswith("svg")
        assert b"<path" in data
    else:
        assert data.startswith(b"%PDF-") and data.rstrip().endswith(b"%%EOF")


@pytest.fixture(scope="module")
def runs(backend, tmp_path_factory):
    """Two runs and a sweep of PROGRAM on the module's backend (set here: a module's
    fixture starts before the test's `$SWARMDSL_BACKEND` is)."""
    tmp = tmp_path_factory.mktemp("plot")
    path = tmp / "walk.swarm"
    path.write_text(PROGRAM)
    dirs = []
    with pytest.MonkeyPatch.context() as m:
        m.setenv("SWARMDSL_BACKEND", backend)
        for noise in ("0.05", "2"):
            d = tmp / f"run-{noise}"
            assert main(["run", str(path), "--headless", "--steps", "20", "--set",
                         f"noise={noise}", "--out", str(d)]) == 0
            dirs.append(d)
        sweep = tmp / "sweep"
        assert main(["sweep", str(path), "--set", "noise=0:2:1", "--seeds", "3", "--steps",
                     "10", "--workers", "1", "--out", str(sweep)]) == 0
    return dirs, sweep


@pytest.mark.parametrize("fmt", ["png", "svg", "pdf"])
def test_metric_over_time_of_several_runs(runs, tmp_path, fmt):
    out = tmp_path / f"time.{fmt}"
    assert main(["plot", "time", *map(str, runs[0]), "-o", str(out)]) == 0
    _valid(out, fmt)
    if fmt == "svg":            # runs named by the param that sets them apart
        text = out.read_text()
        assert "noise = 0.05" in text and "noise = 2" in text and "order" in text
        assert "slow_share" in text       # a name as the program spells it, to look up


@pytest.mark.parametrize("fmt", ["png", "svg", "pdf"])
def test_metric_against_swept_param(runs, tmp_path, fmt):
    out = tmp_path / f"sweep.{fmt}"
    assert main(["plot", "sweep", str(runs[1]), "--x", "noise", "--metric", "order",
                 "--band", "quantiles", "-o", str(out)]) == 0
    _valid(out, fmt)
    if fmt == "svg":
        text = out.read_text()
        assert "noise" in text and "order" in text     # labels from the program's names


@pytest.mark.parametrize("argv, message", [
    (["time", "{run}", "--metric", "ordr", "-o", "{tmp}/x.png"], "did you mean 'order'"),
    (["time", "{run}", "-o", "{tmp}/x.gif"], "must end in .png, .svg or .pdf"),
    (["sweep", "{sweep}", "--x", "nosie", "--metric", "order", "-o", "{tmp}/x.png"],
     "not a swept param"),
    (["sweep", "{sweep}", "--x", "noise", "--metric", "speed", "-o", "{tmp}/x.png"],
     "no column `speed.mean`"),
])
def test_plot_mistakes_are_option_errors(runs, tmp_path, capsys, argv, message):
    argv = [a.format(run=runs[0][0], sweep=runs[1], tmp=tmp_path) for a in argv]
    assert main(["plot", *argv]) == 2
    assert message in capsys.readouterr().err
    assert not list(tmp_path.glob("x.*"))


def test_replicates_are_counted_per_line_and_value():
    """Two lines (n = 10, 20) of 3 seeds each average 3 seeds per point, not 6."""
    pd = pytest.importorskip("pandas")
    from swarmdsl.plot.figures import replicates_per_point

    rows = pd.DataFrame({"eta": [0.0, 1.0] * 6, "n": [10.0] * 6 + [20.0] * 6,
                         "seed": [0, 0, 1, 1, 2, 2] * 2})
    assert replicates_per_point(rows, "eta", ["n"]) == "3"
    assert replicates_per_point(rows.iloc[1:], "eta", ["n"]) == "2-3"


def test_a_run_without_metric_samples_is_named_not_a_traceback(backend, tmp_path, monkeypatch,
                                                               capsys):
    """A run that faulted before its first metric sample has an empty metrics.parquet:
    `plot time` names the folder (exit 2); `plot sweep` over runs that all faulted too."""
    from swarmdsl.compiler.errors import SwarmRuntimeError
    from swarmdsl.runtime.metrics import MetricLog

    def sample(self, sim):
        raise SwarmRuntimeError(f"metric failed at tick {sim.tick}")

    path = tmp_path / "walk.swarm"
    path.write_text(PROGRAM)
    run = tmp_path / "faulted"
    with monkeypatch.context() as m:
        m.setattr(MetricLog, "sample", sample)
        assert main(["run", str(path), "--headless", "--steps", "3", "--out", str(run)]) == 2
        sweep = tmp_path / "sweep"
        main(["sweep", str(path), "--set", "noise=0,1", "--steps", "3", "--workers", "1",
              "--out", str(sweep)])
    capsys.readouterr()
    assert (run / "metrics.parquet").exists()
    assert main(["plot", "time", str(run), "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert f"no metric samples in {run}" in err and '"finished": "fault"' in err
    assert "Traceback" not in err
    assert main(["plot", "sweep", str(sweep), "--x", "noise", "--metric", "order",
                 "-o", str(tmp_path / "x.png")]) == 2
    assert "no completed run has `order.mean`" in capsys.readouterr().err
    assert not list(tmp_path.glob("x.*"))


@pytest.mark.parametrize("name, content", [("runs.jsonl", b'{"key": "a"}\n'),
                                           ("empty.parquet", b"")])
def test_a_file_that_is_not_a_sweep_table_is_named(tmp_path, capsys, name, content):
    table = tmp_path / name
    table.write_bytes(content)
    assert main(["plot", "sweep", str(table), "--x", "noise", "--metric", "order",
                 "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert f"error: {table}: not a sweep table" in err and "internal error" not in err
    assert not list(tmp_path.glob("x.*"))


def test_a_run_table_is_not_taken_for_a_sweep_table(runs, tmp_path, capsys):
    table = next((runs[0][0] / "metrics.parquet").glob("*.parquet"))
    assert main(["plot", "sweep", str(table), "--x", "noise", "--metric", "order",
                 "-o", str(tmp_path / "x.png")]) == 2
    assert "not a sweep table (no `outcome` column" in capsys.readouterr().err


def test_a_text_param_is_drawn_at_its_values(backend, tmp_path):
    """A boolean param swept as true,false: one point per value, labelled with it."""
    path = tmp_path / "flag.swarm"
    path.write_text(PROGRAM.replace("param noise = 0.1", "param noise = 0.1\nparam calm = "
                                    "true").replace("normal(0, noise)",
                                                    "normal(0, if calm then 0 else noise)"))
    sweep = tmp_path / "sweep"
    assert main(["sweep", str(path), "--set", "calm=true,false", "--seeds", "2",
                 "--steps", "5", "--workers", "1", "--out", str(sweep)]) == 0
    out = tmp_path / "calm.svg"
    assert main(["plot", "sweep", str(sweep), "--x", "calm", "--metric", "order",
                 "-o", str(out)]) == 0
    _valid(out, "svg")
    text = out.read_text()
    assert "true" in text and "false" in text


def test_a_run_killed_before_its_first_flush_has_no_samples(runs, tmp_path, capsys):
    """SIGKILL before the first flush leaves metrics.parquet an empty folder and run.json
    saying `running`: named, not a traceback."""
    import json
    import shutil

    run = tmp_path / "killed"
    shutil.copytree(runs[0][0], run)
    shutil.rmtree(run / "metrics.parquet")
    (run / "metrics.parquet").mkdir()
    meta = json.loads((run / "run.json").read_text())
    (run / "run.json").write_text(json.dumps({**meta, "finished": "running",
                                              "last_tick": 0}))
    assert main(["plot", "time", str(run), "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert f"no metric samples in {run}" in err and '"finished": "running"' in err
    assert "internal error" not in err


def test_runs_of_two_programs_are_labelled_by_program_and_their_own_params(backend, runs,
                                                                          tmp_path):
    """Labels come from every run's params, not only the first's; the title names the
    program only when every run is of it."""
    other = tmp_path / "other.swarm"
    other.write_text(PROGRAM.replace("param noise = 0.1", "param noise = 0.1\n"
                                     "param turn = 3"))
    run = tmp_path / "other"
    assert main(["run", str(other), "--headless", "--steps", "5", "--set", "turn=7",
                 "--out", str(run)]) == 0
    out = tmp_path / "time.svg"
    assert main(["plot", "time", str(runs[0][0]), str(run), "-o", str(out)]) == 0
    text = out.read_text()
    assert "walk.swarm, noise = 0.05" in text
    assert "other.swarm, noise = 0.1, turn = 7" in text
    from swarmdsl.plot.figures import _program_title

    assert _program_title([runs[0][0], run]) == ""
    assert _program_title(runs[0]) == "walk.swarm"


def test_runs_without_the_metric_are_named_when_left_out(backend, runs, tmp_path, capsys):
    """Overlaid runs are compared, so a run that lacks a metric is named on stderr, not
    silently missing from its panel; when no run has it, it is an option error."""
    other = tmp_path / "order_only.swarm"
    other.write_text(PROGRAM.replace("metric moving = count(speed > 0)\n", ""))
    run = tmp_path / "order-only"
    assert main(["run", str(other), "--headless", "--steps", "5", "--out", str(run)]) == 0
    capsys.readouterr()
    out = tmp_path / "moving.png"
    assert main(["plot", "time", str(runs[0][0]), str(run), "--metric", "moving",
                 "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"{run}: no metric `moving`; left out of its panel" in err
    assert str(runs[0][0]) not in err
    assert out.exists()
    assert main(["plot", "time", str(run), str(runs[0][0]), "-o", str(out)]) == 0
    assert f"{run}: no metric `moving`" in capsys.readouterr().err   # every metric, too
    assert main(["plot", "time", str(run), str(run), "--metric", "moving",
                 "-o", str(tmp_path / "x.png")]) == 2
    assert "--metric moving: not in any of the 2 runs" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_plot_time_of_a_mistyped_folder_says_it_is_not_there(tmp_path, capsys):
    """It said `no metrics.parquet (run a program that declares a metric ...)`, advice
    about the program for what was a typo in the folder's name."""
    err = cli_error(capsys, ["plot", "time", str(tmp_path / "ouy"), "-o",
                          str(tmp_path / "p.png")])
    assert f"error: RUN_DIR {tmp_path / 'ouy'}: no such folder" in err
    (tmp_path / "notes.txt").write_text("x")
    err = cli_error(capsys, ["plot", "time", str(tmp_path / "notes.txt"), "-o",
                          str(tmp_path / "p.png")])
    assert "notes.txt: is a file, not a folder" in err


def test_plot_sweep_of_a_column_name_tells_the_two_options(backend, walk, tmp_path, capsys):
    """`--metric walker.mean_laps.last` was answered "did you mean
    'walker.mean_laps.last'?", the text the user had given."""
    out = tmp_path / "sweep"
    assert main(["sweep", str(walk), "--set", "n=2,3", "--steps", "2", "--workers",
                 "1", "--out", str(out)]) == 0
    err = cli_error(capsys, ["plot", "sweep", str(out), "--x", "n", "--metric",
                          "walker.mean_laps.last", "-o", str(tmp_path / "p.png")])
    assert "hint: give the summary on its own: --metric walker.mean_laps --summary last" in (
        err)


def test_each_plot_given_the_others_folder_names_the_right_one(backend, walk, tmp_path, capsys):
    """`plot time SWEEP_DIR` advised declaring a metric in the program, and `plot sweep
    RUN_DIR` said only `no such sweep table`."""
    run, sweep, png = tmp_path / "run", tmp_path / "sweep", str(tmp_path / "p.png")
    assert main(["run", str(walk), "--headless", "--steps", "2", "--out", str(run)]) == 0
    assert main(["sweep", str(walk), "--set", "n=2,3", "--steps", "2", "--workers", "1",
                 "--out", str(sweep)]) == 0
    err = cli_error(capsys, ["plot", "time", str(sweep), "-o", png])
    assert f"a sweep's folder, not a run's; draw it with: swarmdsl plot sweep {sweep}" in err
    err = cli_error(capsys, ["plot", "sweep", str(run), "--x", "n", "--metric", "m", "-o", png])
    assert f"a run's folder, not a sweep's; draw its metrics with: swarmdsl plot time {run}" in (
        err)
