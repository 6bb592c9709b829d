"""Random streams are keyed by a draw's place in the program's structure: comments,
blank lines, indentation and spaces change no bit of a run; a structural edit changes
the streams `docs/outputs.md` says it changes, and only those."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_same_outputs
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.compiler import ast, compile_file, compile_source
from swarmdsl.compiler.stream_places import place_of, table_of
from swarmdsl.ops.functions import FUNCTIONS
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
SHIPPED = sorted(PROGRAMS.glob("*.swarm")) + sorted(PROGRAMS.glob("kilobot/*.swarm"))
# numba runs these too (its kernels hoist the draws, and each program compiles its own):
# a flock, a behaviour tree with a sensing model and field reads, messaging robots
ON_NUMBA = ["boids.swarm", "patrol.swarm", "spring1d.swarm"]
MAX_COUNT = 30   # agents per kind in these short runs
STRING_OR_COMMENT = re.compile(r'("[^"\n]*"|#[^\n]*)')


def _spaced(code: str) -> str:
    """Spaces around punctuation and the arithmetic operators (not `+=`, `/=`, `*=`,
    nor an exponent's sign `1e+3`): what a formatter might do."""
    code = re.sub(r"([,(){}])", r" \1 ", code)
    return re.sub(r"(?<![0-9][eE])([*+/^])(?!=)", r" \1 ", code)


def relaid(text: str) -> str:
    """`text` with its layout changed and its meaning kept: comment lines and blank
    lines at the top and between every two lines, every line indented afresh (tab and
    spaces) with trailing blanks, and spaces around operators, outside strings and
    comments."""
    out = ["# a comment at the top, as an annotating user adds", "", ""]
    for i, line in enumerate(text.splitlines()):
        parts = STRING_OR_COMMENT.split(line)
        line = "".join(p if k % 2 else _spaced(p) for k, p in enumerate(parts))
        out += [f"\t  {line.strip()}   ", f"  # note {i}: layout is not meaning", ""]
    return "\n".join(out) + "\n"


def _small(path: Path) -> list[str]:
    """`--set` options that cap each kind's count (a bare param) at MAX_COUNT."""
    program = compile_file(path)
    sets = []
    for kind in program.info.kinds:
        count = kind.options.get("count")
        arg = count.args[0] if count is not None and count.args else None
        if isinstance(arg, ast.Name) and arg.id in program.info.params \
                and program.info.params[arg.id] > MAX_COUNT:
            sets += ["--set", f"{arg.id}={MAX_COUNT}"]
    return sets


def _run(path: Path, out: Path, backend: str, sets: list[str]) -> None:
    assert main(["run", str(path), "--headless", "--steps", "6", "--every", "1",
                 "--seed", "7", "--out", str(out), "--backend", backend, *sets]) == 0


def _relaid_copy(path: Path, folder: Path) -> Path:
    """The program relaid, in a folder of its own beside a copy of the shipped models
    (`nn(...)` reads them from the program's folder)."""
    folder.mkdir()
    shutil.copytree(PROGRAMS / "models", folder / "models")
    copy = folder / path.name
    copy.write_text(relaid(path.read_text()))
    return copy


def _assert_layout_keeps_bits(path: Path, backend: str, tmp_path: Path) -> None:
    copy = _relaid_copy(path, tmp_path / "relaid")
    assert copy.read_text() != path.read_text()
    sets = _small(path)
    _run(path, tmp_path / "as_shipped", backend, sets)
    _run(copy, tmp_path / "as_relaid", backend, sets)
    assert_same_outputs(tmp_path / "as_shipped", tmp_path / "as_relaid")


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_comments_blank_lines_and_indentation_change_no_bit_of_a_shipped_program(
        path, tmp_path):
    """Every shipped program, relaid, records the same agents, fields and metrics as
    shipped, row for row and bit for bit (numpy; `ON_NUMBA` on numba below)."""
    _assert_layout_keeps_bits(path, "numpy", tmp_path)


@pytest.mark.parametrize("name", ON_NUMBA)
def test_layout_changes_no_bit_on_numba(name, tmp_path):
    pytest.importorskip("numba")
    _assert_layout_keeps_bits(PROGRAMS / name, "numba", tmp_path)


def _draw_places(program) -> list[str]:
    """The place of every draw the program compiles (a `choose` is one too)."""
    return sorted(place for node, place in table_of(program.info).values()
                  if isinstance(node, ast.Call)
                  and (getattr(FUNCTIONS.get(node.name), "random", False)
                       or node.name == "choose"))


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_every_draw_of_a_shipped_program_has_a_place_of_its_own(path):
    """No two draws share a stream (they would draw the same numbers), and no place
    is spelt with a line or column: relaid, the places are the same strings."""
    places = _draw_places(compile_file(path))
    assert len(places) == len(set(places))
    copy = compile_source(relaid(path.read_text()), path.name, program_dir=PROGRAMS)
    assert _draw_places(copy) == places


# A program that draws wherever a program can draw: a kind's initial velocity, a
# variable's initial value, a status body, a `when`'s actions, a behaviour tree (a
# condition, an assignment leaf, a named tree used twice), a field read through a
# sensing model, `choose`.
EVERYWHERE = """param n = 12
world { size 80 x 80; edges wrap }
field scent { decay 0.1 }
robot noisy { field_noise 0.2; field_dropout 0.1 }
tree hop(p) { sequence { chance(p); velocity = velocity + random_direction() * p } }
agent walker {
  count n
  robot noisy
  velocity random_direction() * uniform(0.5, 1.5)
  var energy = normal(10, 2)
  var smell = 0
  status roam {
    let turn = normal(0, 0.3)
    velocity = rotate(velocity, turn)
    smell = sample(scent) + random()
    deposit(scent, uniform(0, 1))
    when chance(0.1) -> rest { energy = energy - random() }
  }
  status rest {
    velocity = unit(choose(8, 0.5)) * 0.5
    tree sequence { hop(0.3); hop(0.6); energy = energy + uniform(0, 0.1) }
    when random() < 0.2 -> roam
  }
}
"""


def _agents(text: str, backend: str, steps: int = 8, seed: int = 5) -> dict:
    sim = Simulation(compile_source(text, "everywhere.swarm"), seed, backend=backend)
    sim.run(steps)
    order = np.argsort(sim.agents.cols["id"])
    return {k: np.asarray(v)[order] for k, v in sim.agents.cols.items()}


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def test_the_program_that_draws_everywhere_draws_at_distinct_places():
    places = _draw_places(compile_source(EVERYWHERE, "everywhere.swarm"))
    # 15 draws run; the named tree's two as declared are listed too (never run)
    assert len(places) == len(set(places)) == 17
    assert "agent walker/status roam/body[0]/value" in places
    assert "agent walker/option velocity/args[0]/right" in places
    assert "agent walker/var energy/value" in places
    # the named tree used twice: each use's `chance(p)` draws a stream of its own
    hop = "agent walker/status rest/body[1]/root/kids[{}]/root/kids[0]/expr"
    assert hop.format(0) in places and hop.format(1) in places


@settings(max_examples=12, deadline=None)
@given(data=st.data())
def test_any_layout_of_the_program_that_draws_everywhere_gives_the_same_run(backend, data):
    """Comments, blank lines and spaces at any line boundary, each line indented
    anyhow: the same agents, bit for bit."""
    lines = EVERYWHERE.splitlines()
    out = []
    for line in lines:
        out += data.draw(st.lists(st.sampled_from(["", "# c", "   # x = normal(0, 1)"]),
                                  max_size=2))
        indent = data.draw(st.sampled_from(["", " ", "\t", "      "]))
        trail = data.draw(st.sampled_from(["", "  ", "\t", "  # trailing"]))
        out.append(indent + line.strip() + trail)
    assert _same(_agents(EVERYWHERE, backend), _agents("\n".join(out), backend))


def _value_of(text: str, backend: str) -> np.ndarray:
    return _agents(text, backend, steps=3)["energy"]


def test_a_statement_inserted_before_a_draw_in_its_block_changes_that_draw(backend):
    """`docs/outputs.md`: the draw's index in its block is part of its place. The
    draw of `energy` moves from body[0] to body[1]: its numbers change; a statement
    inserted in another status, or a status moved, leaves them."""
    base = """world { size 50 x 50; edges wrap }
agent a {
  count 6
  var energy = 0
  var spare = 0
  status s {
    energy = energy + normal(0, 1)
  }
  status t { spare = 1 }
}
"""
    before = _value_of(base, backend)
    inserted = base.replace("  status s {\n", "  status s {\n    spare = uniform(0, 1)\n")
    assert not np.array_equal(_value_of(inserted, backend), before)
    # without a draw, the inserted statement still moves the draw to body[1]
    plain = base.replace("  status s {\n", "  status s {\n    spare = 2\n")
    assert not np.array_equal(_value_of(plain, backend), before)
    # appended after it: the draw keeps body[0]
    after = base.replace("energy + normal(0, 1)\n",
                         "energy + normal(0, 1)\n    spare = uniform(0, 1)\n")
    assert np.array_equal(_value_of(after, backend), before)
    # another status edited, or moved above this one: nothing changes here
    elsewhere = base.replace("status t { spare = 1 }", "status t { spare = random() }")
    assert np.array_equal(_value_of(elsewhere, backend), before)
    moved = base.replace("  status t { spare = 1 }\n", "").replace(
        "  status s {", "  status t { spare = 1 }\n  status s {")
    moved = moved.replace("count 6", "count 6\n  initial s")
    assert np.array_equal(_value_of(moved, backend), before)


def test_renaming_a_status_or_swapping_arguments_changes_its_draws(backend):
    base = """world { size 50 x 50; edges wrap }
agent a {
  count 6
  var energy = 0
  status s { energy = energy + normal(0, 1) + 0 }
}
"""
    before = _value_of(base, backend)
    renamed = base.replace("status s", "status s2")
    assert not np.array_equal(_value_of(renamed, backend), before)
    # the draw becomes the right operand, not the left: another place
    swapped = base.replace("normal(0, 1) + 0", "0 + normal(0, 1)")
    assert not np.array_equal(_value_of(swapped, backend), before)
    # redundant parentheses are layout
    paren = base.replace("normal(0, 1) + 0", "((normal(0, 1))) + (0)")
    assert np.array_equal(_value_of(paren, backend), before)


def test_a_draw_the_program_does_not_hold_has_no_place():
    """A node built outside the checked program is an internal error, never a key
    made up from its line."""
    program = compile_source(EVERYWHERE, "everywhere.swarm")
    stray = ast.Call(None, "random", None, (), None, None)
    with pytest.raises(Exception, match="no place in the program's structure"):
        place_of(program.info, stray)


def test_semicolons_and_a_line_split_inside_parentheses_are_layout(backend):
    lines = """world { size 50 x 50; edges wrap }
agent a {
  count 5
  var energy = 0
  status s {
    energy = energy + normal(0, 1)
    velocity = (random(), 0)
  }
}
"""
    packed = """world { size 50 x 50; edges wrap }
agent a { count 5; var energy = 0; status s { energy = energy + normal(0,
      1); velocity = (random(), 0) } }
"""
    assert _same(_agents(lines, backend), _agents(packed, backend))
