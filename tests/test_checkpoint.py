"""Checkpoints: a resumed run is bit-identical to an uninterrupted one, for every shipped
program; checkpoints of another program or version are refused; outputs continue."""

from __future__ import annotations

import functools
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import assert_same_outputs, cli_error
from hypothesis import given, settings
from hypothesis import strategies as st

import swarmdsl
from swarmdsl.cli import main
from swarmdsl.compiler import compile_file
from swarmdsl.compiler.errors import SwarmOptionError
from swarmdsl.runtime import checkpoint
from swarmdsl.runtime.runner import Run
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
SHIPPED = sorted(p.name for p in PROGRAMS.glob("*.swarm"))


@functools.cache
def _program(name):
    return compile_file(PROGRAMS / name)


def _state(sim) -> dict:
    out = {f"col/{k}": v for k, v in sim.agents.cols.items()}
    out.update({f"declared/{k}": v for k, v in sim.agents.declared.items()})
    for i, ext in enumerate(sim.extensions):
        for k, v in ext.state_dict(sim).items():
            out[f"ext/{i}/{k}"] = v
    out["tick"] = sim.tick
    out["rng"] = json.dumps(sim.rng.state(), sort_keys=True)
    return out


def _assert_identical(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], np.ndarray):
            assert a[k].dtype == b[k].dtype, k
            assert a[k].tobytes() == b[k].tobytes(), f"{k} differs after resuming"
        else:
            assert a[k] == b[k], k


@pytest.mark.parametrize("name", SHIPPED)
@settings(max_examples=4)
@given(stop=st.integers(0, 12), more=st.integers(1, 10), seed=st.integers(0, 1000))
def test_resumed_run_is_bit_identical(backend, tmp_path_factory, name, stop, more, seed):
    program = _program(name)
    whole = Simulation(program, seed)
    whole.run(stop + more)
    first = Simulation(program, seed)
    first.run(stop)
    folder = tmp_path_factory.mktemp("ck") / "checkpoint"
    checkpoint.save(first, folder)
    resumed = Simulation(program, 12345)         # the checkpoint's seed wins
    checkpoint.load(resumed, folder)
    resumed.run(more)
    _assert_identical(_state(whole), _state(resumed))


def test_checkpoint_of_another_program_or_params_is_refused(backend, tmp_path):
    sim = Simulation(_program("vicsek.swarm"), 1)
    sim.run(2)
    checkpoint.save(sim, tmp_path / "checkpoint")
    other = Simulation(compile_file(PROGRAMS / "vicsek.swarm", {"eta": "2"}), 1)
    with pytest.raises(SwarmOptionError, match="another program .* or other --set values"):
        checkpoint.load(other, tmp_path / "checkpoint")
    with pytest.raises(SwarmOptionError, match="another program"):
        checkpoint.load(Simulation(_program("boids.swarm"), 1), tmp_path / "checkpoint")


def test_checkpoint_of_another_version_is_refused(backend, tmp_path):
    sim = Simulation(_program("vicsek.swarm"), 1)
    checkpoint.save(sim, tmp_path / "checkpoint")
    meta = json.loads((tmp_path / "checkpoint" / "meta.json").read_text())
    meta["version"] = "0.0.1"
    (tmp_path / "checkpoint" / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(SwarmOptionError, match="written by swarmdsl 0.0.1"):
        checkpoint.load(Simulation(_program("vicsek.swarm"), 1), tmp_path / "checkpoint")


def test_checkpoint_of_draws_keyed_by_line_is_refused(backend, tmp_path):
    """A checkpoint written before draws were keyed by their place (it names no
    generator) would resume with other draws than its run's: refused, naming both."""
    sim = Simulation(_program("vicsek.swarm"), 1)
    checkpoint.save(sim, tmp_path / "checkpoint")
    meta = json.loads((tmp_path / "checkpoint" / "meta.json").read_text())
    assert meta.pop("generator") == "swarmdsl-counter-v2"
    (tmp_path / "checkpoint" / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(SwarmOptionError, match="swarmdsl-counter-v1's, this swarmdsl draws "
                                               "swarmdsl-counter-v2's"):
        checkpoint.load(Simulation(_program("vicsek.swarm"), 1), tmp_path / "checkpoint")


@pytest.mark.parametrize("name", ["aco.swarm", "vicsek.swarm", "matrix2d.swarm"])
def test_resumed_cli_run_continues_the_same_files(backend, tmp_path, name):
    path = str(PROGRAMS / name)
    whole, split = tmp_path / "whole", tmp_path / "split"
    common = ["run", path, "--headless", "--every", "4", "--seed", "5", "--set"]
    sets = ["n=60"] if name == "vicsek.swarm" else []
    common = common[:-1] + [a for s in sets for a in ("--set", s)]
    assert main([*common, "--steps", "24", "--out", str(whole)]) == 0
    # a run killed at tick 20 whose last checkpoint is at tick 16: its outputs hold
    # ticks 17-20 too, which the resumed run drops and writes again, the same
    early = tmp_path / "early"
    assert main([*common, "--steps", "16", "--out", str(early), "--checkpoint-every",
                 "8"]) == 0
    assert main([*common, "--steps", "20", "--out", str(split)]) == 0
    shutil.copytree(early / "checkpoint", split / "checkpoint")
    assert main(["run", path, "--headless", "--resume", str(split), "--steps", "24",
                 *[a for s in sets for a in ("--set", s)]]) == 0
    assert_same_outputs(whole, split)
    if (whole / "metrics.parquet").exists():
        summary = json.loads((whole / "run.json").read_text())["metrics"]
        assert json.loads((split / "run.json").read_text())["metrics"] == summary


def test_resume_refuses_other_params_with_a_clear_error(backend, tmp_path, capsys):
    path = str(PROGRAMS / "vicsek.swarm")
    assert main(["run", path, "--headless", "--steps", "4", "--out", str(tmp_path),
                 "--checkpoint-every", "2"]) == 0
    capsys.readouterr()
    assert main(["run", path, "--headless", "--resume", str(tmp_path), "--set",
                 "eta=3"]) == 2
    err = capsys.readouterr().err
    assert "error: --set eta=3: the run in" in err and "has eta=1" in err
    assert "Traceback" not in err
    assert main(["run", path, "--headless", "--resume", str(tmp_path / "nothing")]) == 2
    assert "no checkpoint there" in capsys.readouterr().err
    assert main(["run", path, "--headless", "--checkpoint-every", "3"]) == 2
    assert "needs --out" in capsys.readouterr().err


def test_recorded_rows_keep_the_values_of_their_tick(backend, tmp_path):
    """A column changed in place later (messages' `msg_tick`) must not rewrite old rows."""
    program = _program("matrix2d.swarm")
    assert main(["run", str(PROGRAMS / "matrix2d.swarm"), "--headless", "--steps", "9",
                 "--every", "3", "--seed", "2", "--out", str(tmp_path)]) == 0
    rows = pq.read_table(tmp_path / "agents.parquet").to_pandas()
    sim = Simulation(program, 2)
    for tick in (0, 3, 6, 9):
        sim.run(tick - sim.tick)
        got = rows[rows.tick == tick].sort_values("id")
        declared = sim.agents.declared["msg_tick"]
        want = sim.agents.cols["msg_tick"][np.argsort(sim.agents.cols["id"])]
        assert np.array_equal(got.msg_tick.to_numpy()[declared], want[declared]), tick


@pytest.mark.parametrize("name", ["aco.swarm", "spring1d.swarm"])
@settings(max_examples=4)
@given(k=st.integers(1, 7), stop=st.integers(1, 15), more=st.integers(1, 8))
def test_run_checkpointed_every_k_resumes_bit_identical(backend, tmp_path_factory, name, k, stop,
                                                        more):
    """Interrupted (Ctrl-C) at `stop`: it resumes from its last multiple of K."""
    from swarmdsl.runtime.runner import Run

    class Interrupted(Run):
        def step(self):
            if self.sim.tick == stop:
                raise KeyboardInterrupt
            super().step()

    program = _program(name)
    tmp = tmp_path_factory.mktemp("run")
    steps = stop + more
    whole = Run(program, seed=4, steps=steps, out=tmp / "whole", every=2)
    whole.show_progress = False
    whole.execute()
    part = Interrupted(program, seed=4, steps=steps, out=tmp / "part", every=2)
    part.show_progress, part.checkpoint_every = False, k
    assert part.execute() == "interrupted"
    again = Run(program, seed=4, steps=steps, out=tmp / "part", every=2)
    again.show_progress = False
    if stop < k:                                   # no checkpoint was written yet
        with pytest.raises(SwarmOptionError, match="no checkpoint"):
            again.resume(tmp / "part")
        return
    assert again.resume(tmp / "part") == stop // k * k
    assert again.execute() == "completed"
    _assert_identical(_state(whole.sim), _state(again.sim))
    assert pq.read_table(tmp / "whole" / "agents.parquet").equals(
        pq.read_table(tmp / "part" / "agents.parquet"))


@pytest.mark.parametrize("damage", ["truncate", "drop_meta_key"])
def test_damaged_checkpoint_is_an_option_error(backend, tmp_path, capsys, damage):
    path = str(PROGRAMS / "vicsek.swarm")
    assert main(["run", path, "--headless", "--steps", "3", "--out", str(tmp_path),
                 "--checkpoint-every", "2"]) == 0
    ck = tmp_path / "checkpoint"
    if damage == "truncate":
        data = (ck / "state.npz").read_bytes()
        (ck / "state.npz").write_bytes(data[: len(data) // 2])
    else:
        meta = json.loads((ck / "meta.json").read_text())
        del meta["rng"]
        (ck / "meta.json").write_text(json.dumps(meta))
    capsys.readouterr()
    assert main(["run", path, "--headless", "--resume", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "checkpoint" in err and "Traceback" not in err


def _checkpointed(tmp_path, *extra, name="vicsek.swarm", steps="6"):
    """A finished run of `name` in tmp_path/run with a checkpoint at its last tick, and
    a copy to resume from: (program path, run folder, its untouched copy)."""
    path = str(PROGRAMS / name)
    out = tmp_path / "run"
    assert main(["run", path, "--headless", "--steps", steps, "--out", str(out),
                 "--checkpoint-every", "3", *extra]) == 0
    shutil.copytree(out, tmp_path / "copy")
    return path, out, tmp_path / "copy"


def _fresh(out: Path, copy: Path) -> None:
    shutil.rmtree(out)
    shutil.copytree(copy, out)


def _refused(capsys, argv, *expected) -> str:
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    for text in expected:
        assert text in err, err
    return err


def test_resume_with_another_seed_is_refused_naming_seed(backend, tmp_path, capsys):
    path, out, _copy = _checkpointed(tmp_path, "--seed", "2")
    before = (out / "run.json").read_text()
    _refused(capsys, ["run", path, "--headless", "--resume", str(out), "--steps", "9",
                      "--seed", "9"],
             "error: --seed 9: the checkpoint in", "a run with seed 2", "leave out --seed")
    assert (out / "run.json").read_text() == before      # nothing ran, nothing written
    assert main(["run", path, "--headless", "--resume", str(out), "--steps", "9",
                 "--seed", "2"]) == 0
    assert json.loads((out / "run.json").read_text())["seed"] == 2


def _recorded_ticks(out: Path) -> list[int]:
    return sorted(set(pq.read_table(out / "agents.parquet").column("tick").to_pylist()))


def test_resume_keeps_every_and_checkpoint_every_unless_given(backend, tmp_path):
    path, out, copy = _checkpointed(tmp_path, "--every", "3")
    resume = ["run", path, "--headless", "--resume", str(out), "--steps", "12"]
    assert main(resume) == 0
    assert _recorded_ticks(out) == [0, 3, 6, 9, 12]
    assert json.loads((out / "checkpoint" / "meta.json").read_text())["tick"] == 12
    _fresh(out, copy)
    # --every 1 is the old default: given, it must count all the same
    assert main([*resume, "--every", "1", "--checkpoint-every", "0"]) == 0
    assert _recorded_ticks(out) == [0, 3, 6, 7, 8, 9, 10, 11, 12]
    assert json.loads((out / "checkpoint" / "meta.json").read_text())["tick"] == 6


def test_a_resumed_run_reports_the_rate_of_the_ticks_it_ran(backend, tmp_path, capsys):
    # steps_per_second divided all the run's ticks by the time of those after the
    # checkpoint, and the progress lines printed every tick until they caught up.
    path, out, _copy = _checkpointed(tmp_path, "--every", "50", steps="120")
    before = json.loads((out / "checkpoint" / "meta.json").read_text())
    capsys.readouterr()
    assert main(["run", path, "--headless", "--resume", str(out), "--steps", "200"]) == 0
    said = capsys.readouterr()
    err = said.err
    shown = [line.split("(")[1].split(")")[0] for line in err.splitlines()
             if line.startswith("tick ")]
    assert shown == ["70%", "80%", "90%", "100%"], err
    assert ": ran 80 ticks (resumed at tick 120, now at 200) of " in said.out, said.out
    meta = json.loads((out / "run.json").read_text())
    assert meta["steps"] == 200
    # the checkpoint kept the time of the 120 ticks before it: run.json's rate and time
    # are the whole run's
    assert 0 < before["tick_seconds"] < meta["wall_seconds"]
    assert meta["steps_per_second"] * meta["wall_seconds"] == pytest.approx(200, rel=0.05)


def test_a_resumed_run_of_an_older_checkpoint_times_its_own_ticks(backend, tmp_path, capsys):
    """A checkpoint without the time before it (written before it kept one): run.json
    gives the time and rate of the ticks this process ran."""
    path, out, _copy = _checkpointed(tmp_path, "--every", "50", steps="120")
    meta_file = out / "checkpoint" / "meta.json"
    saved = json.loads(meta_file.read_text())
    del saved["tick_seconds"]
    meta_file.write_text(json.dumps(saved))
    assert main(["run", path, "--headless", "--resume", str(out), "--steps", "200"]) == 0
    meta = json.loads((out / "run.json").read_text())
    assert meta["steps_per_second"] * meta["wall_seconds"] == pytest.approx(80, rel=0.05)


def test_resuming_a_finished_run_keeps_its_time(backend, tmp_path, capsys):
    """Nothing left to run: run.json kept the run's time, not 0 s and no rate."""
    path, out, _copy = _checkpointed(tmp_path, steps="60")
    first = json.loads((out / "run.json").read_text())
    assert main(["run", path, "--headless", "--resume", str(out)]) == 0
    again = json.loads((out / "run.json").read_text())
    assert again["wall_seconds"] == pytest.approx(first["wall_seconds"], rel=1e-6)
    assert again["steps_per_second"] == pytest.approx(first["steps_per_second"], rel=1e-3)


def test_resume_with_other_params_names_the_param(backend, tmp_path, capsys):
    path, out, _copy = _checkpointed(tmp_path, "--set", "n=30")
    resume = ["run", path, "--headless", "--resume", str(out), "--steps", "9"]
    _refused(capsys, [*resume, "--set", "n=20"],
             "error: --set n=20: the run in", "has n=30; resume with the same params")
    _refused(capsys, resume, f"error: --resume {out}: the run has n=30, this one n=",
             "give --set n=30")
    assert main([*resume, "--set", "n=30"]) == 0


def test_resume_with_an_edited_program_says_so_not_which_set_to_give(backend, tmp_path, capsys):
    """A param's default edited in the file looked like other --set values: the advice
    `give --set n=400` was then refused as "another program". The text is compared
    first."""
    path, out, _copy = _checkpointed(tmp_path)
    edited = tmp_path / "edited.swarm"
    edited.write_text(Path(path).read_text().replace("param n = 400", "param n = 401"))
    err = _refused(capsys, ["run", str(edited), "--headless", "--resume", str(out),
                            "--steps", "9"],
                   f"error: --resume {out}: {edited} is not the program the run was made "
                   "with", "resume with that file unchanged")
    assert "--set" not in err


def test_resume_keeps_the_tree_columns_and_refuses_new_ones(backend, tmp_path, capsys):
    path, out, copy = _checkpointed(tmp_path, "--tree-leaf", name="patrol.swarm")
    resume = ["run", path, "--headless", "--resume", str(out), "--steps", "9"]
    _refused(capsys, [*resume, "--tree-memory"], "error: --tree-memory: the run in",
             "was made without it", "leave out --tree-memory")
    whole = tmp_path / "whole"
    assert main(["run", path, "--headless", "--steps", "9", "--out", str(whole),
                 "--tree-leaf"]) == 0
    for again in ([], ["--tree-leaf"]):
        _fresh(out, copy)
        assert main([*resume, *again]) == 0
        assert pq.read_table(out / "agents.parquet").equals(
            pq.read_table(whole / "agents.parquet"))


CHECKED = """world { size 20 x 20 }
agent a { count 3; var t = 0
  status s { t = t + 1 }
  invariant low: t < 100
  invariant lower: t < 50 }
"""


def test_resume_keeps_the_checks_and_refuses_others(backend, tmp_path, capsys):
    program = tmp_path / "checked.swarm"
    program.write_text(CHECKED)
    out = tmp_path / "run"
    assert main(["run", str(program), "--headless", "--steps", "6", "--out", str(out),
                 "--checkpoint-every", "3", "--property", "low"]) == 0
    resume = ["run", str(program), "--headless", "--resume", str(out)]
    _refused(capsys, [*resume, "--steps", "60", "--check"],
             "error: --check: the run in", "checked a.low before its checkpoint")
    _refused(capsys, [*resume, "--steps", "60", "--property", "lower"],
             "error: --property lower: the run in", "checked a.low before")
    # kept without asking: t reaches 50 at tick 50, which only `lower` forbids
    assert main([*resume, "--steps", "60"]) == 0
    assert main([*resume, "--steps", "100", "--property", "a.low"]) == 1
    assert "`a.low` violated at tick 100" in capsys.readouterr().err


def test_resume_refuses_checks_the_run_did_not_make(backend, tmp_path, capsys):
    program = tmp_path / "checked.swarm"
    program.write_text(CHECKED)
    out = tmp_path / "run"
    assert main(["run", str(program), "--headless", "--steps", "6", "--out", str(out),
                 "--checkpoint-every", "3"]) == 0
    _refused(capsys, ["run", str(program), "--headless", "--resume", str(out), "--check"],
             "error: --check: the run in", "checked no properties")


def test_resume_keeps_the_backend_of_the_checkpoint(tmp_path, capsys, monkeypatch):
    from swarmdsl.runtime import compiled

    path, out, _copy = _checkpointed(tmp_path, "--backend", "numpy")
    meta = json.loads((out / "checkpoint" / "meta.json").read_text())
    assert meta["backend"] == "numpy"
    meta["backend"] = "numba"
    (out / "checkpoint" / "meta.json").write_text(json.dumps(meta))
    monkeypatch.setattr(compiled, "numba_installed", lambda: False)
    _refused(capsys, ["run", path, "--headless", "--resume", str(out), "--steps", "9"],
             f"error: --resume {out}: the run used the numba backend, which is not "
             "installed here", "--backend numpy")
    assert main(["run", path, "--headless", "--resume", str(out), "--steps", "9",
                 "--backend", "numpy"]) == 0
    assert json.loads((out / "run.json").read_text())["backend"] == "numpy"


def _stopped_at(run, tick: int, signum) -> None:
    """Make `run` stop as a signal between ticks does, once it has run `tick` ticks."""
    from swarmdsl import stopping

    step = run.step

    def step_then_stop():
        step()
        if run.sim.tick == tick:
            raise stopping.Stopped(signum)
    run.step = step_then_stop


@pytest.mark.parametrize("stop", [13, 16, 10])  # off and on --every 4, on --checkpoint-every 5
@pytest.mark.parametrize("name", ["aco.swarm", "vicsek.swarm"])   # fields, metrics
def test_a_stop_signal_writes_a_checkpoint_at_the_stop_tick(backend, tmp_path, name, stop):
    # a preempted job (SIGTERM) with --checkpoint-every 5 resumed from its last
    # checkpoint, losing up to 5 ticks; now it resumes where it stopped, and the run
    # it finishes has the outputs of a run never stopped
    import signal

    from swarmdsl.runtime.runner import Run

    program = _program(name)
    whole, split = tmp_path / "whole", tmp_path / "split"
    whole_run = Run(program, seed=3, steps=24, out=whole, every=4, backend=backend)
    assert whole_run.execute() == "completed"
    first = Run(program, seed=3, steps=24, out=split, every=4, backend=backend)
    first.checkpoint_every = 5
    _stopped_at(first, stop, signal.SIGTERM)
    assert first.execute() == "interrupted"
    assert json.loads((split / "run.json").read_text())["last_tick"] == stop
    assert checkpoint.read_meta(split / "checkpoint")["tick"] == stop
    again = Run(program, seed=3, steps=24, out=split, every=4, backend=backend)
    assert again.resume(split) == stop
    assert again.execute() == "completed"
    assert_same_outputs(whole, split)
    assert json.loads((split / "run.json").read_text()).get("metrics") == json.loads(
        (whole / "run.json").read_text()).get("metrics")


def test_sigterm_of_a_checkpointing_cli_run_checkpoints_its_stop_tick(backend, tmp_path):
    # the backend named: unnamed, the default picks numba for a million ticks and numpy
    # for the short whole run (each is checked against itself here)
    import os
    import signal
    import subprocess
    import sys
    import time

    path = str(PROGRAMS / "vicsek.swarm")
    out = tmp_path / "run"
    root = Path(__file__).resolve().parent.parent
    proc = subprocess.Popen(
        [sys.executable, "-m", "swarmdsl", "run", path, "--headless", "--set", "n=40",
         "--backend", backend, "--steps", "1000000", "--every", "7", "--checkpoint-every", "50", "--out",
         str(out)], env=dict(os.environ, PYTHONPATH=str(root)),
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300
        while not (out / "checkpoint" / "meta.json").exists():
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=120) == 143
    finally:
        proc.kill()
    stop = json.loads((out / "run.json").read_text())["last_tick"]
    assert checkpoint.read_meta(out / "checkpoint")["tick"] == stop
    whole = tmp_path / "whole"
    common = ["run", path, "--headless", "--set", "n=40", "--every", "7",
              "--backend", backend, "--steps", str(stop + 9)]
    assert main([*common, "--out", str(whole)]) == 0
    assert main([*common, "--resume", str(out)]) == 0
    assert_same_outputs(whole, out)


def test_a_resume_with_another_every_records_both_in_run_json(tmp_path):
    path, out, copy = _checkpointed(tmp_path, "--every", "3")
    assert json.loads((out / "run.json").read_text()).get("every_history") is None
    assert main(["run", path, "--headless", "--resume", str(out), "--steps", "12",
                 "--every", "2"]) == 0
    meta = json.loads((out / "run.json").read_text())
    assert meta["every"] == 2 and meta["every_history"] == [[0, 3], [6, 2]]
    assert _recorded_ticks(out) == [0, 3, 6, 8, 10, 12]
    # a second resume keeps the history the checkpoint carries
    assert main(["run", path, "--headless", "--resume", str(out), "--steps", "15",
                 "--every", "5"]) == 0
    meta = json.loads((out / "run.json").read_text())
    assert meta["every_history"] == [[0, 3], [6, 2], [12, 5]]


def _checkpointed_run(walk: Path, out: Path) -> None:
    argv = ["run", str(walk), "--headless", "--steps", "10", "--out", str(out),
            "--checkpoint-every", "5"]
    assert main(argv) == 0


@pytest.mark.parametrize("output", ["agents.parquet", "fields.npz", "metrics.parquet"])
def test_resuming_a_run_whose_output_was_deleted_is_refused(backend, walk, tmp_path, capsys,
                                                            output):
    out = tmp_path / "out"
    _checkpointed_run(walk, out)
    target = out / output
    shutil.rmtree(target) if target.is_dir() else target.unlink()
    err = cli_error(capsys, ["run", str(walk), "--headless", "--resume", str(out),
                          "--steps", "15"])
    assert f"--resume {out}: {output} is missing" in err
    assert not target.exists()      # nothing written that starts mid-run


def _api_checkpointed(tmp_path, steps: int = 6) -> tuple[object, Path]:
    """A program and the folder of its finished run, checkpointed at its last tick."""
    program = swarmdsl.load_program(PROGRAMS / "vicsek.swarm", {"n": 20})
    out = tmp_path / "run"
    run = _quiet(Run(program, seed=2, steps=steps, out=out))
    run.checkpoint_every = 3
    assert run.execute() == "completed"
    return program, out


def _quiet(run: Run) -> Run:
    run.show_progress = False
    return run


def _recorded(out: Path):
    return pq.read_table(out / "agents.parquet")


@pytest.mark.parametrize("change, named", [
    (dict(seed=3), "seed 3: the checkpoint"),
    (dict(steps=2), "steps 2: the checkpoint"),
    (dict(out="other"), "build the Run with out="),
])
def test_a_resume_the_checkpoint_cannot_continue_is_refused_and_keeps_the_files(
        backend, tmp_path, change, named):
    """`Run(seed=3).resume(DIR)` of a seed-2 checkpoint drew seed 2's numbers and wrote
    `"seed": 3` into run.json; fewer steps than the checkpoint's tick, or another out
    folder, were taken too, the folder's files cut back to the checkpoint before any
    check. Now each is refused naming the argument, the finished run left whole."""
    program, out = _api_checkpointed(tmp_path)
    before = _recorded(out)
    given = dict(seed=2, steps=10, out=out)
    given.update({k: tmp_path / v if k == "out" else v for k, v in change.items()})
    with pytest.raises(SwarmOptionError, match=named):
        Run(program, **given).resume(out)
    assert _recorded(out).equals(before)


def test_resuming_without_the_runs_tree_columns_names_the_option(backend, tmp_path):
    """A checkpoint of a `tree_leaf=True` run resumed by a Run without it was refused
    as "the checkpoint's agent columns differ from this program's", though the program
    was the same; now the message names tree_leaf and the value to give."""
    program = swarmdsl.load_program(PROGRAMS / "patrol.swarm")
    out = tmp_path / "run"
    run = _quiet(Run(program, seed=1, steps=4, out=out, tree_leaf=True))
    run.checkpoint_every = 2
    run.execute()
    with pytest.raises(SwarmOptionError, match="build the Run with tree_leaf=True"):
        Run(program, seed=1, steps=8, out=out).resume(out)


def test_resume_refuses_a_run_that_already_ran_and_a_folder_that_is_not_a_path(backend,
                                                                               tmp_path):
    """`run.resume(DIR)` after `run.execute()` cut the finished run's files back to the
    checkpoint; `resume(None)` was a TypeError from pathlib."""
    program, out = _api_checkpointed(tmp_path)
    run = _quiet(Run(program, seed=2, steps=6, out=out))
    run.execute()
    before = _recorded(out)
    with pytest.raises(SwarmOptionError, match="already run"):
        run.resume(out)
    assert _recorded(out).equals(before)
    for folder in (None, 3):
        with pytest.raises(SwarmOptionError, match="folder"):
            Run(program, seed=2, steps=10, out=out).resume(folder)


@pytest.mark.parametrize("every, out, named", [
    ("2", "run", "checkpoint_every must be a whole number"),
    (-1, "run", "checkpoint_every must be from 0"),
    (2, None, "checkpoint_every needs a Run with out"),
])
def test_a_bad_checkpoint_every_is_refused_before_the_run(backend, tmp_path, every, out,
                                                          named):
    """`run.checkpoint_every = "2"` ran a tick and stopped with an internal error; with
    no `out` the run went on and wrote no checkpoint. Both are refused before a tick."""
    program = swarmdsl.load_program(PROGRAMS / "vicsek.swarm", {"n": 20})
    run = Run(program, steps=4, out=out and tmp_path / out)
    run.checkpoint_every = every
    with pytest.raises(SwarmOptionError, match=named):
        run.execute()
    assert run.sim.tick == 0
