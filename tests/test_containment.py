"""Every file a program or training spec names stays under its folder, is a regular
file of bounded size, and a refused file's content never reaches the output."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from swarmdsl.cli import main

SECRET = "TOP-SECRET-7f3a"
PROGRAM = ('agent a {\n  count 3\n  var out = 0\n  status s {\n'
           '    out = nn("models/m.pt", 1, 2)\n  }\n}\n')


def _sidecar(**over) -> dict:
    side = {"format": "swarmdsl-model", "arch": "mlp", "n_in": 2, "n_out": 1,
            "hidden": [4], "activation": "relu",
            "normalisation": {"input": {"shift": [0.0, 0.0], "scale": [1.0, 1.0]},
                              "output": {"shift": [0.0], "scale": [1.0]}}}
    side.update(over)
    return side


@pytest.fixture
def project(tmp_path) -> Path:
    """A program folder with `models/m.pt` (its bytes never read by `check`)."""
    folder = tmp_path / "project"
    (folder / "models").mkdir(parents=True)
    (folder / "models" / "m.pt").write_bytes(b"weights")
    (folder / "p.swarm").write_text(PROGRAM)
    return folder


def _check(folder: Path, capsys) -> tuple[int, str]:
    capsys.readouterr()
    rc = main(["check", str(folder / "p.swarm")])
    out = capsys.readouterr()
    return rc, out.out + out.err


def assert_refused_unread(rc: int, out: str, words: str) -> None:
    assert rc == 2, out
    assert re.search(rf"p\.swarm:5:\d+: error: .*{words}", out), out
    assert SECRET not in out


def test_a_plain_sidecar_is_accepted(project, capsys):
    (project / "models" / "m.json").write_text(json.dumps(_sidecar()))
    rc, out = _check(project, capsys)
    assert rc == 0, out


def test_sidecar_symlinked_outside_is_refused_unread(project, tmp_path, capsys):
    outside = tmp_path / "elsewhere.json"
    outside.write_text(json.dumps(_sidecar(format=SECRET)))
    (project / "models" / "m.json").symlink_to(outside)
    assert_refused_unread(*_check(project, capsys), "symlink to another folder")


def test_sidecar_that_is_a_fifo_is_refused_without_hanging(project, capsys):
    os.mkfifo(project / "models" / "m.json")
    assert_refused_unread(*_check(project, capsys), "not a regular file")


def test_sidecar_symlinked_to_a_device_is_refused(project, capsys):
    (project / "models" / "m.json").symlink_to("/dev/zero")
    assert_refused_unread(*_check(project, capsys), "another folder")


def test_oversized_sidecar_is_refused_before_reading(project, capsys):
    (project / "models" / "m.json").write_text(json.dumps(_sidecar(pad=SECRET * 200_000)))
    assert_refused_unread(*_check(project, capsys), "bytes; at most")


@pytest.mark.parametrize("over", [
    {"format": SECRET}, {"arch": SECRET}, {"activation": SECRET}, {"hidden": [SECRET]},
    {"n_in": SECRET}, {"n_out": [SECRET]},
])
def test_bad_sidecar_values_are_not_quoted(project, capsys, over):
    (project / "models" / "m.json").write_text(json.dumps(_sidecar(**over)))
    assert_refused_unread(*_check(project, capsys), "model sidecar 'm.json'")


@pytest.mark.parametrize("over", [
    {"hidden": [10**9]}, {"hidden": [4096] * 17}, {"hidden": [4096, 4096, 4096]},
])
def test_claimed_shapes_are_limited_before_any_allocation(project, capsys, over):
    (project / "models" / "m.json").write_text(json.dumps(_sidecar(**over)))
    assert_refused_unread(*_check(project, capsys), "(at most|parameters)")


def test_deeply_nested_sidecar_json_is_refused(project, capsys):
    (project / "models" / "m.json").write_text("[" * 100_000 + "]" * 100_000)
    rc, out = _check(project, capsys)
    assert rc == 2 and "Traceback" not in out


# ---- training specs ----

def _train(spec_path: Path, capsys) -> tuple[int, str]:
    capsys.readouterr()
    rc = main(["train", str(spec_path)])
    out = capsys.readouterr()
    return rc, out.out + out.err


@pytest.mark.parametrize("key,value", [
    ("out", "../../escaped.pt"), ("out", "/tmp/escaped-absolute.pt"),
    ("out", "models/../../escaped.pt"), ("name", "../../escaped"),
])
def test_spec_cannot_write_outside_its_folder(tmp_path, capsys, key, value):
    folder = tmp_path / "a" / "b"
    folder.mkdir(parents=True)
    spec = folder / "spec.json"
    spec.write_text(json.dumps({"task": "spring1d", key: value, "epochs": 1,
                                "samples": 20}))
    rc, out = _train(spec, capsys)
    assert rc == 2, out
    assert re.search(r"(absolute|'\.\.')", out), out
    assert not list(tmp_path.rglob("escaped*"))
    assert not Path("/tmp/escaped-absolute.pt").exists()


def test_spec_out_through_a_symlinked_folder_is_refused(tmp_path, capsys):
    folder = tmp_path / "spec"
    folder.mkdir()
    outside = tmp_path / "outside"
    outside.mkdir()
    (folder / "models").symlink_to(outside)
    spec = folder / "spec.json"
    spec.write_text(json.dumps({"task": "spring1d", "out": "models/x.pt"}))
    rc, out = _train(spec, capsys)
    assert rc == 2 and "symlink" in out, out
    assert not list(outside.iterdir())


def test_spec_that_is_a_fifo_is_refused_without_hanging(tmp_path, capsys):
    spec = tmp_path / "spec.json"
    os.mkfifo(spec)
    rc, out = _train(spec, capsys)
    assert rc == 2 and "not a regular file" in out, out


def test_spec_values_are_not_quoted(tmp_path, capsys):
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"task": SECRET}))
    rc, out = _train(spec, capsys)
    assert rc == 2 and SECRET not in out, out
    spec.write_text(json.dumps({"task": "spring1d", "epochs": SECRET}))
    rc, out = _train(spec, capsys)
    assert rc == 2 and SECRET not in out, out


# ---- the program file itself ----

def test_program_that_is_a_fifo_or_device_is_refused_without_hanging(tmp_path, capsys):
    fifo = tmp_path / "p.swarm"
    os.mkfifo(fifo)
    assert main(["check", str(fifo)]) == 2
    assert "not a regular file" in capsys.readouterr().err
    assert main(["check", "/dev/zero"]) == 2
    assert "not a regular file" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["run", "check"])
def test_a_refused_program_file_is_named_by_the_path_given(command, capsys):
    """`/dev/null` was reported as 'null', a name that points at no file."""
    assert main([command, "/dev/null"]) == 2
    assert capsys.readouterr().err == ("error: program file '/dev/null' is not a "
                                       "regular file\n")


def test_a_fifo_program_is_named_by_the_path_given(tmp_path, monkeypatch, capsys):
    (tmp_path / "programs").mkdir()
    os.mkfifo(tmp_path / "programs" / "p.swarm")
    monkeypatch.chdir(tmp_path)
    assert main(["check", "./programs/p.swarm"]) == 2
    assert capsys.readouterr().err == ("error: program file './programs/p.swarm' is not "
                                       "a regular file\n")


def test_a_missing_training_spec_is_named_by_the_path_given(tmp_path, capsys):
    rc, out = _train(tmp_path / "specs" / "nope.json", capsys)
    assert rc == 2
    assert f"training spec '{tmp_path / 'specs' / 'nope.json'}' not found" in out, out


def test_huge_program_file_is_refused_before_reading(tmp_path, capsys):
    big = tmp_path / "big.swarm"
    big.write_text("# " + "x" * (11 * 2**20) + "\n")
    assert main(["check", str(big)]) == 2
    assert "bytes; at most" in capsys.readouterr().err
