"""`swarmdsl test` reaches the runs users make: the program as written first, draws up
to the declared counts, every failing property with its own case, 1-minimal cases (or
an honest "may not be minimal"), and coverage that says what was tried.

The aggregation program is the issue's: `crowd <= 8` breaks in every plain run of 80
bots, while a hunt whose swarms had a median of 3 agents reported it as holding.
"""

from __future__ import annotations

import json
import shlex

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.testing import run_program, search

AGGREGATE = """param n = 80 in 1..80
param r = 4
world { size 100 x 100; edges wrap; steps 40 }
agent bot {
  count n
  velocity random_direction()
  var crowd = 0
  status search {
    let near = neighbors(20)
    velocity = normalize(velocity + 0.3 * sum(near : other.pos - pos) / max(count(near), 1))
    crowd = count(neighbors(r))
    when crowd >= 3 -> stay
  }
  status stay {
    velocity = (0, 0)
    crowd = count(neighbors(r))
  }
  invariant not_too_dense: crowd <= 8
}
"""


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)


def test_a_property_a_plain_run_breaks_is_never_reported_as_holding(backend):
    assert not run_program(AGGREGATE, 40, seed=0).ok       # `swarmdsl run --check` fails
    report = search(AGGREGATE, max_examples=5, hypothesis_seed_value=0,
                    properties=["not_too_dense"], shrink_budget=2)
    ce = report.counterexample
    assert ce is not None and ce.origin == "the program as written, seed 0"
    assert [v.name for v in ce.violations] == ["bot.not_too_dense"]
    assert report.found_after == 1


@pytest.mark.parametrize(("count", "limit"), [(1, 1), (5, 3), (9, 9), (12, 30)])
def test_a_hunt_fails_exactly_when_the_program_as_written_does(backend, count, limit):
    """`count() < limit` over `count n` (n = `count` as written): a plain run breaks it
    iff count >= limit, and then the hunt must not pass, even with one drawn run."""
    text = (f"param n = {count} in 1..{count}\nworld {{ size 20 x 20; steps 2 }}\n"
            f"agent a {{ count n; status s {{ }} }}\ninvariant few: count() < {limit}\n")
    plain = run_program(text, 2, seed=0)
    report = search(text, max_examples=1, hypothesis_seed_value=0)
    assert (report.counterexample is not None) == (not plain.ok) == (count >= limit)


def test_set_pins_a_count_for_every_run(backend):
    report = search(AGGREGATE.replace("steps 40", "steps 3"), max_examples=6, seeds=0,
                    fixed={"n": 30}, hypothesis_seed_value=0, properties=["bot.not_too_dense"])
    sizes = report.coverage.sizes
    assert len(sizes) == 6 and set(sizes) == {30}


PASSING = """param n = 80 in 1..80
world { size 100 x 100; steps 2 }
agent bot { count n; status s { } ; invariant fine: true }
agent post { count 40; status s { } }
"""


@pytest.mark.parametrize("count", ["n", "40"])      # a size param, a constant count
def test_drawn_swarms_cover_the_range_up_to_the_declared_count_at_both_ends(backend, count):
    text = PASSING.replace("count n", f"count {count}").split("agent post")[0]
    most = 80 if count == "n" else 40
    report = search(text, max_examples=40, seeds=0, hypothesis_seed_value=0)
    cov = report.coverage
    sizes = sorted(cov.sizes)
    assert len(sizes) == 40
    assert sizes[0] <= 5 and sizes[-1] == most and cov.reached_counts
    small = sum(s <= most // 8 for s in sizes)
    large = sum(s >= most - most // 8 for s in sizes)
    assert small >= 3 and large >= 5, sizes   # weighted to both ends, not only small


def test_a_shrunk_kind_keeps_the_programs_density_in_a_window():
    """A kind the program places over the world, drawn with k of its `declared`
    agents, may go in a window of k / declared of the world's area."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.testing.swarms import _dense

    prog = compile_source(PASSING, "p.swarm")
    kind = prog.info.kinds[0]
    answers = iter([True, 0.25, 1.0, 7])
    dense = _dense(prog, kind, 20, 80, lambda strategy: next(answers))
    assert dense.width * dense.height == pytest.approx(100 * 100 * 20 / 80)
    assert dense.x0 == pytest.approx(0.25 * (100 - 50)) and dense.y0 == pytest.approx(50)
    points = [dense.place(slot)[1:] for slot in range(20)]
    assert all(dense.x0 <= x <= dense.x0 + 50 and 50 <= y <= 100 for x, y in points)
    assert len(set(points)) == 20
    assert _dense(prog, kind, 80, 80, lambda s: True) is None      # the whole count


SEVERAL = """param n = 6 in 1..6
world { size 30 x 30; steps 20 }
agent a {
  count n
  var t = 0
  status s { t = t + 1 }
  invariant early: t < 3
  invariant late: t < 8
  invariant fine: t >= 0
}
invariant few: count() < 4
"""


@pytest.mark.parametrize("seeds", [3, 0])     # found as written, and by drawn runs
def test_every_failing_property_gets_its_own_shrunk_counterexample(backend, seeds):
    report = search(SEVERAL, max_examples=40, hypothesis_seed_value=0, seeds=seeds)
    got = {ce.violations[0].name: ce for ce in report.counterexamples}
    assert sorted(got) == ["a.early", "a.late", "few"]
    assert (got["a.early"].tick, got["a.late"].tick, got["few"].tick) == (3, 8, 0)
    assert got["a.early"].agents == got["a.late"].agents == 1
    assert got["few"].agents == 4
    for name, ce in got.items():
        assert ce.properties == [name] and ce.minimal, ce.describe("s.swarm")
    assert report.unexercised() == []


def test_the_cli_prints_and_saves_each_counterexample_with_its_replay(backend, tmp_path,
                                                                      cache, capsys):
    path = tmp_path / "several.swarm"
    path.write_text(SEVERAL)
    case = tmp_path / "case.json"
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "0", "--examples", "5",
                 "--save-example", str(case)]) == 1
    out = capsys.readouterr().out
    assert out.splitlines()[0].startswith(
        f"{path}: 3 of 4 properties failed: `few`, `a.early`, `a.late` (")
    assert "invariant `a.fine`: exercised by" in out
    lines = [x for x in out.splitlines() if x.strip().startswith("reproduce:")]
    assert len(lines) == 3
    for name in ("few", "a.early", "a.late"):
        saved = tmp_path / f"case-{name}.json"
        assert json.loads(saved.read_text())["failure"]["property"] == name
        (line,) = [x for x in lines if f"--example {saved} " in x + " "]
        argv = shlex.split(line.split("reproduce:", 1)[1])
        assert argv[-2:] == ["--property", name]
        assert main(argv[1:]) == 1
        assert f"`{name}` violated" in capsys.readouterr().err


CROWD = """param n = 12 in 1..12
world { size 30 x 30; edges wrap; steps 3 }
agent a {
  count n
  var crowd = 0
  status s { crowd = count(neighbors(4)) }
  invariant calm: crowd < 3
}
"""


def test_a_minimal_counterexample_passes_without_any_one_agent_or_tick(backend):
    from swarmdsl.runtime.layout import Layout

    ce = search(CROWD, max_examples=30, hypothesis_seed_value=3).counterexample
    assert ce is not None and ce.minimal and ce.agents == 4
    ex = ce.example
    assert not run_program(CROWD, ex.steps, seed=ex.seed, params=ex.overrides(),
                           layout=ex.layout).ok
    for gone in ex.layout.agents:
        rest = Layout(tuple(a for a in ex.layout.agents if a is not gone), ex.layout.kinds)
        params = {**ex.overrides(), "n": len(rest.agents)}
        assert run_program(CROWD, ex.steps, seed=ex.seed, params=params, layout=rest).ok
    assert run_program(CROWD, ex.steps - 1, seed=ex.seed, params=ex.overrides(),
                       layout=ex.layout).ok
    text = ce.describe("crowd.swarm")
    assert "1-minimal: removing any one of its 4 agents, or ending it one tick earlier, " \
           "makes it pass (checked: 5 runs)" in text


def test_shrinking_cut_short_says_the_case_may_not_be_minimal(backend, tmp_path, cache,
                                                              capsys):
    path = tmp_path / "crowd.swarm"
    path.write_text(CROWD.replace("count n", "count n\n  place (15, 15)"))  # one heap
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "3",
                 "--shrink-budget", "1e-9"]) == 1
    out = capsys.readouterr().out
    assert "  shrinking stopped at its time budget: 12 agents, 1 tick, may not be " \
           "minimal (give it more time: --shrink-budget 1)" in out
    assert "1-minimal" not in out
    assert main(["test", str(path), "--quiet", "--shrink-budget", "0"]) == 2
    assert "--shrink-budget 0.0: must be a positive number of seconds" in \
        capsys.readouterr().err
    assert main(["test", str(path), "--quiet", "--seeds", "-1"]) == 2
    err = capsys.readouterr().err
    assert "--seeds -1: must be 0 or more" in err and "Traceback" not in err


IMPLIES = """param n = 3 in 1..3
world {{ size 30 x 30; steps 9 }}
agent a {{
  count n
  var carrying = {carrying}
  var fast = false
  status s {{ }}
  invariant careful: not carrying or not fast
  invariant careful_if: if carrying then not fast else true
}}
"""


def test_coverage_counts_agent_ticks_and_how_often_a_premise_held(backend):
    text = IMPLIES.format(carrying="index == 0")
    result = run_program(text, 9, seed=0, coverage=True)
    assert result.agent_ticks == {"a.careful": 30, "a.careful_if": 30}   # 3 agents x 10
    assert result.premise_ticks == {"a.careful": 10, "a.careful_if": 10}  # agent 0 only
    assert run_program(text, 9, seed=0).premise_ticks == {}   # off unless asked


def test_the_report_says_a_premise_never_held_and_what_was_tried(backend, tmp_path, cache,
                                                                 capsys):
    path = tmp_path / "implies.swarm"
    path.write_text(IMPLIES.format(carrying="false"))
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "0", "--examples",
                 "4"]) == 0
    out = capsys.readouterr().out
    assert f"{path}: no counterexample to 2 properties in 7 runs of up to 9 ticks: 3 of " \
           "the program as written (3 agents, seeds 0-2), 4 drawn (" in out
    assert "  tried: largest swarm 3 agents, longest run 9 ticks" in out
    assert "  invariant `a.careful`: exercised by 7 of 7 runs, checked at " in out
    assert "; its premise `carrying` held at 0 agent-ticks in 0 runs" in out


def test_a_warning_names_the_declared_counts_and_horizon_no_run_reached(backend, tmp_path,
                                                                        cache, capsys):
    path = tmp_path / "implies.swarm"
    path.write_text(IMPLIES.format(carrying="false").replace("in 1..3", "in 1..2"))
    assert main(["test", str(path), "--quiet", "--seeds", "0", "--examples", "2",
                 "--steps", "4", "--set", "n=1"]) == 0
    err = capsys.readouterr().err
    assert "warning: no run had the program's declared counts (`a` 3; the largest swarm " \
           "tried had 1 agents)" not in err       # --set n=1: the declared count is 1
    assert "warning: no run reached the program's horizon of 9 ticks (the longest ran " \
           "4; runs of up to 4 ticks, --steps)" in err
    path.write_text(PASSING.replace("steps 2", "steps 1"))
    assert main(["test", str(path), "--quiet", "--seeds", "0", "--examples", "1",
                 "--hypothesis-seed", "0", "--fixed-count", "post"]) == 0
    out, err = capsys.readouterr()
    if "largest swarm 120 agents" not in out:
        assert "warning: no run had the program's declared counts (`bot` 80, `post` 40; " \
               "the largest swarm tried had " in err


@settings(max_examples=15, deadline=None)
@given(k=st.integers(2, 4),
       points=st.lists(st.tuples(st.floats(0, 12), st.floats(0, 12)), min_size=1,
                       max_size=12))
def test_shrinking_any_failing_swarm_gives_a_checked_1_minimal_case(backend, k, points):
    """Any swarm with an agent that has k - 1 others within 4 shrinks to exactly such a
    star of k agents: in a 1-minimal failing swarm every agent is needed, and a star of
    k is the least that fails. Checked here by runs of our own, not the shrinker's."""
    import time

    from swarmdsl.runtime.layout import AgentSpec, Layout
    from swarmdsl.testing.example import Example
    from swarmdsl.testing.runner import load
    from swarmdsl.testing.shrink import shrink
    from swarmdsl.testing.strategies import param_axes
    from swarmdsl.testing.swarms import kind_draws

    prog = load(CROWD.replace("crowd < 3", f"crowd < {k - 1}"))
    plan = kind_draws(prog, [a for a in param_axes(prog) if a.drawn])

    def run(ex):
        return run_program(prog, ex.steps, seed=ex.seed, params=ex.overrides(),
                           layout=ex.layout, properties=["a.calm"])

    layout = Layout(tuple(AgentSpec("a", i, p) for i, p in enumerate(points)), ("a",))
    start = Example((("n", len(points)),), 0, 3, layout)
    got = shrink(start, "a.calm", plan, prog, run, time.perf_counter() + 120)
    if run(start).ok:
        assert got is None
        return
    assert got.minimal and len(got.example.layout.agents) == k
    ex = got.example
    assert not run(ex).ok and run(Example(ex.params, ex.seed, ex.steps - 1, ex.layout)).ok
    for gone in ex.layout.agents:
        rest = tuple(a for a in ex.layout.agents if a is not gone)
        assert run(Example((("n", len(rest)),), ex.seed, ex.steps,
                           Layout(rest, ("a",)))).ok
