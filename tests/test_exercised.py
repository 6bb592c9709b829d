"""`swarmdsl test` says how many runs exercised each property (could have broken it),
warns about one none did, fails with `--strict` (exit 4), and runs the program's own
`world { steps }` by default. tests/data/props/battery.swarm is the case that passed
silently: its trigger first holds near tick 400, its runs were 100 ticks long."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.testing import run_program, search

BATTERY = Path(__file__).parent / "data" / "props" / "battery.swarm"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)


def test_a_hunt_too_short_for_the_trigger_says_it_never_exercised_it(backend, cache, capsys):
    argv = ["test", str(BATTERY), "--quiet", "--steps", "100", "--examples", "4",
            "--hypothesis-seed", "0"]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert "  horizon: up to 100 ticks per run (--steps)" in out
    # 3 runs of the program as written (cut to --steps 100), then 4 drawn
    assert "  invariant `drone.charged`: exercised by 7 of 7 runs" in out
    assert "  always `drone.recharges`: exercised by 0 of 7 runs" in out
    assert "its trigger held at 0 agent-ticks in 0 runs" in out
    assert "warning: no run reached the program's horizon of 3000 ticks (the longest ran " \
        "100; runs of up to 100 ticks, --steps)" in err
    assert "battery.swarm:28:10: warning: always `drone.recharges` was never exercised: " \
           "its trigger never held with 1 tick left to watch the response" in err
    assert "--strict makes this a failure" in err
    assert "charged` was never" not in err
    assert main([*argv, "--strict"]) == 4
    assert "always `drone.recharges` was never exercised" in capsys.readouterr().err


def test_the_hunt_runs_as_long_as_the_programs_world_says(backend, cache, capsys):
    # 3000 ticks, the world's `steps`: the bug at tick ~400 is found
    # (a time budget the hunt ends well within, even on a loaded machine)
    assert main(["test", str(BATTERY), "--quiet", "--examples", "5", "--time-budget",
                 "120", "--hypothesis-seed", "0"]) == 1
    out = capsys.readouterr().out
    assert "  horizon: up to 3000 ticks per run (the program's `world { steps 3000 }`)" \
        in out
    assert "always `drone.recharges` triggered at tick 4" in out


@pytest.mark.parametrize(("world", "properties", "steps", "why"), [
    ("", "", 100, "the default; the program's world sets no `steps`"),
    ("; steps 40", "", 40, "the program's `world { steps 40 }`"),
    ("", "eventually late within 250: tick > 3", 250,
     "the largest `within`; the program's world sets no `steps`"),
])
def test_the_horizon_and_why(backend, world, properties, steps, why):
    text = (f"world {{ size 20 x 20{world} }}\nagent a {{ count 1; status s {{ }} }}\n"
            f"invariant fine: count() == 1\n{properties}\n")
    report = search(text, max_examples=1, hypothesis_seed_value=0)
    assert (report.steps, report.horizon) == (steps, why)


def test_every_run_is_counted_for_the_properties_it_exercised(backend):
    text = """world { size 20 x 20 }
agent a {
  count 2
  var t = 0
  status s { t = t + 1 }
  always soon: t >= 0 -> eventually t >= 0 within 3
  always never: t < 0 -> eventually t > 0 within 3
}
agent b { count 0; status s { } ; invariant nobody: false }
"""
    report = search(text, max_examples=6, hypothesis_seed_value=1)
    # 3 runs of the program as written, then 6 drawn
    assert report.counterexample is None and report.examples == 9
    assert report.exercised == {"a.soon": 9}
    assert report.coverage.as_written == 3 and len(report.coverage.sizes) == 6
    assert report.unexercised() == ["a.never", "b.nobody"]


@pytest.mark.parametrize(("steps", "exercised"), [(2, False), (3, True)])
def test_an_eventually_is_exercised_once_its_deadline_is_reached(backend, steps, exercised):
    text = ("world { size 20 x 20 }\nagent a { count 1; status s { } }\n"
            "eventually late within 3: tick > 5\n")
    result = run_program(text, steps)
    assert ("late" in result.exercised) is exercised
    assert bool(result.violations) is exercised       # the run that could, failed it


RESPONSE = """world {{ size 30 x 30 }}
agent a {{
  count {n}
  var p = chance({pp})
  var q = false
  status s {{ p = chance({pp}); q = chance({pq}) }}
  always answered: p -> eventually q within {within}
}}
"""


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 3), pp=st.sampled_from([0.0, 0.05, 0.3]),
       pq=st.sampled_from([0.0, 0.5]), within=st.integers(1, 4), steps=st.integers(0, 8),
       seed=st.integers(0, 3))
def test_an_always_is_exercised_when_a_window_closes_as_a_reference_says(backend, n, pp, pq,
                                                                        within, steps,
                                                                        seed):
    """Reference over the recorded trace: some agent's trigger held at t, and the run
    saw its response (a q in t..t+N) or all N ticks after it."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation
    from swarmdsl.testing import Monitor, state_arrays

    prog = compile_source(RESPONSE.format(n=n, pp=pp, pq=pq, within=within), "r.swarm")
    sim, monitor = Simulation(prog, seed), Monitor(prog)
    p, q = [], []
    for t in range(steps + 1):
        if t:
            sim.step()
        state = state_arrays(sim)
        p.append(state["p"])
        q.append(state["q"])
        monitor.check(sim, t)
    p, q = np.array(p, bool), np.array(q, bool)
    expected = any(p[t].any() and (t + within <= steps or
                                   (p[t] & q[t:t + within + 1].any(axis=0)).any())
                   for t in range(steps + 1))
    assert ("a.answered" in monitor.exercised) is expected


def test_a_checked_run_that_never_exercised_a_property_says_so(capsys, backend):
    """`run --check --steps 100` passed `recharges` silently; 3000 ticks break it."""
    assert main(["run", str(BATTERY), "--headless", "--check", "--steps", "100"]) == 0
    err = capsys.readouterr().err
    assert "battery.swarm:28:10: warning: --check: always `drone.recharges` was never " \
           "exercised: its trigger never held with 1 tick left to watch the response; " \
           "a longer run (--steps N) may break it" in err
    assert "charged" not in err
    assert main(["run", str(BATTERY), "--headless", "--check"]) == 1
    assert "always `drone.recharges` triggered at tick 4" in capsys.readouterr().err
