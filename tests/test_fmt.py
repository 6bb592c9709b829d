"""`swarmdsl fmt`: one layout, stable, comments kept, meaning never changed."""

from __future__ import annotations

import random
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.compiler.parse import parse, tokens
from swarmdsl.errors import SwarmError
from swarmdsl.format import format_source, meaning

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = sorted((ROOT / "programs").rglob("*.swarm"))


def _doc_programs():
    for path in sorted((ROOT / "docs").glob("*.md")):
        for i, block in enumerate(re.findall(r"```swarm\n(.*?)```", path.read_text(), re.S)):
            try:
                parse(block)
            except SwarmError:
                continue     # a fragment or a deliberate mistake: nothing to format
            yield pytest.param(block, id=f"{path.stem}-{i}")


DOC_PROGRAMS = list(_doc_programs())


def _assert_same_meaning_and_stable(text: str) -> str:
    out = format_source(text)
    assert meaning(parse(out)) == meaning(parse(text))
    assert format_source(out) == out
    return out


@pytest.mark.parametrize("path", PROGRAMS, ids=lambda p: p.name)
def test_shipped_programs_are_in_the_layout_and_keep_their_meaning(path):
    text = path.read_text()
    assert _assert_same_meaning_and_stable(text) == text


def test_documented_programs_are_found():
    assert len(DOC_PROGRAMS) >= 30


@pytest.mark.parametrize("text", DOC_PROGRAMS)
def test_documented_programs_keep_their_meaning_and_format_stably(text):
    _assert_same_meaning_and_stable(text)


def test_a_messy_program_is_laid_out_and_its_comments_kept():
    messy = ("param n=10 # how many\nparam r  =  2*n in 1..100\n\n\n\n"
             "world{size 100 x 100;grid 10}\nagent a{\ncount n\n    var e=-1\n status s{\n"
             "# the neighbours\nlet k=neighbors(r)\n      e+=sum(k:other.e)-  -2\n"
             "when e>3->s{e=0}\n  velocity=(if e>0 then -1 else 1,0)\n}\n}\n\n\n")
    assert _assert_same_meaning_and_stable(messy) == (
        "param n = 10 # how many\nparam r = 2 * n in 1..100\n\n"
        "world { size 100 x 100; grid 10 }\nagent a {\n  count n\n  var e = -1\n"
        "  status s {\n    # the neighbours\n    let k = neighbors(r)\n"
        "    e += sum(k : other.e) - -2\n    when e > 3 -> s { e = 0 }\n"
        "    velocity = (if e > 0 then -1 else 1, 0)\n  }\n}\n")


def test_an_option_before_a_vector_keeps_its_space_and_a_call_has_none():
    text = ("agent a {\n  count 2\n  place (10, 10)\n"
            "  status s { velocity = rotate ((1, 0), 1) }\n}\n")
    out = _assert_same_meaning_and_stable(text)
    assert "place (10, 10)" in out and "rotate((1, 0), 1)" in out


def test_an_options_values_stay_apart_and_a_subtraction_stays_one():
    text = "world { size 100 x 100; origin 10 -20 }\nagent a {\n  count 2\n" \
           "  place (50, 50) -(1, 1)\n  heading 1-2\n  status s { }\n}\n"
    out = _assert_same_meaning_and_stable(text)
    assert "origin 10 -20" in out and "place (50, 50) -(1, 1)" in out
    assert "heading 1 - 2" in out


def test_a_continued_line_keeps_its_alignment_under_its_opening_line():
    text = ("agent a {\ncount 2\nstatus s {\nlet g = (if tick > 3 then 1\n"
            "          else 2)\nvelocity = (g, 0)\n}\n}\n")
    out = _assert_same_meaning_and_stable(text)
    assert "    let g = (if tick > 3 then 1\n              else 2)\n" in out


_WORDISH = re.compile(r"[A-Za-z0-9_.\"]")


def _perturbed(text: str, rng: random.Random) -> str:
    """`text` with the blanks between tokens of a line and the indentation of lines
    outside brackets changed at random (never joining two words)."""
    toks = tokens(text)
    out, end, depth = [], 0, 0
    continued_lines = set()
    for ttype, value, start, stop in toks:
        between = text[end:start]
        if ttype == "LPAR":
            depth += 1
        if end and between and between.strip(" ") == "":
            joinable = not (_WORDISH.match(value[:1]) and _WORDISH.match(text[end - 1]))
            # around a `-` the spacing says whether an option's value starts there
            if value != "-" and text[end - 1] != "-":
                between = " " * rng.randint(0 if joinable else 1, 3)
        elif "\n" in between and "#" not in between.rsplit("\n", 1)[1]:
            head, _sep, indent = between.rpartition("\n")
            line = text.count("\n", 0, start)
            if depth == 0 and not _opens_continuation(text, start):
                indent = " " * rng.randint(0, 6)
            else:
                continued_lines.add(line)
            between = head + "\n" + indent
        if ttype == "RPAR":
            depth = max(0, depth - 1)
        out.append(between + value)
        end = stop
    out.append(text[end:])
    return "".join(out)


def _opens_continuation(text: str, start: int) -> bool:
    """Whether the line from `start` leaves a `(` open (its next line is continued)."""
    line = text[start:text.find("\n", start)]
    return line.split("#")[0].count("(") > line.split("#")[0].count(")")


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(PROGRAMS), st.integers(0, 2 ** 32 - 1))
def test_any_spacing_of_a_shipped_program_formats_back_to_it(path, seed):
    text = path.read_text()
    messy = _perturbed(text, random.Random(seed))
    assert meaning(parse(messy)) == meaning(parse(text))
    assert format_source(messy) == text


def test_fmt_check_reports_rewrites_and_leaves_broken_files_alone(tmp_path, capsys):
    good = tmp_path / "good.swarm"
    good.write_text("agent a {\n  count 2\n  status s { }\n}\n")
    messy = tmp_path / "messy.swarm"
    messy.write_text("agent a{\ncount 2\nstatus s{}\n}\n")
    broken = tmp_path / "broken.swarm"
    broken.write_text("agent a {\n  count 2\n  status s { velocity = (1, }\n}\n")
    assert main(["fmt", "--check", str(good)]) == 0
    assert main(["fmt", "--check", str(good), str(messy)]) == 1
    assert f"would reformat {messy}" in capsys.readouterr().err
    assert messy.read_text() == "agent a{\ncount 2\nstatus s{}\n}\n"
    assert main(["fmt", str(messy)]) == 0
    assert messy.read_text() == "agent a {\n  count 2\n  status s { }\n}\n"
    before = broken.read_text()
    assert main(["fmt", str(broken)]) == 2
    err = capsys.readouterr().err
    assert f"{broken}:3:" in err and "error: unexpected" in err and "^" in err
    assert broken.read_text() == before


def test_fmt_reads_standard_input_with_a_dash(monkeypatch, capsys):
    import io
    import sys

    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(b"param  x=1\n")))
    assert main(["fmt", "-"]) == 0
    assert capsys.readouterr().out == "param x = 1\n"


def test_a_formatter_that_would_change_meaning_refuses(monkeypatch):
    import swarmdsl.format as fmt

    monkeypatch.setattr(fmt, "_layout", lambda text, *_: text.replace("1", "2"))
    with pytest.raises(fmt.FormatError, match="change the program's meaning"):
        format_source("param x = 1\n")


_DRAWS = ("param n = 20\nworld { size 100 x 100; edges wrap }\n"
          "agent a {\n  count n\n  velocity random_direction()\n  status s {\n"
          "    velocity = rotate(velocity, normal(0, 0.3))\n  }\n}\n")


def test_a_run_is_bit_identical_when_no_draw_moved(backend):
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    messy = _DRAWS.replace("param n = 20", "param  n=20").replace(
        "world { size 100 x 100; edges wrap }", "world{size 100 x 100;edges wrap}")
    out = format_source(messy)
    assert out == _DRAWS and fmt_moved(messy, out) == []
    runs = []
    for text in (messy, out):
        sim = Simulation(compile_source(text, "d.swarm"), 5, backend=backend)
        sim.run(8)
        runs.append(sim.agents.cols["pos"].copy())
    assert runs[0].tobytes() == runs[1].tobytes()


def fmt_moved(a, b):
    from swarmdsl.format import moved_draws

    return moved_draws(a, b)


def test_re_indenting_a_draw_moves_no_stream(tmp_path, capsys, backend):
    """Formatting re-indents the line of `normal(...)` (its column changes): its
    stream is keyed by its place in the program, so the run is the same bit for bit
    and fmt has no draw to name."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    messy = _DRAWS.replace("    velocity = rotate", "        velocity = rotate")
    out = format_source(messy)
    assert out == _DRAWS and fmt_moved(messy, out) == []
    runs = []
    for text in (messy, out):
        sim = Simulation(compile_source(text, "d.swarm"), 5, backend=backend)
        sim.run(8)
        runs.append(sim.agents.cols["pos"].copy())
    assert runs[0].tobytes() == runs[1].tobytes()
    path = tmp_path / "d.swarm"
    path.write_text(messy)
    assert main(["fmt", str(path)]) == 0
    assert "random draw" not in capsys.readouterr().err
    assert path.read_text() == _DRAWS


def test_fmt_names_a_draw_whose_place_changed(monkeypatch, tmp_path, capsys):
    """Were the formatter to move a draw to another place (it refuses to change the
    syntax tree, so only a broken one could), fmt names it."""
    from swarmdsl import format as fmt

    swapped = _DRAWS.replace("normal(0, 0.3)", "normal(0, 0.3) + 0")
    moved = _DRAWS.replace("normal(0, 0.3)", "0 + normal(0, 0.3)")
    assert [m[0] for m in fmt_moved(swapped, moved)] == ["normal"]
    monkeypatch.setattr(fmt, "moved_draws", lambda a, b: [("normal", (7, 37), (7, 41))])
    path = tmp_path / "d.swarm"
    path.write_text(_DRAWS.replace("    velocity = rotate", "        velocity = rotate"))
    assert main(["fmt", str(path)]) == 0
    assert "formatting moves 1 random draw (`normal` 7:37 -> 7:41)" in capsys.readouterr().err
