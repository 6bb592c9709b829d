"""Rename of every kind of declaration, in-process (the server's end-to-end rename is
in test_lsp.py): every occurrence is renamed, and the renamed program compiles."""

from __future__ import annotations

from pathlib import Path

import pytest

from swarmdsl.compiler import compile_source
from swarmdsl.lsp.analysis import analyse
from swarmdsl.lsp.navigate import RenameRefused, apply_edits, rename

ROOT = Path(__file__).resolve().parents[1]


def _at(text: str, needle: str, offset: int):
    i = text.index(needle) + offset
    return text.count("\n", 0, i), i - (text.rfind("\n", 0, i) + 1)


@pytest.mark.parametrize("program, needle, offset, new, uses", [
    ("aco.swarm", "memory trail", 7, "path", 7),          # a path memory
    ("aco.swarm", "field pheromone", 6, "scent", 3),      # a field
    ("aco.swarm", "food alpha", 5, "alpha2", 1),          # a region
    ("aco_bt.swarm", "tree walk", 5, "stroll", 2),        # a named tree and its use
    ("aco_bt.swarm", "walk(steps)", 5, "n_steps", 2),     # a tree's parameter
    ("matrix2d.swarm", "status content", 7, "inside", 4),  # a status and its transitions
    ("boids.swarm", "let near", 4, "nearby", 5),          # a let
    ("patrol.swarm", "var battery", 4, "charge", 8),      # a variable, and its property
])
def test_rename_renames_every_use_and_the_program_compiles(program, needle, offset, new,
                                                           uses):
    path = ROOT / "programs" / program
    text = path.read_text()
    old = needle.split()[-1].split("(")[-1].rstrip(")") if "(" in needle else \
        needle.split()[-1]
    edits = rename(analyse(text, str(path)), *_at(text, needle, offset), new)
    assert len(edits) == uses
    renamed = apply_edits(text, edits)
    compile_source(renamed, str(path))
    assert {text.split("\n")[r.line][r.col:r.end_col] for r, _ in edits} == {old}


def test_a_rename_the_checker_would_refuse_is_refused():
    text = ("agent a {\n  count 2\n  var e = 1\n  status s {\n    let k = e + 1\n"
            "    e = k\n  }\n}\n")
    with pytest.raises(RenameRefused, match="already the variable `e`"):
        rename(analyse(text, "t.swarm"), *_at(text, "let k", 4), "e")
    with pytest.raises(RenameRefused, match="not a name"):
        rename(analyse(text, "t.swarm"), *_at(text, "let k", 4), "2k")
    with pytest.raises(RenameRefused, match="keyword or a built-in"):
        rename(analyse(text, "t.swarm"), *_at(text, "let k", 4), "when")
