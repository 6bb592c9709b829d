"""Every bad program in tests/data/errors gives its exact `line:col: message`, and the
CLI prints it gcc-style with a caret and exits 2."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from swarmdsl.cli import main
from swarmdsl.compiler import compile_file
from swarmdsl.compiler.errors import SwarmError

ERRORS = sorted((Path(__file__).parent / "data" / "errors").glob("*.swarm"))


def _expectation(path: Path):
    m = re.match(r"# expect: (\d+):(\d+): (.*)", path.read_text().splitlines()[0])
    assert m, f"{path.name} lacks a `# expect: L:C: message` header"
    return int(m[1]), int(m[2]), m[3]


def test_error_folder_is_not_empty():
    assert len(ERRORS) >= 15


@pytest.mark.parametrize("path", ERRORS, ids=[p.stem for p in ERRORS])
def test_bad_program_reports_position_and_message(path):
    line, col, message = _expectation(path)
    with pytest.raises(SwarmError) as info:
        compile_file(path)
    err = info.value
    assert (err.span.line, err.span.col) == (line, col)
    assert err.message == message


@pytest.mark.parametrize("path", ERRORS[:6], ids=[p.stem for p in ERRORS[:6]])
def test_cli_check_prints_caret_and_exits_2(path, capsys):
    line, col, message = _expectation(path)
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    first, quoted, caret = err.splitlines()[:3]
    assert first == f"{path}:{line}:{col}: error: {message}"
    assert quoted.startswith(f"{line:>4} | ")
    # the caret sits under the reported column of the quoted line
    assert caret.index("^") == len(f"{line:>4} | ") + col - 1


def test_misspelt_status_suggests_the_right_one(capsys):
    path = next(p for p in ERRORS if p.stem == "misspelt_status")
    assert main(["run", str(path), "--headless", "--steps", "1"]) == 2
    assert "hint: did you mean 'fooded'?" in capsys.readouterr().err


def test_checker_reports_every_error_not_just_the_first(compile_src):
    src = """agent a {
  count 2
  status s {
    velocity += (radiu, 0)
    when speed > 1 -> tt
  }
  status t { }
}
"""
    with pytest.raises(SwarmError) as info:
        compile_src(src)
    messages = [d.message for d in info.value.diagnostics]
    assert messages == ["unknown name `radiu`", "unknown status `tt` in agent `a`"]
