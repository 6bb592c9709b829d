"""invariant / eventually: checking, evaluation per agent and over the swarm, run --check,
and `swarmdsl test` finding, shrinking and reproducing a counterexample."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import pytest

from swarmdsl.cli import main
from swarmdsl.compiler.errors import SwarmError
from swarmdsl.testing import Monitor, run_program, search
from swarmdsl.testing.monitor import PropertyViolation

DATA = Path(__file__).parent / "data" / "props"

LINE = """
param n = 6
world { size 100 x 100 }
agent a {
  count n
  place (10 * index + 5, 50)
  var level = index
  status low { level += 1; when level >= 4 -> high }
  status high { }
  PROPS
}
"""


def _prog(compile_src, props: str, top: str = ""):
    return compile_src(LINE.replace("PROPS", props) + top)


def test_per_agent_invariant_reports_failing_ids(compile_src, run_src):
    from swarmdsl.runtime.simulation import Simulation

    prog = _prog(compile_src, "invariant small: level < 4")
    sim = Simulation(prog, 0)
    m = Monitor(prog)
    assert [v.agent_ids for v in m.check(sim)] == [(4, 5)]
    sim.step()
    (v,) = m.check(sim)
    assert v.agent_ids == (3, 4, 5) and v.tick == 1 and v.name == "a.small"
    assert "agents 3, 4, 5" in v.message()


def test_swarm_aggregates_evaluate_over_every_agent(backend, compile_src):
    from swarmdsl.runtime.simulation import Simulation

    top = """
invariant c: count(status == low) == 6 and count(status == high) == 0
invariant total: count() == n and sum(level) == 15 and mean(level) == 2.5
invariant mm: min(level) == 0 and max(level) == 5
invariant anyall: any(level > 4) and not all(level > 4) and all(pos.y == 50)
invariant centre: mean(pos) == (30, 50)
"""
    prog = _prog(compile_src, "", top)
    assert Monitor(prog).check(Simulation(prog, 0)) == []


def test_per_agent_invariant_may_use_swarm_aggregates(backend, compile_src):
    from swarmdsl.runtime.simulation import Simulation

    prog = _prog(compile_src, "invariant above_mean: level >= mean(level)")
    (v,) = Monitor(prog).check(Simulation(prog, 0))
    assert v.agent_ids == (0, 1, 2)


def test_eventually_swarm_and_per_agent(backend, compile_src):
    top = "eventually all_high within 3: all(status == high)\n"
    prog = _prog(compile_src, "eventually up within 3: status == high", top)
    res = run_program(prog, 10, stop_at_first=False)
    got = {(v.name, v.tick, v.agent_ids) for v in res.violations}
    # agent i reaches `high` after 4 - i ticks (agents 4 and 5 start there at tick 1)
    assert got == {("a.up", 3, (0,)), ("all_high", 3, ())}


def test_eventually_that_holds_is_silent(backend, compile_src):
    prog = _prog(compile_src, "eventually up within 4: status == high")
    assert run_program(prog, 8).ok


def test_checking_does_not_change_the_run(backend, compile_src):
    text = LINE.replace("PROPS", "invariant ok: level >= 0").replace(
        "level += 1", "level += uniform(0, 1)")
    a = run_program(compile_src(text), 5, seed=3, check=True)
    b = run_program(compile_src(text), 5, seed=3, check=False)
    assert np.array_equal(a.state["level"], b.state["level"])


def test_state_arrays_are_ordered_by_id(backend, compile_src):
    res = run_program(_prog(compile_src, ""), 2)
    st = res.state
    assert list(st["id"]) == list(range(6))
    assert list(st["status_name"]) == ["low", "low", "high", "high", "high", "high"]
    assert st["pos"].shape == (6, 2)


def test_variable_read_only_by_a_property_is_not_unread(compile_src):
    text = """
agent a {
  count 2
  var cmd = 0
  status s { cmd += 1 }
  invariant capped: cmd < 10
}
"""
    assert [w.message for w in compile_src(text).info.warnings] == []


@pytest.mark.parametrize("n", [0, 3])
def test_vector_means_hold_over_an_empty_swarm(backend, tmp_path, capsys, n):
    path = tmp_path / "empty.swarm"
    path.write_text(f"""param n = {n}
agent a {{
  count n
  var v = (1, 2)
  status s {{ v += (1, 0) }}
  invariant mean_ok: length(mean(vel)) <= 10
}}
invariant centred: mean(pos) == mean(pos else (0, 0)) and length(sum(v)) >= 0
always answered: length(mean(v)) > 1000 -> eventually mean(v).x == 0 within 2
""")
    assert main(["run", str(path), "--headless", "--steps", "3", "--check"]) == 0
    assert "error" not in capsys.readouterr().err


@pytest.mark.parametrize("text, message", [
    ("agent a { count 1; status s { }; invariant x: speed }\n",
     "an invariant must be a condition (a boolean), got a number"),
    ("agent a { count 1; status s { } }\ninvariant x: speed < 3\n",
     "`speed` is a value of each agent; a swarm property reads it through count, all, any, "
     "sum, mean, min or max"),
    ("agent a { count 1; sense 5; status s { }; invariant x: count(neighbors()) < 3 }\n",
     "`neighbors` in a property takes one argument: the radius"),
    ("agent a { count 1; status s { }; invariant x: random() < 2 }\n",
     "properties cannot draw random numbers (`random`): checking them would change the run"),
    ("agent a { count 1; status s { } }\ninvariant x: count(count(speed > 1) > 2) > 0\n",
     "swarm aggregates cannot be nested"),
    ("agent a { count 1; status s { } }\ninvariant x: all(speed)\n",
     "`all` over the swarm takes a boolean per agent, got a number"),
    ("agent a { count 1; status s { } }\neventually x within 0: count() > 0\n",
     "`within` takes a whole number of ticks of at least 1, got 0"),
    ("agent a { count 1; status s { }; invariant x: true }\ninvariant x: true\n",
     "property `x` is already declared (line 2)"),
])
def test_bad_properties_are_located_errors(compile_src, text, message):
    with pytest.raises(SwarmError) as info:
        compile_src(text)
    assert message in [d.message for d in info.value.diagnostics]


def test_run_check_exits_1_at_the_violation(backend, tmp_path, capsys):
    path = tmp_path / "p.swarm"
    path.write_text(LINE.replace("PROPS", "invariant small: level < 6"))
    assert main(["run", str(path), "--headless", "--steps", "5"]) == 0
    capsys.readouterr()
    assert main(["run", str(path), "--headless", "--steps", "5", "--check"]) == 1
    err = capsys.readouterr().err
    assert f"{path}:10:13: error: invariant `a.small` violated at tick 1 for agent 5" in err
    assert "^~~~~" in err


def test_search_shrinks_the_speed_bug_and_the_command_reproduces(backend, tmp_path, capsys,
                                                                 monkeypatch):
    # the budget only ends a hunt that hangs: under load a 20 s budget ended the
    # shrinking early, so the verdict hung on the machine's load
    report = search(DATA / "speed_bug.swarm", max_examples=80, time_budget=600,
                    hypothesis_seed_value=1)
    ce = report.counterexample
    assert ce is not None
    assert ce.agents <= 5
    (v,) = [v for v in ce.result.violations if v.tick == ce.tick]
    assert v.name == "walker.bounded" and v.agent_ids
    ce.save(tmp_path / "case.json")
    argv = shlex.split(ce.command(str(DATA / "speed_bug.swarm"), tmp_path / "case.json"))
    assert argv[:2] == ["swarmdsl", "run"]
    assert main(argv[1:]) == 1
    assert f"violated at tick {ce.tick} for agent" in capsys.readouterr().err
    if ce.tick > 1:   # one tick fewer does not fail: the shortest run
        assert main([*argv[1:], "--steps", str(ce.tick - 1)]) == 0


def test_swarmdsl_test_cli_exit_codes(backend, tmp_path, capsys):
    # three walkers (`--set n=3`) still break `bounded`, and the hunt shrinks in 55
    # runs, not 157: what a whole hunt shrinks to is the next test's
    assert main(["test", str(DATA / "speed_bug.swarm"), "--examples", "60",
                 "--time-budget", "20", "--hypothesis-seed", "1", "--quiet",
                 "--set", "n=3"]) == 1
    out = capsys.readouterr().out
    assert "counterexample found" in out and "reproduce: swarmdsl run" in out
    assert "invariant `walker.bounded` violated at tick" in out
    assert main(["test", str(DATA / "foraging.swarm"), "--examples", "5", "--steps", "30",
                 "--quiet"]) == 0
    assert "no counterexample to 2 properties in 8 runs" in capsys.readouterr().out
    bad = tmp_path / "bad.swarm"
    bad.write_text("agent a { count 1; status s { }; invariant x: speed }\n")
    assert main(["test", str(bad), "--quiet"]) == 2
    none = tmp_path / "none.swarm"
    none.write_text("agent a { count 1; status s { } }\n")
    assert main(["test", str(none), "--quiet"]) == 0
    assert "no properties to test" in capsys.readouterr().out


def test_swarmdsl_test_reports_an_internal_error_not_a_counterexample(backend, monkeypatch, capsys):
    """A bug in swarmdsl during a drawn run ends the hunt at once: one line naming the
    tick and the exception (exit 3), no counterexample, no shrinking, no traceback."""
    from swarmdsl.runtime.simulation import Simulation

    real_step, raised = Simulation.step, []

    def step(self):
        if self.tick == 2:
            raised.append(self.tick)
            raise RuntimeError("boom")
        real_step(self)

    monkeypatch.setattr(Simulation, "step", step)
    monkeypatch.delenv("SWARMDSL_DEBUG", raising=False)
    argv = ["test", str(DATA / "foraging.swarm"), "--examples", "20", "--steps", "10",
            "--quiet", "--hypothesis-seed", "1"]
    assert main(argv) == 3
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [
        "error: internal error at tick 2: RuntimeError: boom (please report this)"]
    assert "Traceback" not in captured.err and "counterexample" not in captured.out
    assert raised == [2]            # the first run that hit it; nothing shrunk or replayed
    monkeypatch.setenv("SWARMDSL_DEBUG", "1")
    with pytest.raises(RuntimeError, match="boom"):
        main(argv)


def test_run_program_raises_an_internal_error_naming_the_tick(backend, monkeypatch):
    from swarmdsl.internal import InternalError

    def check(self, sim):
        raise ValueError("bad\nshape")

    monkeypatch.setattr(Monitor, "check", check)
    with pytest.raises(InternalError) as caught:
        run_program(DATA / "speed_bug.swarm", 5)
    assert caught.value.message == ("internal error at tick 0: ValueError: bad shape "
                                    "(please report this)")
    assert isinstance(caught.value.__cause__, ValueError)
    assert caught.value.exit_code == 3


@pytest.mark.parametrize(("option", "value"), [
    ("--time-budget", "nan"), ("--time-budget", "inf"), ("--time-budget", "-inf"),
    ("--time-budget", "0"), ("--time-budget", "-1"), ("--examples", "0"),
    ("--steps", "0"),
])
def test_swarmdsl_test_refuses_bad_numbers_naming_the_option(capsys, option, value):
    assert main(["test", str(DATA / "speed_bug.swarm"), "--quiet", f"{option}={value}"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {option} ") and ": must be " in err
    assert "Traceback" not in err


def test_property_violation_is_a_runtime_error_with_exit_code_1():
    assert issubclass(PropertyViolation, SwarmError) and PropertyViolation.exit_code == 1


PROGRAMS = sorted((Path(__file__).resolve().parent.parent / "programs").glob("*.swarm"))


@pytest.mark.parametrize("path", PROGRAMS, ids=[p.stem for p in PROGRAMS])
def test_shipped_programs_properties_hold(backend, path):
    report = search(path, max_examples=4, steps=40, time_budget=30, hypothesis_seed_value=0)
    assert report.counterexample is None, report.counterexample.describe(str(path))


def test_boids_declares_properties():
    from swarmdsl.compiler import compile_file
    from swarmdsl.compiler.lang_properties import properties_of

    names = [p.info.qualified for p in properties_of(compile_file(
        Path(__file__).resolve().parent.parent / "programs" / "boids.swarm"))]
    assert names == ["inside_world", "boid.at_most_cruise"]


def test_checking_never_changes_a_run_even_with_extension_random_calls(backend):
    aco = Path(__file__).resolve().parent.parent / "programs" / "aco.swarm"
    text = aco.read_text() + (
        "invariant busy: count(choose(24, 0.5, pheromone) > -10) == 7\n"
        "invariant short: all(len(trail) <= 2000)\n")
    a = run_program(text, 30, seed=2, check=True)
    b = run_program(text, 30, seed=2, check=False)
    assert a.ok and a.ticks == 30
    assert np.array_equal(a.state["pos"], b.state["pos"])


def test_a_runtime_fault_is_a_counterexample_too(backend):
    text = """
param n = 5 in 1..10
param d = 3 in 0..3
world { size 50 x 50 }
agent a {
  count n
  var u = 1
  status s { u = 1 / (d - index); velocity = (u, 0) }
  invariant fine: u > 0
}
"""
    # the program as written faults (the agent of index 3); removing agents before it
    # moves its index, so four agents are 1-minimal there
    ce = search(text, max_examples=60, time_budget=20, hypothesis_seed_value=0).counterexample
    assert ce is not None and ce.result.fault is not None
    assert "became infinite" in str(ce.result.fault)
    assert ce.origin == "the program as written, seed 0" and ce.minimal
    assert ce.agents == 4 and ce.example.overrides()["n"] == 4
    # drawn runs alone find the smaller case: one agent, d = 0
    ce = search(text, max_examples=60, time_budget=20, hypothesis_seed_value=0,
                seeds=0).counterexample
    assert ce is not None and ce.result.fault is not None
    assert ce.agents == 1 and ce.example.overrides()["d"] == 0


@pytest.mark.slow
@pytest.mark.parametrize("path", PROGRAMS, ids=[p.stem for p in PROGRAMS])
def test_shipped_programs_properties_hold_long(backend, path):
    report = search(path, max_examples=200, time_budget=300)
    assert report.counterexample is None, report.counterexample.describe(str(path))


PARTIAL_KINDS = """
agent a {{ count 3; var s = 4; status x {{ }} }}
agent b {{ count 1; status y {{ }} }}
invariant p: {expr}
"""


def _metric_value(expr: str) -> float:
    """`expr` as a top-level metric at tick 0 (the same swarm aggregates as a property)."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.metrics import MetricLog
    from swarmdsl.runtime.simulation import Simulation

    prog = compile_source(PARTIAL_KINDS.format(expr="true") + f"metric m = {expr}\n",
                          "p.swarm")
    assert prog.info.warnings == []
    log = MetricLog(prog)
    log.sample(Simulation(prog, 0))
    return float(log.pending()[1][0][0])


@pytest.mark.parametrize("aggregate, condition, only_a", [
    ("mean(s)", "mean(s) >= 0", 4.0), ("min(s)", "min(s) >= 0", 4.0),
    ("max(s)", "max(s) >= 0", 4.0), ("sum(2 * s)", "sum(2 * s) >= 0", 24.0),
    ("count(s < 5)", "count(s < 5) >= 0", 3.0), ("all(s > 0)", "all(s > 0) or true", 1.0),
    ("any(s < 1)", "any(s < 1) or true", 0.0)])
def test_a_property_reading_a_variable_some_kinds_lack_is_warned_with_a_fix(
        backend, aggregate, condition, only_a):
    """`b` reads `s` as 0 in a swarm aggregate (mean 3, min 0, `all(s > 0)` false),
    rarely what was meant: a warning at the variable, whose hint, taken as written,
    reduces over the agents of `a` alone, and is not warned about itself."""
    from swarmdsl.compiler import compile_source

    prog = compile_source(PARTIAL_KINDS.format(expr=condition), "p.swarm")
    (w,) = prog.info.warnings
    name = aggregate[:aggregate.index("(")]
    assert w.message == (f"`s` is a variable of `a` only: this `{name}` over every agent "
                         "reads it as 0 for the agents of `b`")
    assert (w.span.line, w.span.col) == (4, len("invariant p: ") + aggregate.rindex("s") + 1)
    fix = w.hint.split("`")[1].replace("...", aggregate[aggregate.index("(") + 1:-1])
    assert _metric_value(fix) == only_a


def test_run_check_of_a_program_without_properties_says_nothing_is_checked(backend, walk,
                                                                          capsys):
    """It ran and exited 0 as a checked run that found nothing wrong would."""
    assert main(["run", str(walk), "--headless", "--steps", "2", "--check"]) == 0
    err = capsys.readouterr().err
    assert (f"warning: --check: {walk} declares no `invariant`, `eventually` or "
            "`always`; nothing is checked") in err
