"""The command line as a user meets it: outputs on disk, exit codes, option errors,
determinism of agents.parquet, and interrupted runs that keep what they recorded."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from swarmdsl import __version__
from swarmdsl.cli import main

PROGRAM = """
param n = 12
world { size 100 x 100; edges wrap; steps 30 }
agent walker {
  count n
  velocity random_direction() * 2
  var energy = 10
  var home = pos
  var tired = false
  status walking {
    velocity = rotate(velocity, normal(0, 0.2))
    energy -= 1
    tired = energy < 5
    when tired and home.x >= 0 -> resting
  }
  status resting { velocity = (0, 0) }
}
"""


@pytest.fixture
def program(tmp_path):
    path = tmp_path / "walk.swarm"
    path.write_text(PROGRAM)
    return path


def _run(program, out, *extra):
    return main(["run", str(program), "--headless", "--out", str(out), *extra])


def test_run_writes_the_three_outputs(backend, program, tmp_path):
    out = tmp_path / "out"
    assert _run(program, out, "--steps", "10", "--every", "4", "--seed", "3",
                "--set", "n=7") == 0
    table = pq.read_table(out / "agents.parquet")
    assert table.column_names[:9] == ["tick", "id", "kind", "status", "x", "y", "heading",
                                      "vx", "vy"]
    assert {"energy", "home_x", "home_y", "tired"} <= set(table.column_names)
    ticks = sorted(set(table["tick"].to_pylist()))
    assert ticks == [0, 4, 8, 10]          # tick 0, every K, and the last tick
    assert table.num_rows == 7 * 4
    run = json.loads((out / "run.json").read_text())
    for key in ("program", "sha256", "seed", "params", "steps", "wall_seconds",
                "steps_per_second", "status_counts", "version", "world"):
        assert key in run
    assert run["seed"] == 3 and run["steps"] == 10 and run["params"] == {"n": 7}
    assert run["status_counts"] == {"walking": 0, "resting": 7}
    assert run["world"]["size"] == [100.0, 100.0] and run["world"]["grid_spacing"] == 10.0
    assert run["world"]["regions"] == []
    fields = np.load(out / "fields.npz")
    assert fields["ticks"].tolist() == [0, 4, 8, 10]
    assert fields["grid_x"].shape == (11,)


def test_same_seed_identical_parquet_other_seed_differs(backend, program, tmp_path):
    for name, seed in (("a", "5"), ("b", "5"), ("c", "6")):
        assert _run(program, tmp_path / name, "--steps", "15", "--seed", seed) == 0
    a, b, c = (pq.read_table(tmp_path / n / "agents.parquet") for n in "abc")
    assert a.equals(b)
    assert not a.equals(c)


def test_world_steps_is_the_default(backend, program, tmp_path):
    assert _run(program, tmp_path / "o") == 0
    assert json.loads((tmp_path / "o" / "run.json").read_text())["steps"] == 30


@pytest.mark.parametrize("args, message", [
    (["--set", "nn=3"], "--set nn: the program has no param `nn`"),
    (["--set", "n=abc"], "--set n=abc: `abc` is not a number"),
    (["--set", "n=1_0"], "--set n=1_0: `1_0` is not a number"),
    (["--set", "n=infinity"], "--set n=infinity: `infinity` is not a number"),
    (["--set", "n"], "--set n: expected NAME=VALUE"),
    (["--set", "n=5", "--set", " n=50"], "--set n is given twice (n=5, n=50); give it once"),
    (["--every", "0"], "--every 0: must be 1 or more"),
    (["--steps", "-1"], "--steps -1: must be 0 or more"),
    (["--seed", "-1"], "--seed -1: must be from 0 to 9,223,372,036,854,775,807"),
    (["--seed", str(2**63)], f"--seed {2**63}: must be from 0 to"),
    (["--steps", str(10**20)], f"--steps {10**20}: must be from 0 to"),
    (["--every", str(2**63)], f"--every {2**63}: must be from 1 to"),
    (["--record", "x.avi"], "--record x.avi: the file must end in .gif or .mp4"),
])
def test_bad_options_name_the_option(program, capsys, args, message):
    assert main(["run", str(program), "--headless", *args]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err


def test_missing_file_is_a_clear_error(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.swarm"), "--headless"]) == 2
    assert "no such program file" in capsys.readouterr().err


def test_check_prints_warnings_and_succeeds(tmp_path, capsys):
    path = tmp_path / "w.swarm"
    path.write_text("agent a {\n  count 2\n  var unused = 1\n  status s { }\n"
                    "  status lost { }\n}\n")
    assert main(["check", str(path)]) == 0
    captured = capsys.readouterr()
    assert f"{path}:3:7: warning: variable `unused` of `a` is never read" in captured.err
    assert f"{path}:5:10: warning: status `lost` of `a` is unreachable" in captured.err
    assert f"{path}:4:10: warning: status `s` of `a` has no way out" in captured.err
    assert "ok (1 agent kind, 2 statuses, 3 warnings)" in captured.out


def test_fault_in_the_first_tick_prints_no_rate(backend, tmp_path, capsys):
    """No tick ran, so there is no ticks/s to report (it read `(inf ticks/s)`)."""
    path = tmp_path / "first.swarm"
    path.write_text("agent a {\n  count 2\n  status s { velocity = (1 / (index - index), 0) }\n}\n")
    assert main(["run", str(path), "--headless", "--steps", "5"]) == 2
    out = capsys.readouterr().out
    assert "stopped by a fault after 0 ticks of 2 agents in " in out
    assert "ticks/s" not in out and "inf" not in out


def test_runtime_fault_keeps_recorded_ticks(backend, tmp_path, capsys):
    path = tmp_path / "fault.swarm"
    path.write_text("""agent a {
  count 3
  var t = 0
  status s {
    t += 1
    velocity = (1 / (5 - t), 0)
  }
}
""")
    out = tmp_path / "o"
    assert _run(path, out, "--steps", "10") == 2
    err = capsys.readouterr().err
    assert f"{path}:6:5: error: `velocity` became infinite" in err
    assert "status `s`" in err and "tick 4" in err
    table = pq.read_table(out / "agents.parquet")
    assert sorted(set(table["tick"].to_pylist())) == [0, 1, 2, 3, 4]
    run = json.loads((out / "run.json").read_text())
    assert run["steps"] == 4 and run["finished"] == "fault"


def test_internal_error_is_a_fault_that_keeps_recorded_ticks(backend, program, tmp_path,
                                                             monkeypatch, capsys):
    from swarmdsl.runtime import simulation

    real_step = simulation.Simulation.step

    def step(self):     # a bug in swarmdsl, not in the program
        if self.tick == 3:
            raise IndexError("too many indices for array")
        real_step(self)

    monkeypatch.setattr(simulation.Simulation, "step", step)
    monkeypatch.delenv("SWARMDSL_DEBUG", raising=False)
    out = tmp_path / "o"
    assert _run(program, out, "--steps", "10") == 3
    captured = capsys.readouterr()
    message = ("internal error at tick 3: IndexError: too many indices for array "
               "(please report this)")
    assert f"error: {message}" in captured.err.splitlines()
    assert "Traceback" not in captured.err
    assert "stopped by a fault after 3 ticks" in captured.out
    ticks = sorted(set(pq.read_table(out / "agents.parquet")["tick"].to_pylist()))
    assert ticks == [0, 1, 2, 3]
    run = json.loads((out / "run.json").read_text())
    assert run["finished"] == "fault" and run["last_tick"] == 3
    assert message in run["error"]
    # SWARMDSL_DEBUG=1: the same run, its outputs closed, then the exception as it is
    monkeypatch.setenv("SWARMDSL_DEBUG", "1")
    with pytest.raises(IndexError, match="too many indices"):
        _run(program, out, "--steps", "10")
    assert json.loads((out / "run.json").read_text())["finished"] == "fault"


INTERNAL = ("error: internal error: RuntimeError: boom (please report this; "
            "SWARMDSL_DEBUG=1 shows the traceback)")


def _boom(*args, **kwargs):
    raise RuntimeError("boom")


def _internal_error_only(captured) -> None:
    """One line naming the exception, last on stderr (after the program's warnings),
    never a traceback."""
    lines = captured.err.splitlines()
    assert lines[-1] == INTERNAL and lines.count(INTERNAL) == 1
    assert "Traceback" not in captured.err


def test_internal_error_in_check_is_one_line_and_exit_3(program, monkeypatch, capsys):
    import swarmdsl.compiler

    monkeypatch.setattr(swarmdsl.compiler, "compile_file", _boom)
    monkeypatch.delenv("SWARMDSL_DEBUG", raising=False)
    assert main(["check", str(program)]) == 3
    _internal_error_only(capsys.readouterr())
    monkeypatch.setenv("SWARMDSL_DEBUG", "0")       # 0 is off
    assert main(["check", str(program)]) == 3
    monkeypatch.setenv("SWARMDSL_DEBUG", "1")
    with pytest.raises(RuntimeError, match="boom"):
        main(["check", str(program)])


def test_internal_error_while_a_run_sets_up_is_one_line_and_exit_3(program, tmp_path,
                                                                   monkeypatch, capsys):
    from swarmdsl.runtime import simulation

    monkeypatch.setattr(simulation.Simulation, "__init__", _boom)
    monkeypatch.delenv("SWARMDSL_DEBUG", raising=False)
    out = tmp_path / "o"
    assert _run(program, out, "--steps", "5") == 3
    _internal_error_only(capsys.readouterr())
    assert not out.exists()         # stopped before the first tick: nothing written


def test_internal_error_while_a_run_closes_is_one_line_and_exit_3(backend, program, tmp_path,
                                                                  monkeypatch, capsys):
    from swarmdsl.runtime.record import Recorder

    monkeypatch.setattr(Recorder, "close", _boom)
    monkeypatch.delenv("SWARMDSL_DEBUG", raising=False)
    assert _run(program, tmp_path / "o", "--steps", "3") == 3
    _internal_error_only(capsys.readouterr())


def test_a_mistyped_option_gets_the_subcommands_usage_and_the_option_meant(program,
                                                                           capsys):
    """argparse passed unknown words up to the top level, which printed its own usage."""
    with pytest.raises(SystemExit) as exit_:
        main(["run", str(program), "--stpes", "3"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: swarmdsl run ")
    assert err.endswith("swarmdsl run: error: unrecognized arguments: --stpes 3 "
                        "(did you mean --steps?)\n")
    with pytest.raises(SystemExit) as exit_:
        main(["check", str(program), "--sett", "n=3"])
    assert exit_.value.code == 2
    assert capsys.readouterr().err.endswith(
        "swarmdsl check: error: unrecognized arguments: --sett n=3 (did you mean --set?)\n")


def test_the_guard_leaves_option_errors_and_ctrl_c_as_they_were(program, monkeypatch,
                                                                capsys):
    import swarmdsl.compiler

    with pytest.raises(SystemExit) as exit_:       # argparse: usage and exit 2
        main(["run", str(program), "--no-such-option"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "swarmdsl run: error: unrecognized arguments: --no-such-option\n" in err
    assert main(["run", str(program), "--headless", "--every", "0"]) == 2
    assert capsys.readouterr().err == "error: --every 0: must be 1 or more\n"

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(swarmdsl.compiler, "compile_file", interrupted)
    assert main(["check", str(program)]) == 130
    assert capsys.readouterr().err == "swarmdsl: stopped by SIGINT\n"


@pytest.mark.parametrize("debug", [False, True])
def test_internal_error_from_the_command_line(program, debug):
    """The real process: one line and exit 3; SWARMDSL_DEBUG=1 shows the traceback."""
    import os

    code = ("import sys, swarmdsl.compiler as c\n"
            "def boom(*a, **k): raise RuntimeError('boom')\n"
            "c.compile_file = boom\n"
            "from swarmdsl.cli import main\n"
            f"sys.exit(main(['check', {str(program)!r}]))\n")
    env = {k: v for k, v in os.environ.items() if k != "SWARMDSL_DEBUG"}
    if debug:
        env["SWARMDSL_DEBUG"] = "1"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env)
    if debug:
        assert done.returncode == 1
        assert "Traceback (most recent call last)" in done.stderr
        assert done.stderr.rstrip().endswith("RuntimeError: boom")
        assert "in boom" in done.stderr
    else:
        assert done.returncode == 3
        assert done.stderr.splitlines() == [INTERNAL]


def test_ctrl_c_keeps_what_was_recorded(backend, program, tmp_path, monkeypatch, capsys):
    from swarmdsl.runtime import simulation

    real_step = simulation.Simulation.step

    def step(self):
        if self.tick == 6:
            raise KeyboardInterrupt
        real_step(self)

    monkeypatch.setattr(simulation.Simulation, "step", step)
    out = tmp_path / "o"
    assert _run(program, out, "--steps", "20") == 130
    assert "interrupted after 6 ticks" in capsys.readouterr().out
    ticks = sorted(set(pq.read_table(out / "agents.parquet")["tick"].to_pylist()))
    assert ticks == list(range(7))
    assert json.loads((out / "run.json").read_text())["finished"] == "interrupted"


def test_gif_recording(backend, program, tmp_path):
    import imageio.v3 as iio

    gif = tmp_path / "walk.gif"
    assert main(["run", str(program), "--headless", "--steps", "6", "--every", "2",
                 "--record", str(gif)]) == 0
    frames = iio.imread(gif, index=None)
    assert frames.shape[0] == 4          # ticks 0, 2, 4, 6
    assert frames.shape[1] % 16 == 0 and frames.shape[2] % 16 == 0


def test_a_video_that_cannot_be_written_is_an_error_naming_record(backend, program, tmp_path,
                                                                 monkeypatch, capsys):
    import errno

    from swarmdsl.viz.video import VideoWriter

    def finish(self):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(VideoWriter, "_finish", finish)
    gif = tmp_path / "walk.gif"
    assert main(["run", str(program), "--headless", "--steps", "2", "--record",
                 str(gif)]) == 2
    captured = capsys.readouterr()
    assert f"no video written to {gif}" in captured.out
    assert (f"error: --record {gif}: no video written (no space left on device)"
            in captured.err)
    assert not gif.exists() and not list(tmp_path.glob(".*"))


def test_a_disk_that_fills_while_a_gif_streams_stops_the_video_not_the_run(
        backend, program, tmp_path, monkeypatch, capsys):
    """Frames reach the file as the run goes, so a full disk shows mid-run: the run and
    its other outputs finish, the video is not claimed, and the exit is 2, as when the
    file could not be finished."""
    import errno

    from swarmdsl.viz.video import VideoWriter

    send = VideoWriter._send_gif

    def fills(self, frame):
        if self.frames_written == 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        send(self, frame)
    monkeypatch.setattr(VideoWriter, "_send_gif", fills)
    gif, out = tmp_path / "walk.gif", tmp_path / "out"
    assert main(["run", str(program), "--headless", "--steps", "8", "--out", str(out),
                 "--record", str(gif)]) == 2
    captured = capsys.readouterr()
    assert (f"error: --record {gif}: no video written (no space left on device)"
            in captured.err)
    assert "internal error" not in captured.err
    run = json.loads((out / "run.json").read_text())
    assert (run["finished"], run["recorded_ticks"]) == ("completed", 9)
    assert not gif.exists() and not list(tmp_path.glob(".*"))


def test_version_and_help():
    done = subprocess.run([sys.executable, "-m", "swarmdsl", "--version"],
                          capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == f"swarmdsl {__version__}"
    for cmd in (["--help"], ["run", "--help"], ["check", "--help"]):
        done = subprocess.run([sys.executable, "-m", "swarmdsl", *cmd],
                              capture_output=True, text=True)
        assert done.returncode == 0 and "usage: swarmdsl" in done.stdout


@pytest.mark.parametrize("argv, listed", [
    (["--help"], True), (["run", "--help"], False), (["check", "x.swarm"], False),
    (["sweep", "--help"], True), (["--version"], True), ([], True), (["rn"], True)])
def test_run_and_check_build_only_their_own_commands(argv, listed):
    """`run` and `check` skip the other commands' modules (their start-up); anything
    else, a misspelt command included, gets the whole tree and its list of choices."""
    from swarmdsl.cli import _command_word, build_parser

    parser = build_parser(_command_word(argv))
    commands = parser._subparsers._group_actions[0].choices
    assert {"run", "check"} <= set(commands)
    assert ({"sweep", "train", "test", "plot", "graph"} <= set(commands)) is listed


def test_run_without_display_falls_back_to_headless(backend, program, tmp_path, capsys,
                                                    monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    assert main(["run", str(program), "--steps", "2"]) == 0
    assert "no display available: running headless" in capsys.readouterr().err


def test_command_line_starts_without_heavy_imports():
    """Building the parser (every `swarmdsl` call) must not pull in torch, hypothesis,
    pygame or the runtime: `swarmdsl --help` should answer at once."""
    code = ("import sys; from swarmdsl.cli import build_parser; build_parser(); "
            "print(sorted(m for m in ('torch', 'hypothesis', 'pygame', 'scipy') "
            "if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


# Every file or folder option, with what the rest of its command line needs.
_PATH_OPTIONS = [
    (["run", "{p}", "--headless", "--out", ""], "--out"),
    (["run", "{p}", "--headless", "--record", ""], "--record"),
    (["run", "{p}", "--headless", "--example", ""], "--example"),
    (["run", "{p}", "--headless", "--resume", ""], "--resume"),
    (["run", "", "--headless"], "file"),
    (["check", ""], "file"),
    (["sweep", "{p}", "--out", ""], "--out"),
    (["sweep", ""], "file"),
    (["test", "{p}", "--save-example", ""], "--save-example"),
    (["test", ""], "file"),
    (["graph", "{p}", "-o", ""], "-o"),
    (["graph", ""], "file"),
    (["train", "spring1d", "--out", ""], "--out"),
    (["plot", "time", "", "-o", "x.png"], "RUN_DIR"),
    (["plot", "time", "{d}", "-o", ""], "-o"),
    (["plot", "sweep", "", "--x", "n", "--metric", "m", "-o", "x.png"], "table"),
    (["plot", "sweep", "{d}", "--x", "n", "--metric", "m", "-o", ""], "-o"),
]


@pytest.mark.parametrize("argv, option", _PATH_OPTIONS,
                         ids=[" ".join(a[:2 if a[0] == "plot" else 1] + [o])
                              for a, o in _PATH_OPTIONS])
def test_an_empty_path_is_refused_naming_the_option(program, tmp_path, monkeypatch, capsys,
                                                    argv, option):
    """`Path("")` is the current folder: `run --out ""` wrote a run into it and
    `--record ""` was refused as `--record .`."""
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    argv = [a.format(p=program, d=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f'error: {option} "": the path is empty; give ' in err
    assert "Traceback" not in err
    assert list(work.iterdir()) == []           # nothing written where the user stands


def test_a_path_of_spaces_is_refused_too(program, capsys):
    assert main(["run", str(program), "--headless", "--record", "  "]) == 2
    assert 'error: --record "  ": the path is only spaces' in capsys.readouterr().err


def test_no_option_reads_a_path_that_turns_empty_into_the_current_folder():
    """Every path option goes through `path_arg`, which refuses an empty path: a new
    option declared with `type=Path` would bring the bug back."""
    import argparse
    from pathlib import Path

    from swarmdsl.cli import build_parser

    def actions(parser):
        for action in parser._actions:
            yield parser.prog, action
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    yield from actions(sub)

    bare = [f"{prog} {'/'.join(a.option_strings) or a.dest}"
            for prog, a in actions(build_parser()) if a.type in (Path, str)]
    assert bare == []


def test_the_api_refuses_an_empty_program_path():
    from swarmdsl.compiler import compile_file
    from swarmdsl.compiler.errors import SwarmOptionError

    with pytest.raises(SwarmOptionError, match="no program file given: the path is empty"):
        compile_file("")


def test_run_help_names_every_output_and_the_default_steps():
    """`run --help` left out `metrics.parquet`, and the 1000 ticks a world without
    `steps` runs for was written nowhere."""
    import argparse

    from swarmdsl.cli import build_parser
    from swarmdsl.compiler.info import WorldInfo

    parser = build_parser("run")
    run = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    text = " ".join(run.choices["run"].format_help().split())
    assert "metrics.parquet (when the program declares a `metric`)" in text
    assert f"default: the world's `steps`, {WorldInfo().steps} when it sets none" in text


def test_a_world_without_steps_runs_the_documented_1000_ticks(backend, tmp_path, capsys):
    path = tmp_path / "p.swarm"
    path.write_text("agent a { count 1; velocity (0, 0); status s { } }\n")
    assert main(["run", str(path), "--headless"]) == 0
    assert "ran 1000 ticks" in capsys.readouterr().out


@pytest.mark.parametrize("command", [["graph"], ["check"]])
def test_output_into_a_closed_pipe_stops_quietly(walk, command):
    """`swarmdsl graph FILE | head -1` printed `error: internal error: BrokenPipeError`
    and exited 3 once head had read its line."""
    import os
    import subprocess
    import sys

    read, write = os.pipe()
    os.close(read)              # the reader is gone before the command writes a byte
    try:
        done = subprocess.run([sys.executable, "-m", "swarmdsl", *command, str(walk)],
                              stdout=write, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write)
    assert done.returncode == 141, done.stderr
    assert done.stderr == ""


@pytest.mark.parametrize(("given", "expected"), [(None, "0"), ("1", "1")])
def test_the_command_asks_numpy_not_to_advise_huge_pages(given, expected):
    """Where the system grants 2 MB pages only on advice, a big run's fresh arrays
    waited while it compacted memory for them: the command's numpy does not ask for
    them, unless the user set it so."""
    import os

    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    if given is not None:
        env["NUMPY_MADVISE_HUGEPAGE"] = given
    probe = ("import sys; sys.argv = ['swarmdsl']; import swarmdsl.cli, os; "
             "print(os.environ['NUMPY_MADVISE_HUGEPAGE'])")
    got = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                         text=True, check=True)
    assert got.stdout.strip() == expected
