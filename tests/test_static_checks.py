"""Static checks of `swarmdsl check` that catch real bugs: guard gaps (interval
reasoning), divisions by neighbour aggregates that are 0 for an agent with no
neighbours, and a `let` computed before the `when` that would have guarded it."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.compiler import compile_source
from swarmdsl.testing import run_program

OPS = ("<", "<=", ">", ">=", "==", "!=")

GAPS = """param m = 3
world {{ size 10 x 10 }}
agent a {{
  count 1
  var v = {init}
  status s {{
{whens}
  }}
  status t {{ v = v {step}; when true -> s }}
}}
"""


def _warnings(text: str) -> list[str]:
    return [str(w) for w in compile_source(text, "g.swarm").info.warnings]


def _gap_warnings(text: str) -> list[str]:
    return [w for w in _warnings(text) if "guard gap" in w]


def _covered(v: float, comparisons) -> bool:
    return any({"<": v < c, "<=": v <= c, ">": v > c, ">=": v >= c, "==": v == c,
                "!=": v != c}[op] for op, c in comparisons)


def _reference_gap(comparisons, whole: bool) -> bool:
    """An uncovered value with covered values below and above it (checked on every
    piece of the partition the constants make; whole numbers only when `whole`)."""
    cs = sorted({c for _op, c in comparisons})
    if whole:
        points = [float(v) for v in range(int(cs[0]) - 2, int(cs[-1]) + 3)]
    else:
        points = [cs[0] - 1, *cs, *[(a + b) / 2 for a, b in zip(cs, cs[1:])], cs[-1] + 1]
        points.sort()
    covered = [_covered(v, comparisons) for v in points]
    for i, ok in enumerate(covered):
        if not ok and any(covered[:i]) and any(covered[i + 1:]):
            return True
    return False


@settings(max_examples=80, deadline=None)
@given(comparisons=st.lists(st.tuples(st.sampled_from(OPS), st.integers(1, 5)),
                            min_size=1, max_size=4),
       whole=st.booleans(), flipped=st.booleans())
def test_a_gap_is_warned_iff_it_exists(comparisons, whole, flipped):
    lines = []
    for op, c in comparisons:
        cond = f"{c} {dict(zip(OPS, ('>', '>=', '<', '<=', '==', '!=')))[op]} v" \
            if flipped else f"v {op} {c}"
        lines.append(f"    when {cond} -> t")
    text = GAPS.format(init="0" if whole else "uniform(0, 6)", step="+ 1" if whole else
                       "+ 0.5", whens="\n".join(lines))
    found = _gap_warnings(text)
    assert bool(found) == _reference_gap([(op, float(c)) for op, c in comparisons], whole), \
        (comparisons, found)


def test_the_gap_is_named_with_its_value_and_param():
    text = GAPS.format(init="0", step="+ 1", whens="    when v < m -> t\n    when v > m -> t")
    (w,) = _gap_warnings(text)
    assert "g.swarm:6:10: warning: guard gap in `a.s`: when `v` == 3 (`m`), no `when` " \
        "leaves it" in w
    real = GAPS.format(init="uniform(0, 6)", step="+ 0.5",
                       whens="    when v < 2 -> t\n    when v > 4.5 -> t")
    (w,) = _gap_warnings(real)
    assert "when 2 <= `v` <= 4.5," in w
    # whole steps cannot land strictly between 2 and 3: no trap
    assert not _gap_warnings(GAPS.format(init="0", step="+ 1",
                                         whens="    when v <= 2 -> t\n    when v >= 3 -> t"))


def test_no_gap_warning_when_the_status_changes_the_variable_or_has_other_whens():
    changes = GAPS.format(init="0", step="+ 1",
                          whens="    v = v + 1\n    when v < m -> t\n    when v > m -> t")
    assert not _gap_warnings(changes)
    other = GAPS.format(init="0", step="+ 1",
                        whens="    when v < m -> t\n    when v > m -> t\n"
                              "    when chance(0.1) -> t")
    assert not _gap_warnings(other)


def test_the_gap_is_real_agents_stay_for_good():
    text = GAPS.format(init="0", step="+ 1", whens="    when v < m -> t\n    when v > m -> t")
    state = run_program(text, 40, seed=0, check=False).state
    assert state["status_name"][0] == "s" and state["v"][0] == 3


NAN = """world {{ size 30 x 30 }}
agent a {{
  count 6
  velocity random_direction()
  var w = 0
  status s {{
{body}
  }}
}}
"""


@pytest.mark.parametrize(("body", "warned"), [
    ("    let near = neighbors(4)\n    w = sum(near : other.pos.x) / count(near)", True),
    ("    let near = neighbors(4)\n    w = 1 / mean(near : dist)", True),
    ("    w = 1 / count(neighbors(4) where other.w > 0)", True),
    ("    let near = neighbors(4)\n    w = sum(near : other.pos.x) / max(count(near), 1)",
     False),
    ("    let near = neighbors(4)\n    w = 1 / mean(near : dist else 1)", False),
    ("    let near = neighbors(4)\n    when count(near) == 0 -> s\n"
     "    w = sum(near : other.pos.x) / count(near)", False),
    ("    let near = neighbors(4)\n    when count(near) < 1 or w > 9 -> s\n"
     "    w = 2 / count(near)", False),
    ("    let near = neighbors(4)\n    w = if count(near) > 0 then 1 / count(near) else 0",
     False),
    # guarded by a `when` on another set: still a hazard
    ("    let near = neighbors(4)\n    when count(neighbors(2)) == 0 -> s\n"
     "    w = 1 / count(near)", True),
])
def test_division_by_an_aggregate_that_can_be_zero(body, warned):
    text = NAN.format(body=body)
    found = [w for w in _warnings(text) if "no neighbours in range" in w]
    assert bool(found) == warned, found


def test_the_warned_division_is_a_real_fault_and_the_guarded_one_is_not():
    bad = NAN.format(body="    let near = neighbors(4)\n"
                          "    w = sum(near : other.pos.x) / count(near)")
    assert run_program(bad, 5, seed=1, check=False).fault is not None
    good = NAN.format(body="    let near = neighbors(4)\n    when count(near) == 0 -> s\n"
                           "    w = sum(near : other.pos.x) / count(near)")
    assert run_program(good, 5, seed=1, check=False).fault is None


def test_a_let_computed_before_the_when_that_would_guard_it(tmp_path, capsys):
    body = ("    let near = neighbors(4)\n    let centre = sum(near : other.pos.x) / count(near)\n"
            "    when count(near) == 0 -> s\n    w = centre")
    text = NAN.format(body=body)
    (w,) = [w for w in _warnings(text) if "divides by" in w]
    assert "g.swarm:8:18: warning: `centre` divides by an aggregate of a neighbour set" in w
    assert "the `when` on line 9 sends those agents away" in w
    assert run_program(text, 5, seed=1, check=False).fault is not None
    moved = NAN.format(body="    let near = neighbors(4)\n    when count(near) == 0 -> s\n"
                            "    let centre = sum(near : other.pos.x) / count(near)\n"
                            "    w = centre")
    assert not [w for w in _warnings(moved) if "neighbour" in w]
    assert run_program(moved, 5, seed=1, check=False).fault is None
    path = tmp_path / "p.swarm"
    path.write_text(text)
    assert main(["check", str(path)]) == 0
    err = capsys.readouterr().err
    assert "hint: move `let centre` below the `when` on line 9" in err


def test_shipped_programs_get_no_hazard_warnings():
    from pathlib import Path

    from swarmdsl.compiler import compile_file

    for path in sorted((Path(__file__).resolve().parent.parent / "programs").glob("*.swarm")):
        found = [str(w) for w in compile_file(path).info.warnings
                 if "guard gap" in str(w) or "neighbour set" in str(w)]
        assert not found, (path.name, found)


def test_reference_helper_is_not_vacuous():
    assert _reference_gap([("<", 3.0), (">", 3.0)], False)
    assert not _reference_gap([("<=", 3.0), (">", 3.0)], False)
    assert not _reference_gap([("<=", 2.0), (">=", 3.0)], True)
    assert _reference_gap([("<=", 2.0), (">=", 3.0)], False)


# ---- "never read nor changed": every reader and writer counts, wherever it is ----

@pytest.mark.parametrize("reader", [
    "agent a { count 3; var e = 1; status s { }; metric me = mean(e) }",
    "agent a { count 3; var e = 1; status s { } }\nmetric me = mean(e)",
    "agent a { count 3; var e = 1; status s { } }\n"
    "eventually big within 5: any(e > 3)",
    "agent a { count 3; var e = 1; status s { }; always up: e > 2 -> "
    "eventually e > 3 within 2 }",
    # read by a kind declared after it, through `other`
    "agent a { count 3; var e = 1; status s { } }\n"
    "agent b { count 2; sense 5; var v = 0; status t { v = sum(neighbors() : other.e) }\n"
    "  metric mx = mean(v) }",
])
def test_a_variable_read_only_by_a_metric_property_or_other_kind_is_read(reader):
    assert [w for w in _warnings(reader) if "never read" in w] == []


@pytest.mark.parametrize("update", [
    "trips += 1", "trips = trips + 1", "trips = tick", "trips *= 2",
    "when tick > 3 -> s { trips -= 1 }",            # in a transition's actions
    "tree sequence { trips += 1 }",                 # in a tree's action leaf
])
def test_a_variable_the_program_only_updates_is_an_output_not_a_warning(update):
    """Every `var` is a column of agents.parquet: a counter only ever incremented is
    what the experiment records, not a forgotten value."""
    text = f"agent a {{ count 3; var trips = 0; status s {{ {update} }} }}"
    assert [w for w in _warnings(text) if "never read" in w] == []


def test_an_attribute_nobody_reads_is_a_recorded_label_not_a_warning():
    assert _warnings("agent a { count 4; attr group = index % 2; status s { } }") == []


def test_a_var_never_read_nor_changed_is_still_warned_once_in_source_order(tmp_path,
                                                                           capsys):
    path = tmp_path / "u.swarm"
    path.write_text("agent a {\n  count 3\n  var e = 1\n  var f = 2\n  var g = 0\n"
                    "  status s { e += 1; let unused = g }\n  metric me = mean(e)\n}\n")
    assert main(["check", str(path)]) == 0
    err = capsys.readouterr().err
    assert err.count("is never read") == 1
    assert f"{path}:4:7: warning: variable `f` of `a` is never read nor changed" in err
    assert ("hint: it only records its initial value in agents.parquet: update it in a "
            "status, declare it `attr f = ...` if a per-agent constant is the point, or "
            "remove it") in err
    # a `let` never used says nothing to the analysis: still warned
    assert f"{path}:6:26: warning: `unused` is bound but never used" in err
