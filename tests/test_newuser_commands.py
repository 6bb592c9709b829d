"""The commands as a new user tries them: what each prints, the exit code, and whether
the files it leaves agree with each other, for inputs a user plausibly gives (a run
folder tidied by hand, an image name for a graph, a grid with a repeated value)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from swarmdsl.cli import main

pq = pytest.importorskip("pyarrow.parquet")

# a field, a metric, and something to record: every output a run writes
PROGRAM = """
param n = 6
param pace = 1
param home = false
world { size 60 x 60; grid 10; edges wrap; steps 20 }
field scent { decay 0.05; diffuse 0.1 }
agent walker {
  count n
  velocity random_direction() * pace
  var laps = 0
  status walking {
    laps += if home then 0 else 1
    deposit(scent, 1)
  }
  metric mean_laps = mean(laps)
}
"""


@pytest.fixture
def program(tmp_path) -> Path:
    path = tmp_path / "walk.swarm"
    path.write_text(PROGRAM)
    return path


def _error(capsys, argv, code: int = 2) -> str:
    """Run a command that must fail; its one `error:` output, never a traceback."""
    assert main(argv) == code
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    return err


def _checkpointed_run(program: Path, out: Path) -> None:
    argv = ["run", str(program), "--headless", "--steps", "10", "--out", str(out),
            "--checkpoint-every", "5"]
    assert main(argv) == 0


@pytest.mark.parametrize("output", ["agents.parquet", "fields.npz", "metrics.parquet"])
def test_resuming_a_run_whose_output_was_deleted_is_refused(program, tmp_path, capsys,
                                                            output):
    out = tmp_path / "out"
    _checkpointed_run(program, out)
    target = out / output
    shutil.rmtree(target) if target.is_dir() else target.unlink()
    err = _error(capsys, ["run", str(program), "--headless", "--resume", str(out),
                          "--steps", "15"])
    assert f"--resume {out}: {output} is missing" in err
    assert not target.exists()      # nothing written that starts mid-run


@pytest.mark.parametrize("argv, said", [
    (["-o", "{d}/g.png"], "-o {d}/g.png: the file must end in .dot, .gv, .mmd or .md"),
    (["-o", "{d}/graph"], "-o {d}/graph: the file must end in .dot, .gv, .mmd or .md"),
    (["--format", "mermaid", "-o", "{d}/g.dot"], "--format mermaid: -o {d}/g.dot names a "
                                                  "dot file"),
    (["--format", "dot", "-o", "{d}/g.md"], "--format dot: -o {d}/g.md names a mermaid"),
])
def test_graph_refuses_a_file_name_its_text_does_not_fit(program, tmp_path, capsys, argv,
                                                          said):
    """`-o graph.png` wrote DOT text into a file named as a picture, which no image
    viewer opens; Mermaid into a `.dot` file, which Graphviz cannot read."""
    argv = [a.format(d=tmp_path) for a in argv]
    err = _error(capsys, ["graph", str(program), *argv])
    assert said.format(d=tmp_path) in err
    assert not any(tmp_path.glob("g*"))


@pytest.mark.parametrize("axis, said", [("pace=1,2,1", "1 is the same value as 1"),
                                        ("pace=1,1.0", "1.0 is the same value as 1"),
                                        ("home=true,True", "True is the same value as true")])
def test_sweep_refuses_a_value_listed_twice(program, tmp_path, capsys, axis, said):
    """`--set pace=1,1` ran one run twice under the same key, two rows that `plot sweep`
    averaged as two replicates."""
    out = tmp_path / "sweep"
    err = _error(capsys, ["sweep", str(program), "--set", axis, "--steps", "2",
                          "--workers", "1", "--out", str(out)])
    assert f"--set {axis}: {said}" in err
    assert not out.exists()


def test_a_sweep_with_failed_runs_says_why(program, tmp_path, capsys):
    """It exited 1 saying only `1 failed`; the reason sat in sweep.parquet's `error`."""
    out = tmp_path / "sweep"
    assert main(["sweep", str(program), "--set", "n=2,2.5", "--steps", "2",
                 "--workers", "1", "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert "(0 already done, 1 failed)" in captured.out
    assert "the first failed run (n=2.5, seed 0):" in captured.err
    assert "walk.swarm:8:9: error: the count of `walker` must be a whole number" in (
        captured.err)


def test_a_running_runs_json_counts_the_ticks_its_files_hold(program, tmp_path,
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

    run = Watched(load_program(program), steps=10, out=tmp_path, every=2)
    run.show_progress = False
    assert run.execute() == "completed"
    assert seen == [("running", 4, 6, 4, 6)]


@pytest.mark.parametrize("argv, said", [
    (["--epochs", "2000000"], "--epochs must be at most 1,000,000, got 2,000,000"),
    (["--seed", str(2**64)], "--seed must be at most 9,223,372,036,854,775,807"),
])
def test_train_names_the_option_that_is_too_large(tmp_path, capsys, argv, said):
    """`--epochs 2000000` was refused as `'epochs' must be a whole number from 1 to
    1e+06`, a spec file's key the user did not write."""
    err = _error(capsys, ["train", "spring1d", "--out", str(tmp_path / "m.pt"), *argv])
    assert f"error: {said}" in err


def test_train_names_the_specs_out_key_not_the_option(tmp_path, capsys):
    spec = tmp_path / "spec.json"
    spec.write_text('{"task": "spring1d", "out": "models/m.onnx"}')
    err = _error(capsys, ["train", str(spec)])
    assert "error: the training spec's 'out' must name a .pt file" in err


@pytest.mark.parametrize("spec, said", [
    ('{"task": "spring1d", "epochs": 1.5}', "'epochs' must be a whole number, got a fraction"),
    ('{"task": "spring1d", "epochs": "5"}', "'epochs' must be a whole number, got a string"),
    ('{"task": "spring1d", "sampling": [1]}', "'sampling' must be an object, got a list"),
    ('{"task": "spring1d", "val_fraction": 1}', "'val_fraction' must be a number above 0 "
                                                "and below 1"),
])
def test_train_spec_errors_read_as_json(tmp_path, capsys, spec, said):
    """They said `'epochs' must be a int, got float`, and refused `val_fraction` 1 as
    outside "from 1e-09 to 1"."""
    path = tmp_path / "spec.json"
    path.write_text(spec)
    err = _error(capsys, ["train", str(path)])
    assert said in err


def test_plot_time_of_a_mistyped_folder_says_it_is_not_there(tmp_path, capsys):
    """It said `no metrics.parquet (run a program that declares a metric ...)`, advice
    about the program for what was a typo in the folder's name."""
    err = _error(capsys, ["plot", "time", str(tmp_path / "ouy"), "-o",
                          str(tmp_path / "p.png")])
    assert f"error: RUN_DIR {tmp_path / 'ouy'}: no such folder" in err
    (tmp_path / "notes.txt").write_text("x")
    err = _error(capsys, ["plot", "time", str(tmp_path / "notes.txt"), "-o",
                          str(tmp_path / "p.png")])
    assert "notes.txt: is a file, not a folder" in err


def test_run_check_of_a_program_without_properties_says_nothing_is_checked(program,
                                                                          capsys):
    """It ran and exited 0 as a checked run that found nothing wrong would."""
    assert main(["run", str(program), "--headless", "--steps", "2", "--check"]) == 0
    err = capsys.readouterr().err
    assert (f"warning: --check: {program} declares no `invariant`, `eventually` or "
            "`always`; nothing is checked") in err


def test_tree_options_on_a_program_without_trees_say_so(program, tmp_path, capsys):
    """`--tree-leaf` recorded a column of nulls without a word."""
    assert main(["run", str(program), "--headless", "--steps", "2", "--tree-leaf",
                 "--tree-memory", "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert (f"warning: --tree-leaf and --tree-memory: {program} has no behaviour tree, "
            "so there is nothing to record") in err


def test_tree_options_on_a_tree_program_are_quiet(capsys):
    patrol = Path(__file__).resolve().parent.parent / "programs" / "patrol.swarm"
    assert main(["run", str(patrol), "--headless", "--steps", "1", "--tree-leaf"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_plot_sweep_of_a_column_name_tells_the_two_options(program, tmp_path, capsys):
    """`--metric walker.mean_laps.last` was answered "did you mean
    'walker.mean_laps.last'?", the text the user had given."""
    out = tmp_path / "sweep"
    assert main(["sweep", str(program), "--set", "n=2,3", "--steps", "2", "--workers",
                 "1", "--out", str(out)]) == 0
    err = _error(capsys, ["plot", "sweep", str(out), "--x", "n", "--metric",
                          "walker.mean_laps.last", "-o", str(tmp_path / "p.png")])
    assert "hint: give the summary on its own: --metric walker.mean_laps --summary last" in (
        err)


@pytest.mark.parametrize("command", [["run", "--headless", "--steps", "2"],
                                     ["sweep", "--steps", "2", "--workers", "1"],
                                     ["test", "--examples", "2", "--quiet"]])
def test_a_bad_backend_variable_is_named_before_anything_runs(program, tmp_path,
                                                              monkeypatch, capsys,
                                                              command):
    """`SWARMDSL_BACKEND=numab` said `unknown backend` without naming the variable; a
    sweep failed every run, and `swarmdsl test` called it a counterexample (exit 1)."""
    monkeypatch.setenv("SWARMDSL_BACKEND", "numab")
    monkeypatch.chdir(tmp_path)
    program.write_text(PROGRAM.replace("  metric", "  invariant counted: laps >= 0\n"
                                       "  metric"))    # a property for `test` to test
    err = _error(capsys, [command[0], str(program), *command[1:]])
    assert "error: $SWARMDSL_BACKEND=numab: not a backend; set it to numba or numpy" in err
    assert not (tmp_path / "walk-sweep").exists()


def test_the_backend_option_wins_over_a_bad_variable(program, monkeypatch):
    monkeypatch.setenv("SWARMDSL_BACKEND", "numab")
    assert main(["run", str(program), "--headless", "--steps", "2",
                 "--backend", "numpy"]) == 0


@pytest.mark.parametrize("command", [["graph"], ["check"]])
def test_output_into_a_closed_pipe_stops_quietly(program, command):
    """`swarmdsl graph FILE | head -1` printed `error: internal error: BrokenPipeError`
    and exited 3 once head had read its line."""
    import os
    import subprocess
    import sys

    read, write = os.pipe()
    os.close(read)              # the reader is gone before the command writes a byte
    try:
        done = subprocess.run([sys.executable, "-m", "swarmdsl", *command, str(program)],
                              stdout=write, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write)
    assert done.returncode == 141, done.stderr
    assert done.stderr == ""


def _sweep(program: Path, out: Path, capsys) -> str:
    assert main(["sweep", str(program), "--set", "n=2,3,4", "--steps", "2",
                 "--workers", "1", "--out", str(out)]) == 0
    return capsys.readouterr().out


def test_a_sweep_killed_mid_line_keeps_every_later_run(program, tmp_path, capsys):
    """The restart appended its first run to the killed sweep's torn last line, so that
    run was lost from runs.jsonl and ran again on the next start."""
    out = tmp_path / "sweep"
    _sweep(program, out, capsys)
    log = out / "runs.jsonl"
    lines = log.read_text().splitlines(keepends=True)
    log.write_text(lines[0] + lines[1][:40])        # SIGKILL while writing the second
    assert "(1 already done, 0 failed)" in _sweep(program, out, capsys)
    assert "(3 already done, 0 failed)" in _sweep(program, out, capsys)


def test_a_sweep_folder_whose_log_is_unreadable_is_refused(program, tmp_path, capsys):
    out = tmp_path / "sweep"
    (out / "runs.jsonl").mkdir(parents=True)
    err = _error(capsys, ["sweep", str(program), "--steps", "2", "--workers", "1",
                          "--out", str(out)])
    assert f"error: --out {out}: its runs.jsonl is unreadable (Is a directory)" in err


@pytest.mark.parametrize("inside, extra, said", [
    ("sweep.parquet", [], "--out {out}: sweep.parquet there is a folder"),
    ("runs", ["--runs"], "--runs {out}/runs: is a file, not a folder"),
])
def test_a_sweep_folder_that_cannot_take_its_outputs_is_refused_first(
        program, tmp_path, capsys, inside, extra, said):
    """A folder named sweep.parquet was an internal error after every run had run; a
    file named runs failed every run of --runs."""
    out = tmp_path / "sweep"
    out.mkdir()
    (out / inside).mkdir() if inside == "sweep.parquet" else (out / inside).write_text("")
    err = _error(capsys, ["sweep", str(program), "--steps", "2", "--workers", "1",
                          "--out", str(out), *extra])
    assert said.format(out=out) in err
    assert not (out / "runs.jsonl").exists()        # no run was made


def test_each_plot_given_the_others_folder_names_the_right_one(program, tmp_path, capsys):
    """`plot time SWEEP_DIR` advised declaring a metric in the program, and `plot sweep
    RUN_DIR` said only `no such sweep table`."""
    run, sweep, png = tmp_path / "run", tmp_path / "sweep", str(tmp_path / "p.png")
    assert main(["run", str(program), "--headless", "--steps", "2", "--out", str(run)]) == 0
    _sweep(program, sweep, capsys)
    err = _error(capsys, ["plot", "time", str(sweep), "-o", png])
    assert f"a sweep's folder, not a run's; draw it with: swarmdsl plot sweep {sweep}" in err
    err = _error(capsys, ["plot", "sweep", str(run), "--x", "n", "--metric", "m", "-o", png])
    assert f"a run's folder, not a sweep's; draw its metrics with: swarmdsl plot time {run}" in (
        err)


def test_a_tiny_time_budget_still_tries_one_run(tmp_path, capsys):
    """`--time-budget 0.001` reported "no counterexample to 1 property in 0 runs" and
    exit 0: a pass for a program it never ran."""
    path = tmp_path / "checked.swarm"
    path.write_text(PROGRAM.replace("  metric", "  invariant counted: laps >= 0\n  metric"))
    assert main(["test", str(path), "--time-budget", "0.001", "--quiet"]) == 0
    assert "no counterexample to 1 property in 1 run of up to" in capsys.readouterr().out
