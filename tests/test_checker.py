"""The checker's diagnostics for the mistakes a first-time user of the language makes
(docs/language*.md): each reported once, where it was made, in the user's words."""

from __future__ import annotations

import numpy as np
import pytest

from swarmdsl.compiler.errors import SwarmError


def _errors(compile_src, text: str) -> list[str]:
    """Every error the checker reports for `text`, as `line:col: message`."""
    with pytest.raises(SwarmError) as err:
        compile_src(text)
    found = getattr(err.value, "diagnostics", [err.value])
    return [f"{d.span.line}:{d.span.col}: {d.message}" for d in found]


_STATUS_USING = {
    "map seen 10 0": "note(seen, 1); v = recall(seen)",
    "memory trail 0": "remember(trail); v = len(trail)",
    "memory trail 5; memory path 5": "v = len(trail) + len(path)",
    "message x": "broadcast(x, 1); v = max(heard() : msg.x)",
}


@pytest.mark.parametrize("option", list(_STATUS_USING))
def test_a_refused_kind_declaration_is_the_only_error(compile_src, option):
    """A map, memory or message line that is refused used to be followed by an
    "unknown name" (or "not in the message") error at every use of what it declared,
    hinting `speed` for `seen`: one mistake read as several."""
    text = (f"agent a {{ count 3; {option}; var v = 0\n"
            f"  status s {{ {_STATUS_USING[option]} }} }}\n")
    errors = _errors(compile_src, text)
    assert len(errors) == 1, errors
    assert errors[0].startswith("1:")


@pytest.mark.parametrize("shape", ["circle(50, 50, -5)", "rect(60, 60, 10, 10)",
                                   "circle(50, 50)", "square(1, 2, 3)"])
def test_a_refused_region_is_the_only_error(compile_src, shape):
    """A region whose shape is refused is not also an unknown name where it is used."""
    text = (f"world {{ size 100 x 100 }}\nregion z = {shape}\n"
            "agent a { count 3; var b = false; status s { b = inside(z) } }\n")
    assert [e[:4] for e in _errors(compile_src, text)] == ["2:12"]


def test_a_misspelt_name_is_still_unknown_beside_a_refused_map(compile_src):
    """Only the refused declaration's own name is spared its "unknown name"."""
    text = "agent a { count 3; map seen 10 0; var v = 0\n  status s { v = recall(sen) } }\n"
    assert _errors(compile_src, text)[1] == "2:25: unknown name `sen`"


def test_a_negative_second_value_of_an_option_is_a_value(compile_src):
    """`origin 10 -20` (a believed origin below the world) was read as `origin 10 - 20`,
    one value, and refused: "`origin` takes x and y"."""
    prog = compile_src("world { size 100 x 100; origin 10 -20 }\n"
                       "agent a { count 3; status s { } }\n")
    assert prog.info.extra["origin"] == (10.0, -20.0)


@pytest.mark.parametrize("line, message", [
    # was `edges repel (1 - 2)`: "the edge repulsion weight must be at least 0, got -1"
    ("world { edges repel 1 -2 }", "1:23: the edge repulsion range must be positive, got -2"),
    # was `map seen (-10) 10` read as `map (seen - 10) 10`, then every use unknown
    ("world { }\nagent b { count 1; map seen -10 10; status s { } }",
     "2:29: the map's cell size must be positive, got -10"),
    ("world { size 100 x -50 }", "1:20: the world's height must be positive, got -50"),
])
def test_a_negative_option_value_is_named_at_itself(compile_src, line, message):
    assert _errors(compile_src, line + "\nagent a { count 3; status s { } }\n") == [message]


@pytest.mark.parametrize("line, origin", [
    ("origin 10 - 20 5", (-10.0, 5.0)),   # spaced both sides: a subtraction
    ("origin 10-20 5", (-10.0, 5.0)),
    ("origin (10 -20) 5", (-10.0, 5.0)),  # inside brackets: a subtraction
    ("origin -10 -20 + 5", (-10.0, -15.0)),
])
def test_a_subtraction_in_an_option_stays_one(compile_src, line, origin):
    prog = compile_src(f"world {{ {line} }}\nagent a {{ count 3; status s {{ }} }}\n")
    assert prog.info.extra["origin"] == origin


def test_an_option_given_a_signed_extra_value_says_how_to_subtract(compile_src):
    with pytest.raises(SwarmError) as err:
        compile_src("world { steps 50 -1 }\nagent a { count 3; status s { } }\n")
    assert err.value.message == "`steps` takes 1 value: `steps N`"
    assert "write `n - 1` to subtract" in err.value.hint


@pytest.mark.parametrize("option, message", [
    ("range 0", "1:31: `range` must be a number above 0, got 0"),
    ("comm_range 0", "1:36: `comm_range` must be a number above 0, got 0"),
])
def test_a_robot_that_senses_or_hears_nothing_is_refused(assert_located_error, option,
                                                         message):
    """`range 0` was accepted silently: a robot blind to every neighbour and field
    point, when the user most likely meant "no limit" (leave `range` out)."""
    assert_located_error(f"robot r {{ like kilobot; {option} }}\n"
                         "agent a { robot r; count 5; status s { } }\n", message)


def _body(statement: str) -> str:
    return ("agent a { count 3; var v = 0; var b = false\n"
            f"  status s {{ {statement}; b = v > 0 }} }}\n")


@pytest.mark.parametrize("statement, message", [
    ("v = 5 / 0", "2:18: cannot compute this constant: division by zero"),
    ("v = 1 + log(-1) * 2", "2:22: cannot compute this constant: log(-1) is not a real "
                            "number"),
    ("v = normal(0 / 0, 1)", "2:25: cannot compute this constant: division by zero"),
    ("v /= 0", "2:19: `/= 0` divides by zero"),
    ("when v > sqrt(-1) -> s", "2:23: cannot compute this constant: sqrt(-1) is not a "
                               "real number"),
])
def test_a_constant_that_cannot_be_computed_is_a_check_error(assert_located_error,
                                                             statement, message):
    """`swarmdsl check` said "ok" and the run faulted at its first tick; the docs
    promise constant draw arguments (`normal(0 / 0, 1)`) are checked before the run."""
    assert_located_error(_body(statement), message)


def test_a_field_formula_that_cannot_be_computed_is_named_at_itself(assert_located_error):
    """The run said "the initial value of field `f` is not finite at some node" at the
    field's name."""
    assert_located_error("world { }\nfield f { initial 1 / 0 }\n"
                         "agent a { count 3; status s { deposit(f, 1) } }\n",
                         "2:19: cannot compute this constant: division by zero")


@pytest.mark.parametrize("statement, v", [
    ("v = if 0 > 0 then 10 / 0 else 0", 0.0),        # the side no agent takes
    ("b = false and log(-1) > 0", 0.0),
    ("v = count(neighbors(5) where 1 / 0 > dist)", None),   # each pair's own business
])
def test_a_constant_fault_on_a_side_not_taken_is_no_error(run_src, statement, v):
    """Checked and run: the side that would fault is never computed."""
    got = run_src(_body(statement), steps=2).agents.cols["v"]
    assert np.isfinite(got).all()
    if v is not None:
        assert (got == v).all()


def test_a_constant_fault_is_reported_once(compile_src):
    """A param's value is already "cannot compute a param's value"; a velocity already
    names `velocity`: neither is said twice."""
    errors = _errors(compile_src, "param p = 1 / 0\n"
                                  "agent a { count 3; velocity (1 / 0, 0); status s { } }\n")
    assert [e[:5] for e in errors] == ["1:11:", "2:29:"]


def test_a_refused_param_is_the_only_error(compile_src):
    """`param w = (1, 2)` was then 0 everywhere it was used: "the world's width must be
    positive, got 0", "`+=` needs a number on the right, got a vector", ..."""
    errors = _errors(compile_src, "param w = (1, 2)\nparam r = 1 / 0\n"
                                  "world { size w x 100; grid r }\n"
                                  "agent a { count 3; sense r; var v = w\n"
                                  "  status s { v += (1, 1) } }\n")
    assert [e[:4] for e in errors] == ["1:11", "2:11"]


@pytest.mark.parametrize("call, message", [
    ("velocity = approach(goal, -2)", "4:38: the speed of `approach` must be 0 or more, "
                                      "got -2"),
    ("b = arrived(goal, -1)", "4:30: the reach of `arrived` must be 0 or more, got -1"),
    ("b = touching(z, -1)", "4:28: the reach of `touching` must be 0 or more, got -1"),
    ("b = at_edge(-2)", "4:24: the margin of `at_edge` must be 0 or more, got -2"),
    ("tree move_to((50, 50), -1)", "4:35: the tolerance of `move_to` must be 0 or more, "
                                   "got -1"),
    ("tree move_to((50, 50), 1, -2)", "4:38: the speed of `move_to` must be 0 or more, "
                                      "got -2"),
])
def test_a_negative_speed_or_reach_is_refused(assert_located_error, call, message):
    """`approach(goal, -2)` walked agents away from their goal and `arrived(goal, -1)`
    or `touching(z, -1)` was never true, both accepted silently."""
    assert_located_error("world { }\nregion z = circle(50, 50, 5)\n"
                         "agent a { count 3; objective goal = (50, 50); var b = false\n"
                         f"status s {{ {call}; b = not b }} }}\n", message)


@pytest.mark.parametrize("node, message", [
    # was "unexpected `v`" with a list of tokens
    ("sequence { when v > 0 -> t }", "2:30: a `when` cannot go inside a tree"),
    ("sequence { let q = 1 }", "2:30: a `let` cannot go inside a tree"),
    # was "unexpected `sequence`", expecting `succeeded`, `failed` or `running`
    ("sequence { tree fallback { v > 0 } }", "2:30: a status has one `tree`; inside it, "
                                             "nodes are written without `tree`"),
    ("repeat -1 v += 1", "2:26: unexpected `-`: a count after `repeat` that is not a "
                         "number or a name takes brackets"),
])
def test_a_statement_inside_a_tree_is_named(assert_located_error, node, message):
    assert_located_error("agent a { count 3; var v = 0\n"
                         f"  status s {{ tree {node} }}\n  status t {{ }} }}\n", message)


@pytest.mark.parametrize("text, col, hint", [
    ("param é = 2\n", 7, "names are ASCII letters, digits and `_`"),
    ("param 漢字 = 2\n", 7, "names are ASCII letters, digits and `_`"),
    ("param p = 'a'\n", 11, 'a string is written in double quotes: "models/net.pt"'),
])
def test_a_character_a_name_or_string_cannot_hold_says_what_can(compile_src, text, col,
                                                                 hint):
    """The docs said names are "letters": `é` is one, and was refused with no hint."""
    with pytest.raises(SwarmError) as err:
        compile_src(text + "agent a { count 3; status s { } }\n")
    assert err.value.message.startswith("unexpected character")
    assert (err.value.span.line, err.value.span.col, err.value.hint) == (1, col, hint)


@pytest.mark.parametrize("vars_, message", [
    ("var e = f; var f = 1", "1:28: variable `f` (line 1) is not known yet here: an "
                             "initial value may use only the variables declared before it"),
    ("var e = e + 1", "1:28: variable `e` cannot use its own value"),
])
def test_a_variable_read_before_it_is_declared_says_so(assert_located_error, vars_,
                                                       message):
    """It was "unknown name `f`", though `f` is declared on the same line; a param in
    the same place already got this message."""
    assert_located_error(f"agent a {{ count 3; {vars_}; status s {{ e += 1 }} }}\n", message)


def test_a_constant_max_speed_inf_says_to_leave_it_out(compile_src, run_src):
    """docs/language.md said "`max_speed` may be `inf`: no limit", and `max_speed inf`
    was refused with only "see the limits". Per agent it is no limit; as a constant the
    way to say so is to leave `max_speed` out."""
    with pytest.raises(SwarmError) as err:
        compile_src("agent a { count 1; max_speed inf; status s { } }\n")
    assert err.value.hint == "leave `max_speed` out for no speed limit"
    sim = run_src("world { size 100 x 100 }\n"
                  "agent a { count 1; place (10, 50); velocity (30, 0)\n"
                  "  max_speed if index == 0 then inf else 2; status s { } }\n")
    assert sim.agents.cols["pos"][0].tolist() == [40.0, 50.0]


@pytest.mark.parametrize("statement, col, message, hint", [
    ("when v > 0 => t", 12, "unexpected `=`", "a transition is written `->`"),  # was `==`
    ("v = if v > 0 then 1", 20, "unexpected new line: expected `else`", None),  # `_else`
    ("v == 1", 4, "unexpected `=`", "`==` compares; a statement assigns with `=`, e.g. "
                                    "`v = 1`"),
    ("b = v > 0 && b", 11, "unexpected character '&'", "conditions are joined with `and`"),
    ("b = v > 0 || b", 11, "unexpected character '|'", "conditions are joined with `or`"),
    ("b = !b", 5, "unexpected character '!'", "a condition is negated with `not`; `!=` "
                                              "compares"),
    ("v = b ? 1 : 2", 7, "unexpected character '?'", "a choice is written `if CONDITION "
                                                     "then A else B`"),
    ("v = v**2", 7, "unexpected `*`", "`^` raises to a power: `x ^ 2`"),
    ("var q = 1", 1, "a `var` is declared in the agent block, not in a status",
     "declare it beside `count`, or bind a value of this tick with `let`"),
    ("status u { }", 1, "a `status` cannot go inside a status",
     "is a `}` missing above it?"),
    # was "a `invariant` cannot go inside a status"
    ("invariant ok: v > 0", 1, "an `invariant` is declared in the agent block or at top "
     "level, not in a status", "declare it beside `count` (about each agent), or at top "
     "level (about the swarm)"),
    ("metric m = v", 1, "a `metric` is declared in the agent block or at top level, not "
     "in a status", "declare it beside `count`, or at top level"),
])
def test_another_language_habit_gets_this_languages_form(compile_src, statement, col,
                                                         message, hint):
    """What a user of Python, C or JavaScript types first; each was a bare "unexpected"
    with a list of tokens, or a wrong hint (`=>` was told "use `==` to compare")."""
    with pytest.raises(SwarmError) as err:
        compile_src("agent a { count 3; var v = 0; var b = false\nstatus s {\n"
                    f"{statement}\n}}\nstatus t {{ }} }}\n")
    got = err.value
    assert (got.span.line, got.span.col, got.message, got.hint) == (3, col, message, hint)


def test_an_unquoted_model_path_is_one_error(compile_src):
    """`nn(models/spring1d.pt, ...)` was also "unknown name `models`" and "unknown name
    `spring1d`" around the real mistake."""
    errors = _errors(compile_src, "agent a { count 3; var v = 0\n"
                                  "  status s { v = nn(models/spring1d.pt, 1, 2) } }\n")
    assert errors == ["2:21: the first argument of `nn` must be a string literal naming "
                      "the model file"]


def test_a_name_declared_as_two_things_is_one_error(compile_src):
    """`field f` and `agent f`: every `deposit(f, 1)` also said "`deposit` needs a field
    here, got an agent kind" (the kind won the name)."""
    errors = _errors(compile_src, "world { }\nfield f { }\nagent f { count 3; var v = 0\n"
                                  "  status s { deposit(f, 1); v = sample(f) } }\n")
    assert errors == ["3:7: `f` is already declared as a field (line 2)"]


@pytest.mark.parametrize("shape, message", [
    ("rect(200, 200, 300, 300) 2", "1:41: this refined region lies outside the world (0, 0) "
                                   "to (100, 100): it would refine no cell"),
    ("circle(50, 50, 0)", "1:41: this refined region has no area: it would refine no "
                          "cell"),
])
def test_a_refinement_that_refines_nothing_is_refused(assert_located_error, shape,
                                                      message):
    """It was accepted silently: the grid stayed as coarse as without it."""
    assert_located_error(f"world {{ size 100 x 100; grid 10; refine {shape} }}\n"
                         "field f { }\nagent a { count 3; status s { deposit(f, 1) } }\n",
                         message)


def test_clamp_bounds_the_wrong_way_round_are_refused(assert_located_error):
    """`clamp(v, 3, 1)` gave 1 whatever `v` was, silently."""
    assert_located_error("agent a { count 3; var v = 0\n  status s { v = clamp(v + 1, 3, 1) } }\n",
                         "2:18: `clamp(x, lo, hi)` needs lo <= hi, got lo = 3 and hi = 1")


@pytest.mark.parametrize("text, message", [
    ("agent a { count 3; var v = 0; status s { v = tired + 1 }\n"
     "  metric tired = count(v > 3) }\n", "1:46: `tired` is a metric, which the program "
                                          "cannot read"),
    ("agent a { count 3; var v = 0; status s { v += 1 } }\nmetric m = mean(v)\n"
     "metric twice = m * 2\n", "3:16: `m` is a metric, which the program cannot read"),
])
def test_reading_a_metric_says_it_is_one(assert_located_error, text, message):
    """It was "unknown name `m`", though `m` is declared two lines up."""
    assert_located_error(text, message)


@pytest.mark.parametrize("body, message", [
    ("v = q\n    let q = 2", "3:9: `q` is bound by a `let` after this (line 4): a `let` is "
                            "known only in the statements after it"),
    ("let q = q + 1\n    v = q", "3:13: `let q` cannot use its own value"),
])
def test_a_let_read_before_it_is_bound_says_so(assert_located_error, body, message):
    """Both were "unknown name `q`", with `q` bound on the next line."""
    assert_located_error(f"agent a {{ count 3; var v = 0\n  status s {{\n    {body}\n  }}\n}}\n",
                         message)


@pytest.mark.parametrize("body", ["v = normal(0, sd)", "v = sqrt(sd)"])
def test_a_named_trees_parameter_is_not_the_param_of_its_name(run_src, body):
    """`param sd = -1` and `tree t(sd) { v = normal(0, sd) }` called as `t(2)`: the
    tree's `sd` is 2, yet check read the param and refused `normal(0, -1)`."""
    sim = run_src(f"param sd = -1\ntree t(sd) {{ {body} }}\n"
                  "agent a { count 3; var v = 0; status s { tree t(2) } }\n")
    v = sim.agents.cols["v"]
    assert np.isfinite(v).all()
    if "sqrt" in body:
        assert np.allclose(v, np.sqrt(2))       # the tree's sd, not the param's -1
    else:
        assert len(set(v.tolist())) == 3        # drawn with sd 2, one draw per agent


def test_a_draw_made_constant_by_a_trees_argument_is_checked(assert_located_error):
    """`t(0 - 1)` made `normal(0, sd)` a constant `normal(0, -1)`: the run did not check
    it (constant draws are the checker's) and the checker had only seen `sd`; it drew
    with a negative deviation, silently."""
    assert_located_error("tree t(sd) { v = normal(0, sd) }\n"
                         "agent a { count 3; var v = 0; status s { tree t(0 - 1) } }\n",
                         "2:49: `normal(mean, sd)` needs sd >= 0, got sd = -1")


def test_unknown_outside_choose_says_where_it_goes(assert_located_error):
    """It was "unknown function `unknown`" with the hint "did you mean 'known'?", though
    the docs list it (as an attraction of `choose`)."""
    assert_located_error("world { }\nfood alpha = circle(80, 80, 5)\n"
                         "agent a { count 3; labels known; var b = false\n"
                         "  status s { b = unknown(food, known) } }\n",
                         "4:18: `unknown(food, LABELS)` is an attraction of `choose` only")


def _diagnostics(compile_src, text: str) -> list[tuple[str, str | None]]:
    """Every error as (`line:col: message`, hint)."""
    with pytest.raises(SwarmError) as err:
        compile_src(text)
    found = getattr(err.value, "diagnostics", [err.value])
    return [(f"{d.span.line}:{d.span.col}: {d.message}", d.hint) for d in found]


@pytest.mark.parametrize("text, where", [
    ("param n = 10\nagent a { count nn\n status s { } }\n", "2:17"),
    ("param n = 10\nagent a { count 2 * nn + 1\n status s { } }\n", "2:21"),
    ("param n = 10\nworld { size nn x 100 }\nagent a { count 3\n status s { } }\n", "2:14"),
])
def test_an_unknown_name_in_a_constant_is_named_with_a_suggestion(compile_src, text, where):
    """`count nn` (a typo of `n`) said "the count of `a` must be a constant": true of
    every unknown name, and silent about the typo."""
    assert _diagnostics(compile_src, text) == [(f"{where}: unknown name `nn`",
                                                "did you mean 'n'?")]


def test_a_known_name_that_is_not_a_constant_is_still_called_that(compile_src):
    text = "agent a { count e; var e = 3\n status s { e = 1 } }\n"
    assert _errors(compile_src, text) == [
        "1:17: the count of `a` must be a constant (numbers and params only)"]


def test_an_unknown_neighbour_radius_is_the_only_error(compile_src):
    """`neighbors(radus)` first said to add `sense R`, the typo second."""
    text = ("param radius = 10\nagent a { count 3\n status s {\n"
            "  let near = neighbors(radus)\n  velocity = (count(near), 0) } }\n")
    assert _diagnostics(compile_src, text) == [("4:24: unknown name `radus`",
                                                "did you mean 'radius'?")]
    fixed = compile_src(text.replace("radus", "radius"))
    assert fixed.info.kinds[0].sense == 10


# ---- comparisons whose answer is known: NaN, or `inf` against a value never infinite ----

_MAPPED = """world {{ size 100 x 100 }}
agent scout {{
  count 20
  map spots 5 10
  var e = 0
  status roaming {{
    velocity = (1, 0)
    e += 1
    note(spots, 1)
    when {cond} -> exploring
  }}
  status exploring {{ velocity = (0, 1); when e > 1e9 -> roaming }}
}}
"""


def _warned(compile_src, text: str) -> list[tuple[str, str | None]]:
    return [(f"{w.span.line}:{w.span.col}: {w.message}", w.hint)
            for w in compile_src(text).info.warnings]


def test_age_compared_with_inf_warns_and_points_to_known(compile_src, run_src):
    """`age` of a cell never seen was `inf` and is 10^15: a program written for the old
    meaning silently took the other branch."""
    text = _MAPPED.format(cond="age(spots, pos + (7, 0)) == inf")
    assert _warned(compile_src, text) == [(
        "10:10: this comparison is always false: the `age` of a cell never seen is 10^15, "
        "never `inf`", "`known(spots, point)` tells whether the cell was seen: test `not "
        "known(spots, point)` for a cell never seen")]
    sim = run_src(text, steps=3)        # what the warning says is what the run does
    assert set(sim.agents.cols["status"]) == {0}
    sim = run_src(_MAPPED.format(cond="not known(spots, pos + (7, 0))"), steps=3)
    assert set(sim.agents.cols["status"]) == {1}


@pytest.mark.parametrize("op", ["==", "!=", "<", "<=", ">", ">="])
@pytest.mark.parametrize("infinity", ["inf", "-inf"])
@pytest.mark.parametrize("age_first", [True, False])
def test_the_warning_says_what_the_comparison_gives(compile_src, op, infinity, age_first):
    """Every operator, either infinity, either side: the answer the warning names is the
    comparison's for any finite age (the never-seen one included)."""
    age = "age(spots)"
    cond = f"{age} {op} {infinity}" if age_first else f"{infinity} {op} {age}"
    (warning,) = _warned(compile_src, _MAPPED.format(cond=cond))
    import operator

    compare = {"==": operator.eq, "!=": operator.ne, "<": operator.lt, "<=": operator.le,
               ">": operator.gt, ">=": operator.ge}[op]
    inf = float(infinity)
    for value in (0.0, 3.0, 1e15):
        truth = compare(value, inf) if age_first else compare(inf, value)
        assert f"always {'true' if truth else 'false'}:" in warning[0]


@pytest.mark.parametrize("op", ["==", "!=", "<", "<=", ">", ">="])
@pytest.mark.parametrize("nan", ["inf - inf", "0 * inf", "inf / inf"])
def test_a_comparison_with_nan_warns_that_it_never_holds(compile_src, op, nan):
    (warning,) = _warned(compile_src, _MAPPED.format(cond=f"e {op} {nan}"))
    truth = "true" if op == "!=" else "false"
    assert warning == (f"10:10: this comparison is always {truth}: its right side is NaN "
                       "(not a number), which is unequal to every number, itself included",
                       "a value is NaN exactly when `x != x`")


@pytest.mark.parametrize("cond", ["e == inf", "age(spots) > 5", "e < 1e15",
                                  "age(spots) == e", "inf == inf"])
def test_a_comparison_that_can_go_either_way_gets_no_warning(compile_src, cond):
    """A variable can overflow to `inf`; only readings never infinite are sure."""
    assert _warned(compile_src, _MAPPED.format(cond=cond)) == []


def test_there_is_no_nan_and_the_hint_says_why(compile_src):
    (error,) = _diagnostics(compile_src, _MAPPED.format(cond="e == nan"))
    assert error[0] == "10:15: unknown name `nan`"
    assert "`x != x` holds exactly for NaN" in error[1]


# ---- constant arguments of probes: refused at check, naming the argument ----

_PROBED = """param far = 5
world {{ size 100 x 100; grid 10 }}
field F {{ decay 0.1 }}
region z = circle(50, 50, 5)
agent a {{
  count 5
  map spots 5 10
  var e = 0
  status s {{
    {statement}
  }}
}}
"""


@pytest.mark.parametrize("statement, col, message", [
    ("e = cone(F, inf, 0.5)", 17, "the look-ahead distance of `cone` is infinite"),
    ("e = cone(F, 3, -inf)", 20, "the half angle of `cone` is infinite"),
    ("e = ahead(F, inf)", 18, "the look-ahead distance of `ahead` is infinite"),
    ("e = ahead(F, 2, 2 * inf)", 21, "the turn angle of `ahead` is infinite"),
    ("e = sample(F, (inf, 0))", 19, "the sampled point of `sample` is infinite"),
    ("e = sample(F, (far, 0 * inf))", 19, "the sampled point of `sample` is not a number "
                                          "(NaN)"),
    ("e = F at (inf, 3)", 14, "the point after `at` is infinite"),
    ("e = if touching(z, inf) then 1 else 0", 24, "the reach of `touching` is infinite"),
    ("e = age(spots, (0, -inf))", 20, "the point of `age` is infinite"),
    ("note(spots, 1, (1e16, 0))", 20, "the point of `note` is 1e+16; constants are limited "
                                      "to 1e+15 in size"),
])
def test_a_constant_probe_argument_the_run_would_refuse_is_an_error(compile_src, statement,
                                                                     col, message):
    """`cone(F, inf, 0.5)` passed `check` and failed at the first tick with "positions
    must be finite"."""
    (error,) = _diagnostics(compile_src, _PROBED.format(statement=statement))
    assert error == (f"10:{col}: {message}",
                     "a point, distance or angle is a finite number; see docs/limits.md")


@pytest.mark.parametrize("statement", ["e = cone(F, far * 2, 0.5)",
                                       "e = ahead(F, e, heading)",
                                       "e = sample(F, pos + (far, 0))",
                                       "e = age(spots, (far, 0))"])
def test_finite_and_per_agent_probe_arguments_pass(compile_src, statement):
    """A finite constant, or one known only per agent, passes `check` and the probe
    reads a finite value on every agent."""
    from swarmdsl.runtime.simulation import Simulation

    sim = Simulation(compile_src(_PROBED.format(statement=statement)), 0, backend="numpy")
    sim.run(2)
    assert np.isfinite(sim.agents.cols["e"]).all()
