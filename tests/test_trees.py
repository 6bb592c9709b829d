"""Behaviour trees: timing exact in ticks, reactive against memory forms, long actions,
status entry, and the checker's located findings."""

from __future__ import annotations

import numpy as np
import pytest

from swarmdsl.compiler import compile_source
from swarmdsl.compiler.errors import SwarmCheckError
from swarmdsl.runtime.simulation import Simulation

HEAD = "world { size 100 x 100; edges wall }\n"


def trace(body: str, steps: int, var: str, extra: str = "", top: str = "") -> list:
    """Agent 0's `var` after each tick, for a one-status agent with `t` counting ticks
    (t is 1 during the first tick's tree)."""
    src = (HEAD + top + "agent bot {\n  count 1\n  place (10, 50)\n  var t = 0\n"
           f"  var n = 0\n  var last = 0\n{extra}  status s {{\n    t += 1\n{body}\n  }}\n}}\n")
    sim = Simulation(compile_source(src, "t.swarm"), seed=0)
    out = []
    for _ in range(steps):
        sim.step()
        out.append(sim.agents.cols[var][0].tolist())
    return out


def test_wait_runs_n_ticks_then_succeeds_on_the_next(backend):
    got = trace("tree sequence { wait(3); last = t }", 9, "last")
    assert got == [0, 0, 0, 4, 4, 4, 4, 8, 8]


def test_repeat_runs_its_child_once_per_tick(backend):
    n = trace("tree repeat 3 n += 1\n    when tree succeeded -> s { last = t }", 7, "n")
    last = trace("tree repeat 3 n += 1\n    when tree succeeded -> s { last = t }", 7, "last")
    assert n == [1, 2, 3, 4, 5, 6, 7]
    assert last == [0, 0, 3, 3, 3, 6, 6]


def test_retry_gives_n_attempts_then_fails(backend):
    body = "tree retry 3 sequence { n += 1; t < 0 }\n    on failure -> s { last = t }"
    assert trace(body, 6, "last") == [0, 0, 3, 3, 3, 6]
    body = "tree retry 3 sequence { n += 1; t >= 2 }\n    on success -> s { last = t }"
    assert trace(body, 2, "last") == [0, 2]


def test_timeout_fails_on_the_nth_running_tick(backend):
    body = "tree timeout 3 wait(10)\n    on failure -> s { last = t }"
    assert trace(body, 7, "last") == [0, 0, 3, 3, 3, 6, 6]
    body = "tree timeout 3 wait(2)\n    on success -> s { last = t }"
    assert trace(body, 3, "last") == [0, 0, 3]


def test_cooldown_skips_n_ticks_after_its_child_finishes(backend):
    body = "tree reactive fallback { cooldown 2 n += 1; last += 1 }"
    assert trace(body, 7, "n") == [1, 1, 1, 2, 2, 2, 3]
    assert trace(body, 7, "last") == [0, 1, 2, 2, 3, 4, 4]


def test_memory_sequence_resumes_reactive_sequence_rechecks(backend):
    memory = trace("tree sequence { t < 3; wait(5); last = t }", 8, "last")
    reactive = trace("tree reactive sequence { t < 3; wait(5); last = t }", 8, "last")
    assert memory == [0, 0, 0, 0, 0, 6, 6, 6]     # the wait, once started, runs out
    assert reactive == [0] * 8                   # t < 3 fails at t = 3 and halts it


def test_memory_fallback_resumes_reactive_fallback_rechecks(backend):
    body = "tree {} fallback {{ t > 2 and t < 5; sequence {{ wait(4); last = t }} }}"
    assert trace(body.format(""), 8, "last") == [0, 0, 0, 0, 5, 5, 5, 5]
    # reactive: t = 3, 4 succeed on the first child and halt the wait; it restarts at 5
    assert trace(body.format("reactive"), 10, "last") == [0] * 8 + [9, 9]


def test_parallel_memory_keeps_results_reactive_reticks(backend):
    body = "tree {} parallel 2 {{ wait(1); wait(4) }}\n    on success -> s {{ last = t }}"
    assert trace(body.format(""), 6, "last") == [0, 0, 0, 0, 5, 5]
    got = trace(body.format("reactive"), 10, "last")
    assert got[:9] == [0] * 9 and got[9] == 10


def test_parallel_fails_once_k_successes_are_out_of_reach(backend):
    body = "tree parallel 2 { t < 0; wait(3); t < 0 }\n    on failure -> s { last = t }"
    assert trace(body, 2, "last") == [1, 2]      # 2 failures of 3: 2 successes impossible


def test_decorators_invert_and_force(backend):
    assert trace("tree invert t > 1\n    on success -> s { last = t }", 3, "last") == [1, 1, 1]
    body = "tree force success t > 100\n    on success -> s { last = t }"
    assert trace(body, 2, "last") == [1, 2]
    body = "tree force failure t > 0\n    on failure -> s { last = t }"
    assert trace(body, 2, "last") == [1, 2]


def test_tree_running_is_this_ticks_result(backend):
    body = "tree wait(2)\n    when not tree running -> s { last = t }"
    assert trace(body, 6, "last") == [0, 0, 3, 3, 3, 6]
    # a transition, even back to the same status, enters it afresh
    body = "tree wait(2)\n    when tree running -> s { n += 1 }"
    assert trace(body, 4, "n") == [1, 2, 3, 4]


def test_move_to_steers_at_speed_arrives_exactly_and_stops(backend):
    src = HEAD + """agent bot {
  count 1
  place (10, 50)
  var arrived = 0
  var t = 0
  status go {
    t += 1
    tree move_to((20, 50), 0.5, 2)
    on success -> done { arrived = t }
  }
  status done { }
}"""
    sim = Simulation(compile_source(src, "m.swarm"), seed=0)
    xs = []
    for _ in range(7):
        sim.step()
        xs.append(float(sim.agents.cols["pos"][0, 0]))
    assert xs[:5] == [12, 14, 16, 18, 20]
    assert sim.agents.cols["arrived"][0] == 6
    assert sim.agents.cols["vel"][0].tolist() == [0, 0]


def test_move_to_crosses_the_edge_of_a_wrapped_world(backend):
    """(95, 50) is 10 units from (5, 50) across the edge of a wrap-around world, 90 the
    other way: move_to takes the short way, as `other.pos - pos` does."""
    src = """world { size 100 x 100; edges wrap }
agent bot {
  count 1
  place (5, 50)
  status go { tree move_to((95, 50), 0, 2) }
}"""
    sim = Simulation(compile_source(src, "w.swarm"), seed=0, backend=backend)
    xs = []
    for _ in range(6):
        sim.step()
        xs.append(float(sim.agents.cols["pos"][0, 0]))
    assert xs == [3, 1, 99, 97, 95, 95]


def test_move_to_is_interrupted_by_a_reactive_condition(backend):
    src = HEAD + """agent bot {
  count 1
  place (10, 50)
  var t = 0
  status go {
    t += 1
    tree reactive fallback {
      sequence { t >= 3; velocity = (0, 0) }
      move_to((90, 50), 0.5, 2)
    }
  }
}"""
    sim = Simulation(compile_source(src, "m.swarm"), seed=0)
    sim.run(6)
    assert float(sim.agents.cols["pos"][0, 0]) == 14.0   # moved on ticks 1 and 2 only


def test_retrace_runs_until_the_path_is_empty_and_lands_on_the_start(backend):
    src = HEAD + """agent bot {
  count 1
  place (10, 50)
  memory path 10
  var t = 0
  var back = 0
  status out {
    t += 1
    velocity = (3, 1)
    remember(path)
    when t == 4 -> home { velocity = (0, 0) }
  }
  status home {
    t += 1
    tree retrace(path)
    on success -> idle { back = t }
  }
  status idle { }
}"""
    sim = Simulation(compile_source(src, "r.swarm"), seed=0)
    sim.run(12)
    assert sim.agents.cols["back"][0] == 9     # 4 points popped on ticks 5-8, done on 9
    assert sim.agents.cols["pos"][0].tolist() == [10.0, 50.0]


def test_follow_climbs_to_the_peak_and_fails_where_there_is_nothing(backend):
    src = HEAD + """field warmth { initial max(0, 40 - distance(pos, (50, 50))) }
agent bot {
  count 2
  place (if index == 0 then (30, 50) else (95, 95))
  var t = 0
  var peak = 0
  var lost = 0
  status climb {
    t += 1
    tree follow(warmth, 2)
    on success -> done { peak = t }
    on failure -> done { lost = t }
  }
  status done { }
}"""
    sim = Simulation(compile_source(src, "f.swarm"), seed=0)
    sim.run(40)
    cols = sim.agents.cols
    assert cols["lost"][1] == 1 and cols["peak"][1] == 0      # nothing to follow
    assert cols["peak"][0] > 0
    assert np.linalg.norm(cols["pos"][0] - [50, 50]) <= 10    # at the warm spot's grid peak


def test_entering_a_status_restarts_its_tree(backend):
    body = """tree sequence { wait(3); last = t }
    when t == 2 -> away"""
    src = (HEAD + "agent bot {\n  count 1\n  var t = 0\n  var last = 0\n  status s {\n"
           "    t += 1\n" + body + "\n  }\n  status away {\n    t += 1\n    when true -> s\n"
           "  }\n}\n")
    sim = Simulation(compile_source(src, "e.swarm"), seed=0)
    sim.run(8)
    # waits ticks 1-2, leaves at 2, back at 4: waits 4, 5, 6, done at 7
    assert sim.agents.cols["last"][0] == 7


def test_named_trees_take_parameters_and_serve_several_kinds(backend):
    top = "tree pause(k) { sequence { wait(k); last = t } }\n"
    assert trace("tree pause(2)", 4, "last", top=top) == [0, 0, 3, 3]
    src = HEAD + top + """agent a {
  count 1
  var t = 0
  var last = 0
  status s { t += 1; tree pause(1) }
}
agent b {
  count 1
  var t = 0
  var last = 0
  status s { t += 1; tree pause(t) }
}"""
    sim = Simulation(compile_source(src, "k.swarm"), seed=0)
    sim.run(3)
    assert sim.agents.cols["last"].tolist() == [2, 0]


# ---- the checker ----

CHECKS = [
    ("tree forage(r) { wait(r) }\n", "tree forge(3)",
     "unknown tree, action or condition `forge`", "did you mean 'forage'?"),
    ("tree forage(r) { wait(r) }\n", "tree forage(1, 2)",
     "tree `forage` takes 1 argument (r), got 2", None),
    ("", "when wait(3) -> s",
     "`wait` is a long action: it runs over several ticks and can only be a leaf of a "
     "`tree`, not part of a condition or value", None),
    ("", "tree sequence { not move_to((1, 1), 1) }",
     "`move_to` is a long action: it runs over several ticks and can only be a leaf of a "
     "`tree`, not part of a condition or value", None),
    ("", "tree force failure wait(2)\n    on success -> s",
     "the tree of this status can never succeed, so this transition never fires", None),
    ("", "tree n += 1\n    when tree failed -> s",
     "the tree of this status can never fail, so this transition never fires", None),
    ("", "tree force failure wait(2)\n    last = if tree succeeded then 1 else 0",
     "the tree of this status can never succeed, so `tree succeeded` is always false here",
     None),
    ("", "tree n += 1\n    when t > 3 and tree failed -> s",
     "the tree of this status can never fail, so this transition never fires", None),
    ("", "on success -> s",
     "`tree succeeded` (or `on success`) needs a `tree` earlier in this status", None),
    ("tree a() { b() }\ntree b() { a() }\n", "tree a()",
     "tree `a` uses itself (a -> b -> a)", None),
    ("", "tree parallel 3 { wait(1); wait(2) }",
     "`parallel K` needs a whole number K from 1 to the number of children (2), got 3",
     None),
    ("", "tree wait(1)\n    tree wait(2)",
     "a status has one `tree`; this status already has one (line 10)", None),
    ("tree pause() { wait(1) }\n", "tree sequence { pause }",
     "`pause` is a tree; use it as `pause(...)`", None),
    ("", "tree repeat 2.5 n += 1", "the count of `repeat` must be a whole number of "
     "ticks, got 2.5", None),
]


def _compile(top: str, body: str):
    src = (HEAD + top + "agent bot {\n  count 1\n  place (10, 50)\n  var t = 0\n"
           f"  var n = 0\n  var last = 0\n  status s {{\n    t += 1\n    {body}\n  }}\n}}\n")
    return compile_source(src, "c.swarm"), src


@pytest.mark.parametrize("top, body, message, hint", CHECKS)
def test_checker_reports_tree_mistakes_where_they_are(top, body, message, hint):
    with pytest.raises(SwarmCheckError) as info:
        _compile(top, body)
    errs = [e for e in info.value.diagnostics if e.message == message]
    assert errs, [e.message for e in info.value.diagnostics]
    err = errs[0]
    assert err.span.line >= 2 + top.count("\n") or "tree" in top
    assert err.hint == hint or hint is None


def test_located_message_points_at_the_bad_leaf():
    with pytest.raises(SwarmCheckError) as info:
        _compile("tree forage(r) { wait(r) }\n", "tree sequence { t > 1; forge(3) }")
    err = info.value.diagnostics[0]
    assert (err.span.line, err.span.col) == (11, 28)
    assert "did you mean 'forage'?" in err.render()


def test_unreachable_children_are_warned_about_at_the_child():
    prog, _src = _compile("", "tree fallback { n >= 0 or true; wait(3) }")
    warns = [w for w in prog.info.warnings if "never run" in w.message]
    assert len(warns) == 1
    assert warns[0].message == ("this child can never run: the one before it never fails, "
                                "so the `fallback` stops there")
    assert (warns[0].span.line, warns[0].span.col) == (10, 37)
    prog, _src = _compile("", "tree sequence { t < 0 and false; n += 1 }")
    assert any("never succeeds" in w.message for w in prog.info.warnings)


def test_a_named_tree_never_used_is_warned_about():
    prog, _src = _compile("tree spare() { wait(1) }\n", "tree wait(1)")
    assert any(w.message == "tree `spare` is never used" for w in prog.info.warnings)


def test_on_success_and_on_failure_are_known_to_exclude_each_other():
    src = HEAD + """agent bot {
  count 1
  status s {
    tree timeout 5 wait(2)
    on success -> s
    on failure -> s
  }
}
"""
    prog = compile_source(src, "n.swarm")
    assert not [n for n in prog.info.extra.get("notes", []) if "hold together" in n.message]


def test_a_mistake_in_a_named_tree_used_several_times_is_reported_once():
    # The body of a named tree is checked at each use; its mistakes are still one each.
    top = "tree visit(p) { sequence { move_too(p, 1); wait(p > 1) } }\n"
    body = "tree sequence { visit((1, 1)); visit((2, 2)); visit((3, 3)) }"
    with pytest.raises(SwarmCheckError) as info:
        _compile(top, body)
    messages = [e.message for e in info.value.diagnostics]
    assert messages.count("unknown tree, action or condition `move_too`") == 1, messages
    with pytest.raises(SwarmCheckError) as info:
        _compile("tree a() { a() }\n", "tree sequence { a(); a() }")
    messages = [e.message for e in info.value.diagnostics]
    assert messages == ["tree `a` uses itself (a -> a)"], messages


# ---- counts: limits, `forever` ----

COUNT_CHECKS = [
    ("tree repeat inf n += 1", 17, "the count of `repeat` must be a finite number, got inf"),
    ("tree retry inf n += 1", 16, "the count of `retry` must be a finite number, got inf"),
    ("tree timeout inf wait(3)", 18,
     "the count of `timeout` must be a finite number, got inf"),
    ("tree cooldown inf n += 1", 19,
     "the count of `cooldown` must be a finite number, got inf"),
    ("tree wait(inf)", 15, "the ticks of `wait` must be a finite number, got inf"),
    ("tree repeat 1e20 n += 1", 17, "the count of `repeat` is too large: a tree's count "
     "of ticks or runs (`repeat`, `retry`, `timeout`, `cooldown`, `wait`) is limited to "
     "1,000,000,000,000, got 1e+20"),
    ("tree cooldown forever n += 1", 19,
     "`forever` is a count of `repeat` and `retry` only, not the count of `cooldown`"),
    ("tree parallel forever { wait(1) }", 19, "`forever` is a count of `repeat` and "
     "`retry` only, not the success threshold of `parallel`"),
    ("tree repeat forever n += 1\n    on success -> s", 8,
     "the tree of this status can never succeed, so this transition never fires"),
]


@pytest.mark.parametrize("body, col, message", COUNT_CHECKS)
def test_tree_counts_are_finite_bounded_and_located(body, col, message):
    """`repeat inf` and friends were an internal OverflowError; `repeat 1e20` ran."""
    with pytest.raises(SwarmCheckError) as info:
        _compile("", body)
    err = info.value.diagnostics[0]
    assert err.message == message
    assert (err.span.line, err.span.col) == (10 + body.count("\n"), col)


def test_repeat_forever_and_retry_forever_never_end_by_count(backend):
    assert trace("tree repeat forever n += 1\n    when tree running -> s { last += 1 }",
                 6, "last") == [1, 2, 3, 4, 5, 6]
    body = "tree retry forever sequence { n += 1; t == 5 }\n    on success -> s { last = t }"
    assert trace(body, 6, "last") == [0, 0, 0, 0, 5, 5]
    assert trace(body, 6, "n") == [1, 2, 3, 4, 5, 6]


@pytest.mark.parametrize("count, got", [("n * 1e30 + inf", "inf"), ("n + 1e13", "1e+13")])
def test_a_computed_count_beyond_the_limit_is_a_located_runtime_error(backend, count, got):
    from swarmdsl.compiler.errors import SwarmRuntimeError

    prog, _src = _compile("", f"tree wait({count})")
    sim = Simulation(prog, seed=0, backend=backend)
    with pytest.raises(SwarmRuntimeError) as info:
        sim.step()
    err = info.value
    assert err.message == f"the count is {got} for agent 0 (kind `bot`, status `s`) at tick 0"
    assert (err.span.line, err.span.col) == (10, 15)
    assert "1,000,000,000,000" in err.hint


# ---- regions as targets ----

REGION_TARGETS = """world { size 100 x 100 }
nest home = circle(80, 50, 5)
food f1 = circle(10, 10, 2)
food f2 = circle(90, 90, 2)
agent a {
  count 2
  place (20 + 50 * index, 50)
  var c = (0, 0)
  var arrived_at = -1
  status s {
    c = centre(food)
    tree sequence { move_to(home, 0, 2); arrived_at = tick }
    on success -> done
  }
  status done { c = center(home) }
}
"""


def test_move_to_a_region_stops_at_its_edge_and_centre_names_its_centre(backend):
    """`move_to(home, 5, 2)` asked for a vector: a region is a target, as for objectives
    (its nearest point), and `centre(R)` is its centre (the nearest one of a kind)."""
    sim = Simulation(compile_source(REGION_TARGETS, "r.swarm"), seed=0, backend=backend)
    sim.step()
    cols = sim.agents.cols
    assert cols["c"].tolist() == [[10, 10], [90, 90]]     # the food nearest each agent
    sim.run(30)
    assert cols["pos"].tolist() == [[75, 50], [75, 50]]   # the edge of `home`, exactly
    assert cols["arrived_at"].tolist() == [28, 3]    # 55 and 5 units at 2 a tick
    assert cols["c"].tolist() == [[80, 50], [80, 50]]


def test_move_to_names_what_its_target_may_be():
    with pytest.raises(SwarmCheckError) as info:
        _compile("", "tree move_to(5, 1)")
    err = info.value.diagnostics[0]
    assert err.message == "the target of `move_to` must be a vector or a region, got a number"
    assert (err.span.line, err.span.col) == (10, 18)
