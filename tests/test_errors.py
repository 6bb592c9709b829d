"""Every bad program in tests/data/errors gives its exact `line:col: message`, and the
CLI prints it gcc-style with a caret and exits 2."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.compiler import compile_file
from swarmdsl.compiler.errors import Span, SwarmError

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


def test_a_when_without_a_condition_is_named_at_its_arrow(tmp_path, capsys):
    """Not "comparisons cannot be chained": where a condition starts, `->` lexes as
    `-` and `>`."""
    path = tmp_path / "w.swarm"
    path.write_text("agent a { count 5; status s { when -> s } }\n")
    assert main(["check", str(path)]) == 2
    first, quoted, caret = capsys.readouterr().err.splitlines()[:3]
    assert first == f"{path}:1:36: error: `when` needs a condition before `->`"
    assert caret == " " * (len("   1 | ") + 35) + "^~"


_PROPERTY_BODY = "agent a {{ count 5; var e = 1; status s {{ e += 1 }}\n  {}\n}}\n"


@pytest.mark.parametrize("line, message", [
    ("invariant e >= 0", "2:15: unexpected `>=`: `invariant` needs a name before its "
                         "condition"),
    ("invariant pos.x > 0", "2:16: unexpected `.`: `invariant` needs a name before its "
                            "condition"),
    ("eventually e > 3 within 9", "2:16: unexpected `>`: `eventually` needs a name "
                                  "before its condition"),
    ("always e < 3 -> eventually e > 5 within 9", "2:12: unexpected `<`: `always` needs "
                                                   "a name before its condition"),
    ("invariant ok e > 0", "2:16: unexpected `e`: a `:` is missing after `invariant ok`"),
    ("eventually ok e > 0 within 3", "2:17: unexpected `e`: `within TICKS:` is missing "
                                     "after `eventually ok`"),
    # named, with `=` for `:` or no `within`: the name is there, the separator is not
    ("invariant ok = e >= 0", "2:16: unexpected `=`: a `:` follows `invariant ok`, not `=`"),
    ("eventually ok = e > 3", "2:17: unexpected `=`: `within TICKS:` follows "
                              "`eventually ok`, not `=`"),
    ("eventually ok: e > 3", "2:16: unexpected `:`: `within TICKS:` is missing after "
                             "`eventually ok`"),
    # a named property's own chained comparison is still called that
    ("invariant ok: e >= 0 >= 1", "2:24: unexpected `>=`: comparisons cannot be chained"),
])
def test_a_property_without_its_name_or_colon_says_so(line, message, assert_located_error):
    """Not "comparisons cannot be chained" for `invariant e >= 0`: the word after the
    keyword was read as the property's name, and the condition's first word as more."""
    assert_located_error(_PROPERTY_BODY.format(line), message)


def test_misspelt_status_suggests_the_right_one(capsys):
    path = next(p for p in ERRORS if p.stem == "misspelt_status")
    assert main(["run", str(path), "--headless", "--steps", "1"]) == 2
    assert "hint: did you mean 'fooded'?" in capsys.readouterr().err


# ---- misspelt keywords: named, with the keyword meant, not a list of expected tokens ----

_AGENT = "agent a {{\n  count 3\n  {}\n  status s {{ velocity = (1, 0) }}\n}}\n"
_STATUS = "agent a {{\n  count 3; var e = 0\n  status s {{\n    {}\n  }}\n}}\n"


@pytest.mark.parametrize("text, message", [
    ("agnet a { count 3; status s { } }\n", "1:1: unknown keyword `agnet`; did you mean "
                                           "`agent`?"),
    ("paramm n = 3\nagent a { count n; status s { } }\n",
     "1:1: unknown keyword `paramm`; did you mean `param`?"),
    (_AGENT.format("stauts resting { }"), "3:3: unknown keyword `stauts`; did you mean "
                                          "`status`?"),
    (_AGENT.format("fianl status done { }"), "3:3: unknown keyword `fianl`; did you mean "
                                             "`final`?"),
    (_AGENT.format("invarinat ok: speed >= 0"), "3:3: unknown keyword `invarinat`; did "
                                                "you mean `invariant`?"),
    (_STATUS.format("lett x = 3"), "4:5: unknown keyword `lett`; did you mean `let`?"),
    (_STATUS.format("wen e > 3 -> s"), "4:5: unknown keyword `wen`; did you mean `when`?"),
    (_STATUS.format("tree sequnce { e = 1 }"), "4:10: unknown keyword `sequnce`; did you "
                                               "mean `sequence`?"),
    (_STATUS.format("tree sequence {\n      fallbak { e = 1 }\n    }"),
     "5:7: unknown keyword `fallbak`; did you mean `fallback`?"),
    # inside a statement: a name where the parser expected a keyword
    ("param n = 3 ni 0..10\nagent a { count n; status s { } }\n",
     "1:13: unknown keyword `ni`; did you mean `in`?"),
    (_STATUS.format("e = if e > 1 then 1 els 2"), "4:25: unknown keyword `els`; did you "
                                                  "mean `else`?"),
    (_STATUS.format("e = if e > 1 thn 1 else 2"), "4:18: unknown keyword `thn`; did you "
                                                  "mean `then`?"),
    (_AGENT.format("invariant ok: speed > 0 adn speed < 9"),
     "3:27: unknown keyword `adn`; did you mean `and`?"),
    (_STATUS.format("tree sequence { e = 1 }\n    on sucess -> s"),
     "5:8: unknown keyword `sucess`; did you mean `success`?"),
])
def test_a_misspelt_keyword_is_named_with_the_one_meant(text, message,
                                                        assert_located_error):
    """`stauts resting {` said "unexpected `{`" and listed the tokens expected there."""
    assert_located_error(text, message)


@pytest.mark.parametrize("text", [
    _AGENT.format("potato resting { }"),        # near no keyword
    _STATUS.format("lett(x, 3)"),               # a name in use: an action, not `let`
    _STATUS.format("stauts resting { }"),       # `status` cannot start a statement here
    "world { sise 100 x 100 x }\nagent a { count 3; status s { } }\n",   # options: names
])
def test_a_word_that_is_no_keywords_typo_there_gets_no_suggestion(compile_src, text):
    with pytest.raises(SwarmError) as info:
        compile_src(text)
    assert "did you mean" not in info.value.message


_AGENT_ITEMS = {"status": "status resting { }", "var": "var e = 3", "attr": "attr e = 3",
                "final": "final status done { }", "objective": "objective o = 1",
                "invariant": "invariant ok: speed >= 0",
                "eventually": "eventually ok within 5: speed >= 0",
                "always": "always ok: speed > 1 -> eventually speed < 1 within 5",
                "metric": "metric m = mean(speed)"}
_GRAMMAR_WORDS = set(re.findall(r'"([a-z_]+)"', (Path(__file__).parents[1] / "swarmdsl" /
                                                 "grammar.lark").read_text()))


@given(st.sampled_from(sorted(_AGENT_ITEMS)), st.sampled_from(["swap", "drop", "double",
                                                               "change"]),
       st.integers(0, 20), st.sampled_from("abcdefghijklmnopqrstuvwxyz"))
def test_any_one_letter_slip_in_an_agent_keyword_is_caught(keyword, edit, at, letter):
    """Every keyword that starts an item of the agent block, with one letter swapped,
    dropped, doubled or changed, is named with a keyword one edit away from it."""
    from hypothesis import assume

    from swarmdsl.compiler.keywords import AGENT_BLOCK, closest, edit_distance
    from swarmdsl.compiler.parse import parse

    i = at % len(keyword)
    word = {"swap": keyword[:i] + keyword[i + 1:i + 2] + keyword[i:i + 1] + keyword[i + 2:],
            "drop": keyword[:i] + keyword[i + 1:],
            "double": keyword[:i] + keyword[i] + keyword[i:],
            "change": keyword[:i] + letter + keyword[i + 1:]}[edit]
    assume(word != keyword and word not in _GRAMMAR_WORDS)
    line = _AGENT_ITEMS[keyword].replace(keyword, word, 1)
    with pytest.raises(SwarmError) as info:
        parse(_AGENT.format(line), "test.swarm")
    meant = closest(word, AGENT_BLOCK)
    assert edit_distance(word, meant) <= edit_distance(word, keyword) == 1
    assert info.value.message == f"unknown keyword `{word}`; did you mean `{meant}`?"
    assert (info.value.span.line, info.value.span.col) == (3, 3)


_PROGRAMS = sorted((Path(__file__).parents[1] / "programs").rglob("*.swarm"))
_INNER_KEYWORDS = r"\b(then|else|and|or|within|in|where)\b"   # `at` names messages too


def _keyword_sites() -> list[tuple[Path, int, str]]:
    """(program, offset, keyword) of every keyword inside a statement of the shipped
    programs, outside comments and strings."""
    sites = []
    for path in _PROGRAMS:
        text = path.read_text()
        for m in re.finditer(_INNER_KEYWORDS, text):
            line = text[text.rfind("\n", 0, m.start()) + 1:m.start()]
            # `place in home`: an option's words are names to the parser (the checker
            # names a misspelt `in` there: unknown name)
            if ("#" not in line and line.count('"') % 2 == 0
                    and not re.fullmatch(r"\s*place\s+", line)):
                sites.append((path, m.start(), m[1]))
    return sites


@given(st.sampled_from(_keyword_sites()), st.integers(0, 10))
def test_a_slip_in_any_keyword_inside_a_shipped_program_is_named(site, at):
    """Every keyword inside a statement of every shipped program (`then`, `else`, `and`,
    `or`, `within`, `in`, `where`), with two neighbouring letters swapped, is
    named where it stands with a keyword as near as the one meant."""
    from swarmdsl.compiler.keywords import edit_distance
    from swarmdsl.compiler.parse import parse

    path, start, keyword = site
    i = at % (len(keyword) - 1)
    word = keyword[:i] + keyword[i + 1] + keyword[i] + keyword[i + 2:]
    text = path.read_text()
    text = text[:start] + word + text[start + len(keyword):]
    with pytest.raises(SwarmError) as info:
        parse(text, "p.swarm")
    m = re.fullmatch(r"unknown keyword `(\w+)`; did you mean `(\w+)`\?", info.value.message)
    assert m and m[1] == word, info.value.message
    assert edit_distance(word, m[2]) <= edit_distance(word, keyword) == 1
    line = text.count("\n", 0, start) + 1
    assert (info.value.span.line, info.value.span.col) == (
        line, start - text.rfind("\n", 0, start))


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


# ---- what `check` refuses before a run: the same located error `run` would give ----

CHECKED_BEFORE_RUN = ["max_speed_negative", "max_speed_negative_param", "world_option_twice",
                      "place_outside_world", "place_in_region_outside_world",
                      "bool_param_range", "keyword_as_name"]


@pytest.mark.parametrize("stem", CHECKED_BEFORE_RUN)
def test_check_exits_2_with_the_caret_under_the_mistake(stem, capsys):
    path = next(p for p in ERRORS if p.stem == stem)
    line, col, message = _expectation(path)
    assert main(["check", str(path)]) == 2
    first, quoted, caret = capsys.readouterr().err.splitlines()[:3]
    assert first == f"{path}:{line}:{col}: error: {message}"
    assert caret.index("^") == len(f"{line:>4} | ") + col - 1


def test_negative_max_speed_from_set_is_refused_before_the_run(tmp_path, capsys):
    path = tmp_path / "m.swarm"
    path.write_text("param m = 1\nagent a { count 3; max_speed m; status s { } }\n")
    out = tmp_path / "out"
    assert main(["run", str(path), "--headless", "--steps", "2", "--set", "m=-1",
                 "--out", str(out)]) == 2
    assert f"{path}:2:30: error: the max_speed of `a` must be 0 or more, got -1" \
        in capsys.readouterr().err
    assert not out.exists()   # refused before anything is created
    assert main(["check", str(path)]) == 0


def test_max_speed_known_only_per_agent_is_still_refused_at_run_time(backend, compile_src):
    from swarmdsl.runtime.simulation import Simulation

    prog = compile_src("agent a { count 3; max_speed 1 - index; status s { } }")
    with pytest.raises(SwarmError, match="the max_speed of `a` must be 0 or more, got -1"):
        Simulation(prog, 0)


def test_world_options_are_set_once_but_refine_repeats(compile_src, assert_located_error):
    assert_located_error("world {\n  steps 5\n  grid 5\n  steps 6\n}\n"
                         "agent a { count 1; status s { } }",
                         "4:3: option `steps` is already set for the world")
    prog = compile_src("world { refine rect(0, 0, 20, 20) 1; refine rect(50, 50, 70, 70) 1 }\n"
                       "field f { }\nagent a { count 1; status s { } }")
    assert prog.world.width == 100


@pytest.mark.parametrize(("text", "where", "word"), [
    ("param if = 3\nagent a { count 3; status s { } }", "1:7", "if"),
    ("agent a { count 3; var on = false; status s { } }", "1:24", "on"),
    ("agent a { count 3; attr not = 1; status s { } }", "1:25", "not"),
    ("agent a { count 3; status true { } }", "1:27", "true"),
    ("agent when { count 3; status s { } }", "1:7", "when"),
    ("agent a { count 3; status s { let where = 2; velocity = (where, 0) } }", "1:35",
     "where"),
    ("field then { }\nagent a { count 3; status s { } }", "1:7", "then"),
    ("nest in = circle(5, 5, 5)\nagent a { count 3; status s { } }", "1:6", "in"),
    ("tree t(x, else) { sequence { } }\nagent a { count 3; status s { } }", "1:11", "else"),
])
def test_a_keyword_cannot_be_declared_as_a_name(text, where, word, assert_located_error):
    assert_located_error(text, f"{where}: `{word}` is a keyword and cannot be used as a name")


def test_soft_keywords_stay_usable_names(compile_src):
    # words that are keywords only inside trees or between two expressions
    prog = compile_src("agent a {\n  count 2\n  var at = 1\n  var running = 0\n"
                       "  status success { at += 1; running = at; when running > 5 -> failure }\n"
                       "  status failure { }\n}\n")
    assert [k.name for k in prog.kinds] == ["a"]


# ---- line ends: LF, CRLF and a lone CR all end a line, in positions and quotes ----

BAD_LINE_3 = ["param n = 3", "# a comment", "agent a { count n; status s { x } }", ""]


@pytest.mark.parametrize("newline", ["\n", "\r\n", "\r"], ids=["lf", "crlf", "cr"])
def test_line_ends_give_the_same_position_and_quoted_line(tmp_path, capsys, newline):
    path = tmp_path / "e.swarm"
    path.write_bytes(newline.join(BAD_LINE_3).encode())
    assert main(["check", str(path)]) == 2
    first, quoted, caret = capsys.readouterr().err.splitlines()[:3]
    assert first == f"{path}:3:33: error: unexpected `}}`"
    assert quoted == "   3 | agent a { count n; status s { x } }"
    assert caret.index("^") == quoted.index("}", 36)


@pytest.mark.parametrize("newline", ["\r\n", "\r"], ids=["crlf", "cr"])
def test_a_valid_program_checks_whatever_its_line_ends(tmp_path, capsys, newline):
    path = tmp_path / "ok.swarm"
    path.write_bytes(newline.join(["param n = 3", "agent a {", "  count n",
                                   "  status s { }", "}", ""]).encode())
    assert main(["check", str(path)]) == 0
    assert "ok (1 agent kind" in capsys.readouterr().out


def test_a_form_feed_in_a_comment_does_not_shift_the_quoted_line(compile_src):
    text = "# a page break \f here\nparam n = 3\nagent a { count n; status s { x } }\n"
    with pytest.raises(SwarmError) as info:
        compile_src(text)
    rendered = info.value.render()
    assert "test.swarm:3:33: error" in rendered
    assert "   3 | agent a { count n; status s { x } }" in rendered


def test_a_byte_that_is_not_utf8_after_a_lone_cr_is_located(tmp_path, capsys):
    path = tmp_path / "latin.swarm"
    path.write_bytes(b"param n = 3\ragent a { count n; status caf\xe9 { } }\r")
    assert main(["check", str(path)]) == 2
    assert f"{path}:2:30: error: the file is not UTF-8 text" in capsys.readouterr().err


@pytest.mark.parametrize(("expr", "first"), [
    ("count(zz)", "unknown name `zz`"),
    ("mean(zz else 1)", "unknown name `zz`"),
    ("sum(neighbors(5) : count(neighbors(3)))",
     "neighbour queries cannot be nested inside another one"),
])
def test_an_aggregate_over_a_broken_argument_adds_no_second_error(expr, first, compile_src):
    """The argument's own error is the whole story: no "needs a neighbour set, got
    error" naming the checker's internal type after it."""
    src = f"agent a {{ count 2; var v = 0; status s {{ v = {expr} }} }}\n"
    with pytest.raises(SwarmError) as info:
        compile_src(src)
    messages = [d.message for d in info.value.diagnostics]
    assert messages == [first]


@pytest.mark.parametrize(("value", "message"), [
    ("sqrt(-1)", "1:11: cannot compute a param's value: sqrt(-1) is not a real number"),
    ("log(0)", "1:11: cannot compute a param's value: log(0) is minus infinity"),
    ("exp(1000)", "1:11: cannot compute a param's value: exp(1000) is too large"),
    ("5 % 0", "1:11: cannot compute a param's value: 5 % 0: the remainder of a division"),
    ("sqrt(2, 3)", "1:11: cannot compute a param's value: `sqrt` takes 1 argument, got 2"),
    ("acos(0.5)", "1:11: unknown function `acos`"),
    ("q + 1", "1:11: param `q` (line 2) is not known yet here"),
    ("p * 2", "1:11: param `p` cannot use its own value"),
])
def test_a_param_that_cannot_be_computed_says_why_in_the_language(value, message,
                                                                   assert_located_error):
    """Not Python's "math domain error" or "math.sqrt() takes exactly one argument",
    and not "must be a constant" for a misspelt function or a param declared later."""
    assert_located_error(f"param p = {value}\nparam q = 2\n"
                         "agent a { count 1; status s { } }\n", message)


def test_pure_functions_of_constants_are_constants(compile_src):
    """`clamp` and `sign` fold like `sqrt` and `min`, with the runtime's values."""
    prog = compile_src("param p = clamp(7, 0, 5) + sign(-3)\n"
                       "agent a { count clamp(p, 1, 3); status s { } }\n")
    assert prog.params["p"] == 4


def test_a_range_written_high_to_low_is_called_empty_at_the_range(assert_located_error):
    """Not "p = 2 lies outside its range 5..0", which reads as if 2 were the mistake."""
    assert_located_error("param p = 2 in 5..0\nagent a { count 1; status s { } }\n",
                         "1:16: the range 5..0 of param `p` is empty: its low end is above "
                         "its high end")


@pytest.mark.parametrize(("target", "message"), [
    ("tick", "`tick` is a built-in value and cannot be assigned"),
    ("pi", "`pi` is a built-in value and cannot be assigned"),
    ("dist", "`dist` is a built-in value and cannot be assigned"),
    ("heat", "`heat` is a field and cannot be assigned"),
    ("home", "`home` is a region and cannot be assigned"),
])
def test_assigning_a_name_that_is_not_a_variable_says_what_it_is(target, message,
                                                                 assert_located_error):
    """Not "unknown variable `tick`": the name is known, it just cannot change."""
    assert_located_error("field heat { }\nregion home = circle(5, 5, 1)\n"
                         f"agent a {{ count 2; status s {{ {target} = 1 }} }}\n",
                         f"3:31: {message}")


@pytest.mark.parametrize(("statement", "at", "hint"), [
    ("v.y = 1", ".", "a component cannot be assigned alone; set the whole vector: "
                     "`v = (v.x, Y)`"),
    ("velocity.x = 1", ".", "a component cannot be assigned alone; set the whole vector: "
                            "`velocity = (X, velocity.y)`"),
    ("e++", "+", "write `e += 1`"),
    ("e = 1 if e > 0 else 2", "if", "a choice is written `if CONDITION then A else B`"),
    ("if e > 1 { e = 0 }", "e", "`if` chooses a value (`x = if C then A else B`); to act "
                                "when a condition holds, use `when C -> STATUS` or a `tree`"),
    ("v = [1, 0]", "[", "a vector is written `(x, y)`"),
])
def test_habits_of_other_languages_get_a_hint_in_this_one(statement, at, hint, tmp_path,
                                                          capsys):
    path = tmp_path / "h.swarm"
    head = "agent a { count 2; var e = 0; var v = (0, 0); status s { "
    path.write_text(f"{head}{statement} }} }}\n")
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    col = len(head) + statement.index(at) + 1
    assert f"{path}:1:{col}: error: unexpected " in err
    assert f"  hint: {hint}\n" in err


# ---- the caret counts terminal cells: combining marks take none, wide characters two ----

GUTTER = len("   1 | ")


@pytest.mark.parametrize(("line", "message", "cells", "run"), [
    # `e` + U+0301 draws one cell, `é`: the error at the mark points at it
    ("agent a { count 1; status s { velocity = (1, e\u0301) } }",
     "1:47: error: unexpected character U+0301 (COMBINING ACUTE ACCENT)", 45, "^"),
    # a combining mark earlier in the line takes no cell before the mistake
    ("agent a { count 1; status s { let q = \"e\u0301\u0323\"; bogus = 1 } }",
     "1:46: error: unknown variable `bogus`", 43, "^~~~~"),
    # two wide characters take four cells before the mistake
    ("agent a { count 1; status s { let q = \"\u6f22\u5b57\"; bogus = 1 } }",
     "1:45: error: unknown variable `bogus`", 46, "^~~~~"),
    # a wide character is the mistake: the caret covers both its cells
    ("agent a { count 1; status s { x = \u6f22 } }",
     "1:35: error: unexpected character '\u6f22'", 34, "^~"),
])
def test_the_caret_lands_under_the_character_whatever_its_width(line, message, cells, run,
                                                                tmp_path, capsys):
    path = tmp_path / "u.swarm"
    path.write_text(line + "\n", encoding="utf-8")
    assert main(["check", str(path)]) == 2
    first, quoted, caret = capsys.readouterr().err.splitlines()[:3]
    assert first == f"{path}:{message}"
    assert quoted == "   1 | " + line
    assert caret == " " * (GUTTER + cells) + run


# Characters with the cells a terminal gives them, written out rather than asked of
# unicodedata, so the test does not repeat the renderer's own rule.
NARROW = "abz_(=; 1é#"
WIDE = "\u6f22\u5b57\u3042\ud55c\uff21\u4e00"   # CJK, kana, hangul, full-width A
MARKS = "\u0301\u0300\u0323\u0308\u20dd\u200d"   # combining marks, enclosing, ZWJ

_cluster = st.tuples(st.sampled_from(NARROW + WIDE),
                     st.text(st.sampled_from(MARKS), max_size=2)).map(lambda t: t[0] + t[1])


@given(clusters=st.lists(_cluster, min_size=1, max_size=30), data=st.data())
def test_the_caret_starts_at_the_cell_of_the_spanned_character(clusters, data):
    """For any mix of narrow, wide and combining characters, a span on one character
    (or on one of the marks drawn on it) gets a caret under that character's cells."""
    target = data.draw(st.integers(0, len(clusters) - 1))
    inside = data.draw(st.integers(0, len(clusters[target]) - 1))  # 0: the base char
    line = "".join(clusters)
    col = sum(len(c) for c in clusters[:target]) + inside + 1
    end = col + (len(clusters[target]) - inside if inside == 0 else 1)
    rendered = SwarmError("m", Span("f", 1, col, 1, end)).render(line + "\n")
    caret = rendered.splitlines()[2]
    cells = [2 if c[0] in WIDE else 1 for c in clusters]
    assert caret == " " * (GUTTER + sum(cells[:target])) + "^" + "~" * (cells[target] - 1)


def test_a_check_error_survives_pickling_with_every_diagnostic(compile_src):
    """Raised in another process (a user's own process pool) it arrives whole: every
    diagnostic, each with its place and the quoted line."""
    import pickle

    with pytest.raises(SwarmError) as err:
        compile_src("agent a {\n  count 3\n  status s { x = 1\n y = 2 }\n}\n")
    again = pickle.loads(pickle.dumps(err.value))
    assert type(again) is type(err.value)
    assert again.render() == err.value.render()
    assert len(again.diagnostics) == 2 and "3:14" in again.render()


def test_a_fault_inside_a_statement_names_its_line(backend):
    """`cone(visited, inf, 0.5)` passed `check` and faulted with no line at all (a
    constant `inf` is now refused at check: here the distance is infinite per agent)."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.compiler.errors import SwarmRuntimeError
    from swarmdsl.runtime.simulation import Simulation

    src = ("world { size 100 x 100 }\nfield visited { decay 0.1 }\n"
           "agent a {\n  count 3\n  status s {\n    velocity = (1, 0)\n"
           "    when cone(visited, speed + inf, 0.5) < 1 -> s\n  }\n}\n")
    sim = Simulation(compile_source(src, "c.swarm"), seed=0, backend=backend)
    with pytest.raises(SwarmRuntimeError) as info:
        sim.step()
    err = info.value
    assert (err.span.line, err.span.col) == (7, 5)
    assert err.message == ("status `s` of `a` failed at tick 0: positions must be finite "
                           "(got NaN or infinity)")


@pytest.mark.parametrize("size", ["(a + 10) x (a * 2)", "40 x (a * 2)", "(a + 10) x 20"])
def test_a_bracketed_world_height_is_not_a_call_of_x(size):
    """`size 40 x (a * 2)` read `x (a * 2)` as a call: "unknown function `x`"."""
    from swarmdsl.compiler import compile_source

    prog = compile_source(f"param a = 10\nworld {{ size {size} }}\n"
                          "agent b { count 1; status s { } }\n", "s.swarm")
    assert (prog.world.width, prog.world.height) == {
        "(a + 10) x (a * 2)": (20, 20), "40 x (a * 2)": (40, 20),
        "(a + 10) x 20": (20, 20)}[size]


def test_a_region_wholly_outside_the_world_is_warned_about_where_declared():
    from swarmdsl.compiler import compile_source

    prog = compile_source("food f = circle(500, 500, 5)\nnest n = circle(50, 50, 5)\n"
                          "agent a { count 3; status s { when inside(f) -> s } }\n", "r.swarm")
    warns = [w for w in prog.info.warnings if "outside" in w.message]
    assert [(w.span.line, w.span.col, w.message) for w in warns] == [
        (1, 6, "food `f` lies wholly outside the world (100 x 100): no agent can ever "
               "stand in it")]


def test_a_robot_that_loses_every_message_is_warned_about():
    from swarmdsl.compiler import compile_source

    prog = compile_source("robot radio { like kilobot; loss 1 }\n"
                          "agent a { count 3; robot radio; status s { } }\n", "l.swarm")
    [w] = prog.info.warnings
    assert (w.span.line, w.span.col) == (1, 29)
    assert w.message == "a loss of 1 loses every message: no robot of this profile hears " \
                        "anything"


def test_a_fault_while_placing_names_the_initial_value_it_came_from(backend):
    """A kernel fault in an initial value said only "placing agents of `a` failed"."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.compiler.errors import SwarmRuntimeError
    from swarmdsl.runtime.simulation import Simulation

    from swarmdsl.compiler.lowering import REFERENCE

    # compiled with its lowering fixed, so a numba run does not compile it again (which
    # would drop the broken closure put in below)
    prog = compile_source("agent a {\n  count 3\n  var u = 1\n  var w = u + 1\n"
                          "  status s { }\n}\n", "p.swarm", lowering=REFERENCE)
    kind = prog.kinds[0]

    def broken(f):
        raise ValueError("a kernel fault")
    kind.vars[1] = (*kind.vars[1][:2], broken)
    with pytest.raises(SwarmRuntimeError) as info:
        Simulation(prog, seed=0, backend=backend)
    err = info.value
    assert err.message == "placing agents of `a` failed: a kernel fault"
    assert (err.span.line, err.span.col) == (4, 3)


@pytest.mark.parametrize("call, hinted", [
    ("mean(near, other.vel)", True),   # a comma where the `:` goes
    ("sum(near, near)", True),
    ("count(near, near)", False),      # nothing to aggregate: no `:` to suggest
])
def test_an_aggregate_given_a_comma_for_its_colon_says_where_the_colon_goes(call, hinted):
    from swarmdsl.compiler import compile_source

    text = ("agent a {\n  count 3\n  status s {\n    let near = neighbors(5)\n"
            f"    let v = {call}\n  }}\n}}\n")
    with pytest.raises(SwarmError) as err:
        compile_source(text, "test.swarm")
    said = str(err.value)
    name = call.split("(")[0]
    assert f"test.swarm:5:13: error: `{name}` takes one neighbour set" in said
    assert (f"`{name}(SET : EXPR)`" in (err.value.hint or "")) == hinted


@pytest.mark.parametrize("where, text", [
    ("9:10", "agent a {{ count 3; status s {{\n\n\n\n\n\n\n\n    when {} > 3 -> s\n}} }}\n"),
    ("1:25", "field heat {{ twin exp(-({} - 50) ^ 2) }}\nagent a {{ count 3; status s {{ }} }}\n"),
])
@pytest.mark.parametrize("name, meant", [("x", "pos.x"), ("y", "pos.y"),
                                         ("vx", "velocity.x"), ("vy", "velocity.y")])
def test_a_component_written_as_a_column_name_points_at_the_vector(where, text, name, meant):
    """`x` is a column of agents.parquet, not a name in a program: the hint says what
    to write, in a status and in a twin's formula alike."""
    from swarmdsl.compiler import compile_source

    with pytest.raises(SwarmError) as err:
        compile_source(text.format(name), "test.swarm")
    assert f"test.swarm:{where}: error: unknown name `{name}`" in str(err.value)
    assert f"write `{meant}`" in err.value.hint


@pytest.mark.parametrize("stmt, call", [
    ("tree sequence { speed > 1; wait 3 }", "wait(3)"),       # a tree's long action
    ("v = sqrt 4", "sqrt(4)"),                                # a function
    ("v = count near", "count(near)"),                        # an aggregate
])
def test_a_call_written_without_brackets_gets_them_in_the_hint(stmt, call):
    from swarmdsl.compiler import compile_source

    text = ("agent a {\n  count 3\n  var v = 0\n  status s {\n    let near = "
            f"neighbors(5)\n    {stmt}\n  }}\n}}\n")
    with pytest.raises(SwarmError) as err:
        compile_source(text, "test.swarm")
    assert "test.swarm:6:" in str(err.value)
    name = call.split("(")[0]
    assert err.value.hint == f"`{name}` takes its arguments in brackets: `{call}`"
