"""What the arguments of `chance`, `normal` and `uniform` must be (compiler/draws.py):
refused where they are written when constant, per agent at run time otherwise, alike on
both backends, and without changing a single draw of a valid program."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import backend_names

from swarmdsl import cli
from swarmdsl.compiler import compile_source
from swarmdsl.runtime.simulation import Simulation


def _run(tmp_path, capsys, src: str, *args: str) -> tuple[int, str]:
    path = tmp_path / "draws.swarm"
    path.write_text(src + "\n", encoding="utf-8")
    capsys.readouterr()
    rc = cli.main(["run", str(path), "--headless", "--steps", "3", "--out",
                   str(tmp_path / "out"), *args])
    out = capsys.readouterr()
    return rc, out.err + out.out


def _status(body: str, var: str = "var u = 0") -> str:
    return f"agent a {{ count 4; {var}; status s {{ {body} }} }}"


@pytest.mark.parametrize("src,where,said", [
    (_status("b = chance(0 * index / 0 * index)", "var b = false"), "1:57",
     "the p of `chance(p)` is NaN for agent 0 (kind `a`, status `s`) at tick 0"),
    (_status("b = chance(index - 1)", "var b = false"), "1:57",
     "`chance(p)` needs 0 <= p <= 1, got p = -1 for agent 0 (kind `a`, status `s`) "
     "at tick 0"),
    (_status("b = chance(index / 2)", "var b = false"), "1:57",
     "`chance(p)` needs 0 <= p <= 1, got p = 1.5 for agent 3 (kind `a`, status `s`) "
     "at tick 0"),
    (_status("u = normal(0, index - 2)"), "1:56",
     "`normal(mean, sd)` needs sd >= 0, got sd = -2 for agent 0 (kind `a`, status `s`) "
     "at tick 0"),
    (_status("u = normal(1 / (index - 2), 1)"), "1:53",
     "`normal(mean, sd)` needs a finite mean, got mean = inf for agent 2 (kind `a`, "
     "status `s`) at tick 0"),
    (_status("u = uniform(5, index)"), "1:46",
     "`uniform(lo, hi)` needs lo <= hi, got lo = 5 and hi = 0 for agent 0 (kind `a`, "
     "status `s`) at tick 0"),
    # fused into one compiled loop on numba: the draw is still the reference closure's
    (_status("u = normal(0, index - 2) * 2 + u * 3 + 1"), "1:56",
     "`normal(mean, sd)` needs sd >= 0, got sd = -2 for agent 0 (kind `a`, status `s`) "
     "at tick 0"),
    # an initial value: while placing
    ("agent a { count 4; var u = uniform(index, 2); status s { } }", "1:28",
     "`uniform(lo, hi)` needs lo <= hi, got lo = 3 and hi = 2 for agent 3 of `a` while "
     "placing agents"),
    # a draw per neighbour pair: the agent whose neighbour it is
    ("agent a { count 6; sense 500; var u = 0\n"
     "  status s { u = sum(neighbors() : normal(0, other.index - 3)) } }", "2:46",
     "`normal(mean, sd)` needs sd >= 0, got sd = -2 for agent 0 (kind `a`, status `s`) "
     "at tick 0"),
])
def test_a_bad_argument_at_run_time_is_a_located_error(tmp_path, capsys, backend, src,
                                                       where, said):
    rc, out = _run(tmp_path, capsys, src, "--backend", backend)
    assert rc == 2, out
    assert f"draws.swarm:{where}: error: {said}\n" in out, out
    assert "hint: " in out and "Traceback" not in out and ".py:" not in out


@pytest.mark.parametrize("src,where,said", [
    (_status("b = chance(2)", "var b = false"), "1:57", "`chance(p)` needs 0 <= p <= 1, "
     "got p = 2"),
    (_status("u = normal(0, -1)"), "1:56", "`normal(mean, sd)` needs sd >= 0, got sd = -1"),
    (_status("u = uniform(5, 1)"), "1:46",
     "`uniform(lo, hi)` needs lo <= hi, got lo = 5 and hi = 1"),
    (_status("u = uniform(0, inf)"), "1:46",
     "`uniform(lo, hi)` needs finite bounds, got lo = 0 and hi = inf"),
    (_status("b = chance(inf - inf)", "var b = false"), "1:57",
     "the p of `chance(p)` is NaN"),
    ("param p = 0.5\n" + _status("b = chance(p * 3)", "var b = false"), "2:57",
     "`chance(p)` needs 0 <= p <= 1, got p = 1.5"),
])
def test_a_constant_bad_argument_is_refused_before_the_run(tmp_path, capsys, src, where,
                                                           said):
    rc, out = _run(tmp_path, capsys, src)
    assert rc == 2, out
    assert f"draws.swarm:{where}: error: {said}\n" in out, out
    assert not (tmp_path / "out").exists()


def test_a_set_param_is_checked_as_the_program_would_be(tmp_path, capsys):
    src = "param sd = 1\n" + _status("u = normal(0, sd)")
    assert _run(tmp_path, capsys, src)[0] == 0
    rc, out = _run(tmp_path, capsys, src, "--set", "sd=-0.5")
    assert rc == 2, out
    assert "draws.swarm:2:56: error: `normal(mean, sd)` needs sd >= 0, got sd = -0.5" in out


@pytest.mark.parametrize("body", [
    "u = if index > 1 then normal(0, index - 2) else 0",
    "u = (if index > 1 then normal(0, index - 2) else 0) * 2 + u * 3 + 1",
    "u = if index < 2 then 0 else uniform(2, index)",
    "b = index > 0 and chance(1 / index)",
    "b = index == 0 or chance(1 / index)",
    "b = index > 0 and index < 9 and chance(1 / index)",
    "when index > 0 and chance(1 / index) -> t",
    "when index == 0 -> t; u = normal(1 / index, 1) * 2 + u * 3 + 1",
])
def test_a_draw_an_agent_does_not_take_is_not_checked_for_it(tmp_path, capsys, backend,
                                                             body):
    """Both sides are computed for every agent; only the side it takes counts."""
    src = ("agent a { count 4; var u = 0; var b = false\n"
           f"  status s {{ {body} }}; status t {{ }} }}")
    rc, out = _run(tmp_path, capsys, src, "--backend", backend)
    assert rc == 0, out


def test_the_check_changes_no_draw_and_the_backends_agree():
    """Arguments checked per agent draw the very numbers constant ones do (the site is
    where the call starts), on both backends, tick after tick."""
    per_agent = """
    u = normal(0 * index, 1 + 0 * index) * 2 + u * 3 + 1
    w = uniform(-1 + 0 * index, 1)
    b = index >= 0 and chance(0.5 + 0 * index)
    z = if index > 0 then normal(1, 2 + 0 * index) else uniform(0 * index, 1)"""
    # the same text with constant arguments, padded: every call starts where it did
    constant = per_agent.replace(" + 0 * index", " " * 12).replace("0 * index", "0" + " " * 8)
    states = []
    for text in (per_agent, constant):
        prog = compile_source("agent a {\n  count 50\n  var u = 0\n  var w = 0\n"
                              "  var z = 0\n  var b = false\n  status s {" + text
                              + "\n  }\n}\n", "test.swarm")
        for backend in backend_names():
            sim = Simulation(prog, 7, backend=backend)
            sim.run(5)
            states.append({c: sim.agents.cols[c].copy() for c in "uwzb"})
    for other in states[1:]:
        for c in "uwzb":
            assert np.array_equal(states[0][c], other[c]), c
    assert states[0]["b"].any() and not states[0]["b"].all()
