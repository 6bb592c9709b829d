"""`swarmdsl plot`: the files are written and are valid images of the asked format."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
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
                     "10", "--workers", "1", "--runs", "--out", str(sweep)]) == 0
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


# ---- figures for papers: quantile bands, every run a point, axes within the metric ----

def _close(fig):
    import matplotlib.pyplot as plt

    plt.close(fig)


def _fake_sweep(tmp_path, values_at: dict, bounds=(0.0, 1.0), lines=None):
    """A sweep table of `order.mean` per run: {eta: [value per seed]} (per `lines`
    value of `n` when given), with the bounds a sweep records."""
    from swarmdsl.sweep.table import write_table

    rows = []
    for n in lines or [None]:
        for eta, values in values_at.items():
            for seed, v in enumerate(values):
                params = [["eta", str(eta)]] + ([["n", str(n)]] if n is not None else [])
                rows.append({"params": params, "seed": seed, "outcome": "completed",
                             "metrics": {"order": {"mean": v}}, "key": f"{eta}-{n}-{seed}"})
    names = ["eta"] + (["n"] if lines else [])
    write_table(tmp_path, rows, names, ["mean"], ["order"],
                {"order": list(bounds)} if bounds else None)
    return tmp_path / "sweep.parquet"


BIMODAL = {0.0: [1.0] * 17, 1.0: [0.0] * 13 + [1.0] * 4, 2.0: [0.02, 0.05, 0.1] * 5 + [0.0, 0.3]}


def _bands(ax):
    """Every band's (x, low, high) vertices as drawn."""
    from matplotlib.collections import PolyCollection

    return [c for c in ax.collections if isinstance(c, PolyCollection)]


def _points(ax):
    from matplotlib.collections import PathCollection

    return [c for c in ax.collections if isinstance(c, PathCollection)]


@pytest.mark.parametrize("band", ["quantiles", "minmax", "sd"])
def test_a_fractions_bands_and_axis_stay_within_0_and_1(tmp_path, band):
    """The issue's case: 13 runs at 0 and 4 at 1 at one setting. Mean ± sd ran from
    -0.15 to 1.10; now every band and the axis lie within [0, 1], and every run is a
    point, so the two clusters of outcomes show."""
    from swarmdsl.plot.figures import sweep_figure

    fig = sweep_figure(_fake_sweep(tmp_path, BIMODAL), "eta", "order", "mean", band)
    ax = fig.axes[0]
    lo, hi = ax.get_ylim()
    assert 0.0 <= lo < 0.05 and 0.95 < hi <= 1.0
    for poly in _bands(ax):
        for path in poly.get_paths():
            y = path.vertices[:, 1]
            assert y.min() >= 0.0 and y.max() <= 1.0
    (points,) = _points(ax)
    ys = points.get_offsets()[:, 1]
    assert len(ys) == sum(len(v) for v in BIMODAL.values())
    assert (ys == 0.0).sum() == 14 and (ys == 1.0).sum() == 21   # both modes at eta = 1
    xs = points.get_offsets()[:, 0]
    assert np.all(np.abs(xs - np.round(xs)) <= 0.2)      # jittered about their value
    assert len(np.unique(xs)) == len(xs)
    assert len(_bands(ax)) == (1 if band == "sd" else 2)
    _close(fig)


def test_the_default_is_the_median_with_quantile_bands_and_the_runs(tmp_path):
    from swarmdsl.plot.figures import sweep_figure

    fig = sweep_figure(_fake_sweep(tmp_path, BIMODAL), "eta", "order", "mean")
    ax = fig.axes[0]
    (line,) = ax.get_lines()
    assert list(line.get_ydata()) == [1.0, 0.0, np.median(BIMODAL[2.0])]   # medians
    inner, outer = _bands(ax)
    y_outer = outer.get_paths()[0].vertices[:, 1]
    y_inner = inner.get_paths()[0].vertices[:, 1]
    assert y_outer.max() >= y_inner.max() and y_outer.min() <= y_inner.min()
    assert "bands 25-75 % and 5-95 % of runs, runs as points" in ax.get_title()
    _close(fig)
    fig = sweep_figure(tmp_path / "sweep.parquet", "eta", "order", "mean", points=False)
    assert not _points(fig.axes[0])
    _close(fig)


def test_a_metric_with_no_known_bounds_takes_the_datas_range(tmp_path):
    from swarmdsl.plot.figures import sweep_figure

    table = _fake_sweep(tmp_path, {0.0: [-3.0, 5.0], 1.0: [10.0, 12.0]}, bounds=None)
    fig = sweep_figure(table, "eta", "order", "mean", "sd")
    lo, hi = fig.axes[0].get_ylim()
    assert lo < -3.0 and hi > 12.0 and hi - lo < 25     # the data's, padded
    _close(fig)


def test_each_line_has_its_own_colour_and_one_legend_entry(tmp_path):
    """12 lines of the other param: 12 colours, no two alike, one legend entry each,
    and the legend within the figure."""
    from swarmdsl.plot.figures import sweep_figure

    lines = list(range(10, 130, 10))
    fig = sweep_figure(_fake_sweep(tmp_path, {0.0: [0.1, 0.2], 1.0: [0.5, 0.6]},
                                   lines=lines), "eta", "order", "mean")
    ax = fig.axes[0]
    colours = [tuple(line.get_color()) for line in ax.get_lines()]
    assert len(colours) == 12 and len(set(colours)) == 12
    assert sum(len(p.get_offsets()) for p in _points(ax)) == 48
    _assert_legend_fits(fig, ax, 12)
    _close(fig)


def _assert_legend_fits(fig, ax, entries: int) -> None:
    legend = ax.get_legend()
    assert len(legend.get_texts()) == entries
    fig.tight_layout()
    fig.canvas.draw()
    box = legend.get_window_extent()
    figure = fig.bbox
    assert box.x0 >= figure.x0 - 1 and box.x1 <= figure.x1 + 1
    assert box.y0 >= figure.y0 - 1 and box.y1 <= figure.y1 + 1


def test_a_real_sweeps_fraction_is_drawn_within_its_bounds(runs, tmp_path):
    """End to end: the sweep records what `order` (a polarisation) can take, the plot
    reads it: the axis ends within [0, 1] and there is a point per run of the table."""
    import pyarrow.parquet as pq

    from swarmdsl.plot.figures import sweep_figure
    from swarmdsl.runtime.metrics import read_bounds

    table = runs[1] / "sweep.parquet"
    bounds = read_bounds(pq.read_schema(table))
    assert bounds == {"order": (0.0, 1.0), "moving": (0.0, None),
                      "slow_share": (0.0, None)}
    fig = sweep_figure(table, "noise", "order", "mean")
    ax = fig.axes[0]
    lo, hi = ax.get_ylim()
    assert lo >= 0.0 and hi <= 1.0
    # one swept param, one line: the table's bookkeeping columns (`libraries`, ...)
    # are not params, so there is no legend
    assert ax.get_legend() is None and not fig.legends
    assert sum(len(p.get_offsets()) for p in _points(ax)) == pq.read_table(table).num_rows
    _close(fig)


# ---- plot time over replicates ----

def _fake_run(folder, program: str, params: dict, seed: int, ticks, values, bounds=None):
    """A run folder with the run.json and metrics.parquet `plot time` reads."""
    import json

    import pyarrow as pa
    import pyarrow.parquet as pq

    from swarmdsl.runtime.metrics import BOUNDS_KEY

    folder.mkdir(parents=True)
    (folder / "run.json").write_text(json.dumps({"program": program, "params": params,
                                                 "seed": seed}))
    table = pa.table({"tick": pa.array(ticks, pa.int64()),
                      "name": pa.array(["order"] * len(ticks)),
                      "value": pa.array(values, pa.float64())})
    if bounds is not None:
        table = table.replace_schema_metadata({BOUNDS_KEY: json.dumps(
            {"order": list(bounds)})})
    pq.write_table(table, folder / "metrics.parquet")
    return folder


def test_twenty_replicates_are_one_line_and_band_with_one_legend_entry_per_group(tmp_path):
    """Two noise levels x 10 seeds: two lines (the median), two bands, a legend of two
    entries; each band within [0, 1] though the runs spread to both ends."""
    from swarmdsl.plot.figures import time_figure

    rng = np.random.default_rng(0)
    ticks = np.arange(0, 50, 5)
    dirs = []
    for noise in (0.5, 3.0):
        for seed in range(10):
            v = np.clip(rng.normal(0.9 if noise < 1 else 0.1, 0.4, ticks.size), 0, 1)
            dirs.append(_fake_run(tmp_path / f"n{noise}s{seed}", "vicsek.swarm",
                                  {"noise": noise, "n": 100}, seed, ticks, v, (0.0, 1.0)))
    fig = time_figure(dirs, None)
    ax = fig.axes[0]
    lines = [line for line in ax.get_lines() if not line.get_label().startswith("_")]
    assert len(lines) == 2 and len({tuple(line.get_color()) for line in lines}) == 2
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [
        "noise = 0.5 (10 runs)", "noise = 3.0 (10 runs)"]
    for poly in _bands(ax):
        y = poly.get_paths()[0].vertices[:, 1]
        assert y.min() >= 0.0 and y.max() <= 1.0
    assert "median and 25-75 % of runs" in ax.get_title()
    _close(fig)
    fig = time_figure(dirs, None, band="sd", each=True)
    ax = fig.axes[0]
    assert len(ax.get_lines()) == 22          # 20 runs and the two means
    assert len(ax.get_legend().get_texts()) == 2
    _close(fig)


def test_many_groups_get_distinct_colours_and_a_legend_that_fits(tmp_path):
    from swarmdsl.plot.figures import time_figure

    dirs = []
    for g in range(25):
        for seed in range(2):
            dirs.append(_fake_run(tmp_path / f"g{g}s{seed}", "x.swarm", {"eta": g / 10},
                                  seed, [0, 1, 2], [g / 25, 0.5, 1 - g / 25]))
    fig = time_figure(dirs, None)
    ax = fig.axes[0]
    lines = [line for line in ax.get_lines() if not line.get_label().startswith("_")]
    assert len({tuple(np.round(line.get_color(), 6)) for line in lines}) == 25
    _assert_legend_fits(fig, ax, 25)
    _close(fig)


def test_replicates_with_different_ticks_are_summarised_where_they_have_values(tmp_path):
    """A run that ended early (a fault) counts only at the ticks it has."""
    from swarmdsl.plot.figures import time_figure

    dirs = [_fake_run(tmp_path / "a", "x.swarm", {"k": 1}, 0, [0, 1, 2, 3], [0, 1, 2, 3]),
            _fake_run(tmp_path / "b", "x.swarm", {"k": 1}, 1, [0, 1], [2, 3]),
            _fake_run(tmp_path / "c", "x.swarm", {"k": 1}, 2, [0, 1, 2, 3], [4, 5, 6, 7])]
    fig = time_figure(dirs, None)
    (line,) = [line for line in fig.axes[0].get_lines()
               if not line.get_label().startswith("_")]
    assert list(line.get_xdata()) == [0, 1, 2, 3]
    assert list(line.get_ydata()) == [2, 3, 4, 5]        # medians of 3, 3, 2, 2 runs
    _close(fig)


def test_a_sweeps_run_folders_plot_as_groups(runs, tmp_path):
    """`plot time DIR/runs/*` of a sweep (3 noise values x 3 seeds): three groups."""
    from swarmdsl.plot.figures import time_figure

    folders = sorted((runs[1] / "runs").iterdir())
    assert [p.name for p in folders] == sorted(f"noise={n}_seed={s}" for n in (0, 1, 2)
                                               for s in (0, 1, 2))
    fig = time_figure(folders, ["order"])
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert texts == [f"noise = {n} (3 runs)" for n in (0.0, 1.0, 2.0)]
    lo, hi = fig.axes[0].get_ylim()
    assert lo >= 0.0 and hi <= 1.0
    _close(fig)


# ---- what a metric can take, from its expression ----

@pytest.mark.parametrize("expr, bounds", [
    ("length(mean(normalize(vel)))", (0.0, 1.0)),
    ("mean(if speed > 1 then 1 else 0)", (0.0, 1.0)),
    ("count(speed > 1) / count()", (0.0, 1.0)),
    ("largest_cluster(3) / count()", (0.0, 1.0)),
    ("all(speed > 0)", (0.0, 1.0)),
    ("count()", (0.0, None)),
    ("clusters(3)", (0.0, None)),
    ("mean_nearest_distance()", (0.0, None)),
    ("mean_nearest_distance(speed > 1 else -1)", (-1.0, None)),
    ("mean(speed)", (0.0, None)),
    ("mean(heading)", (None, None)),
    ("1 - length(mean(normalize(vel)))", (0.0, 1.0)),
    ("2 * mean(if speed > 1 then 1 else 0) + 1", (1.0, 3.0)),
    ("mean(sin(heading))", (-1.0, 1.0)),
    ("clamp(mean(heading), -2, n)", (-2.0, 15.0)),
    ("count(speed > 1) / n", (0.0, None)),
    ("max(pos.x) - min(pos.x)", (None, None)),
    ("abs(mean(heading))", (0.0, None)),
    ("if count() > 3 then 1 else 0.5", (0.5, 1.0)),
])
def test_what_a_metric_can_take_is_read_from_its_expression(expr, bounds):
    from swarmdsl.compiler import compile_source

    program = compile_source(PROGRAM + f"\nmetric probe = {expr}\n", "walk.swarm")
    (probe,) = [m for m in program.metrics if m.info.name == "probe"]
    assert probe.info.bounds == bounds


# ---- sweep run folders named by params and seed ----

def test_run_folder_names_are_readable_safe_and_unique():
    from swarmdsl.sweep.folders import assign, is_folder_name, run_folder

    assert run_folder([("eta", "0.5")], 3) == "eta=0.5_seed=3"
    assert run_folder([("eta", "-1e-05"), ("mode", "a b/c")], 0) == \
        "eta=-1e-05_mode=a%20b%2Fc_seed=0"
    assert run_folder([], 7) == "seed=7"
    assert run_folder([("x", "é")], 1) == "x=%C3%A9_seed=1"
    assert run_folder([("eta", "0.50")], 1) != run_folder([("eta", "0.5")], 1)
    long = run_folder([(f"p{i}", "1" * 20) for i in range(20)], 12)
    assert len(long) <= 180 and long.endswith("_seed=12")
    assert long != run_folder([(f"p{i}", "1" * 20) for i in range(19)] + [("p19", "2")],
                              12)
    # a clash with another run of the folder (another --steps), or one only by case
    names = assign([("k1", [("m", "A")], 1), ("k2", [("m", "a")], 1),
                    ("k3", [("eta", "1")], 2)], {"eta=1_seed=2": "other"})
    assert names["k1"] == "m=A_seed=1" and names["k2"] == "m=a_seed=1_k2"
    assert names["k3"] == "eta=1_seed=2_k3"
    # a run in the log keeps its folder; a name from the log that is a path is ignored
    assert assign([("k1", [("m", "A")], 1)], {"old=1_seed=1": "k1"}) == {
        "k1": "old=1_seed=1"}
    assert not is_folder_name("../x=1") and not is_folder_name("a/b=1")
    assert assign([("k", [("x", "1")], 1)], {"../../x=1_seed=1": "o"}) == {
        "k": "x=1_seed=1"}


def test_a_sweep_started_again_finds_its_named_runs_and_another_sweep_does_not_clash(
        backend, tmp_path, capsys):
    import json

    path = tmp_path / "walk.swarm"
    path.write_text(PROGRAM)
    out = tmp_path / "s"
    argv = ["sweep", str(path), "--set", "noise=0.1,1", "--seed-list", "4,9", "--steps",
            "3", "--workers", "1", "--runs", "--out", str(out)]
    assert main(argv) == 0
    names = sorted(p.name for p in (out / "runs").iterdir())
    assert names == ["noise=0.1_seed=4", "noise=0.1_seed=9", "noise=1_seed=4",
                     "noise=1_seed=9"]
    stamp = {n: (out / "runs" / n / "run.json").stat().st_mtime_ns for n in names}
    assert main(argv) == 0           # started again: every run found, none run
    assert "(4 already done, 0 failed)" in capsys.readouterr().out
    assert {n: (out / "runs" / n / "run.json").stat().st_mtime_ns for n in names} == stamp
    # the same params and seeds for another length, into the same folder
    assert main([*argv[:7], "5", *argv[8:]]) == 0
    after = sorted(p.name for p in (out / "runs").iterdir())
    assert len(after) == 8 and set(names) <= set(after)
    for n in names:
        assert json.loads((out / "runs" / n / "run.json").read_text())["steps"] == 3
    logged = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert sorted(r["folder"] for r in logged) == after
    for r in logged:
        assert json.loads((out / "runs" / r["folder"] / "run.json").read_text())[
            "seed"] == r["seed"]
