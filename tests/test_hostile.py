"""Hostile and careless input: every program exits 0 or 2, never with a traceback, and
every content error is located (`file:line:col: error:`).

The number positions below cover every option of the `world` and `agent` blocks (a
meta-test keeps it so as options are added), and every param, with the values a careless
or hostile user types: infinities, NaN, overflowing literals and powers, huge and tiny
numbers.
"""

from __future__ import annotations

import importlib.util
import json
import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmdsl import cli
from swarmdsl.compiler import (
    extensions,  # noqa: F401  (registers every option)
    limits,
    nesting,
    options,
)

LOCATED = re.compile(r"^\S+:\d+:\d+: error: ", re.MULTILINE)

# Values no option or param may take, and the words each refusal must contain.
EXTREMES = ["inf", "-inf", "inf - inf", "1e400", "10 ^ 400", "9 ^ 9 ^ 9", "1e300 * 1e300",
            "2 ^ 2000", "-1e300", "1e16", "0 ^ -1", "(-8) ^ 0.5"]

# One program per option, `{v}` marking the number position under attack.
WORLD_CASES = {
    "size": ["world { size {v} x 100 }", "world { size 100 x {v} }"],
    "grid": ["world { grid {v} }"],
    "edges": ["world { edges repel {v} }", "world { edges repel 1 {v} }"],
    "steps": ["world { steps {v} }"],
    "origin": ["world { origin {v} 0 }"],
    "refine": ["world { refine rect(0, 0, {v}, 50) 2 }", "world { refine circle(5, 5, {v}) }"],
}
AGENT_CASES = {
    "count": ["count {v}"],
    "place": ["place ({v}, 1)"],
    "velocity": ["velocity ({v}, 0)"],
    "heading": ["heading {v}"],
    "sense": ["sense {v}"],
    "max_speed": ["max_speed {v}"],
    "initial": ["initial s\n  var w = {v}"],
    "robot": ["robot generic\n  max_speed {v}"],
    "memory": ["memory trail {v}"],
    "map": ["map seen {v} 10", "map seen 10 {v}"],
    "labels": ["labels found\n  var w = {v}"],
    "message": ["message m num\n  var w = {v}"],
    "believe": ["believe ({v}, 0)"],
}
PARAM_CASES = ["param p = {v}", "param p = 1 in 0 .. {v}"]
# Numbers inside statements and declarations that the compiler must fold.
STATEMENT_CASES = {
    "deposit radius": "field f { decay 0.1 }\nagent a { count 3; status s { "
                      "deposit(f, 1, {v}) } }\n",
    "within": "agent a { count 3; status s { }\n  eventually e within {v} : true }\n",
    "memory": "agent a { count 3; memory m {v}; status s { } }\n",
}


def _agent(option: str) -> str:
    count = "" if option.startswith("count") else "  count 3\n"
    return "agent a {\n" + count + "  " + option + "\n  status s { }\n}\n"


def _programs():
    for name, templates in WORLD_CASES.items():
        for t in templates:
            yield f"world:{name}", t + "\nagent a { count 3; status s { } }\n"
    for name, templates in AGENT_CASES.items():
        for t in templates:
            yield f"agent:{name}", _agent(t)
    for t in PARAM_CASES:
        yield "param", t + "\nagent a { count 3; status s { } }\n"
    for name, t in STATEMENT_CASES.items():
        yield f"statement:{name}", t


def run_cli(tmp_path, source: str, *args: str, capsys) -> tuple[int, str]:
    """Run the CLI in this process on `source`; any exception escaping is a test failure."""
    path = tmp_path / "hostile.swarm"
    path.write_text(source, encoding="utf-8")
    capsys.readouterr()
    rc = cli.main([*args, str(path)] if args[0] != "run" else
                  ["run", str(path), "--headless", *args[1:]])
    out = capsys.readouterr()
    return rc, out.err + out.out


def test_every_world_and_agent_option_is_attacked():
    """The suite grows with the language: a new option without a hostile case fails here."""
    assert set(options.WORLD_OPTIONS) <= set(WORLD_CASES), (
        set(options.WORLD_OPTIONS) - set(WORLD_CASES))
    assert set(options.AGENT_OPTIONS) <= set(AGENT_CASES), (
        set(options.AGENT_OPTIONS) - set(AGENT_CASES))


@pytest.mark.parametrize("value", EXTREMES)
@pytest.mark.parametrize("where,template", list(_programs()))
def test_extreme_numbers_are_refused_where_written(tmp_path, capsys, where, template, value):
    source = template.replace("{v}", value)
    rc, out = run_cli(tmp_path, source, "check", capsys=capsys)
    assert rc == 2, f"{where} accepted {value!r}:\n{source}\n{out}"
    assert LOCATED.search(out), out
    assert "Traceback" not in out


@pytest.mark.parametrize("where,template", list(_programs()))
def test_ordinary_numbers_still_run(backend, tmp_path, capsys, where, template):
    """The same positions with a sensible value compile and run: the refusals are real."""
    value = "50" if where in ("agent:memory",) else "5"
    rc, out = run_cli(tmp_path, template.replace("{v}", value), "run", "--steps", "2",
                      capsys=capsys)
    assert rc == 0, out


@pytest.mark.parametrize("name", sorted(limits.OPTION_LIMITS))
def test_every_limit_is_documented(name):
    from pathlib import Path

    text = (Path(__file__).parent.parent / "docs" / "limits.md").read_text()
    assert f"`{name}`" in text
    assert f"{limits.OPTION_LIMITS[name][1]:,}".split(".")[0] in text or \
        f"{limits.OPTION_LIMITS[name][1]:g}" in text


# ---- resource estimates: refused before the run, at the option to change ----

@pytest.mark.parametrize("source,line,words", [
    ("field p { decay 0.1 }\nworld { size 1000 x 1000\n grid 0.01 }\n"
     "agent a { count 3; status s { } }\n", 3, "nodes"),
    ("world { size 100 x 100; grid 0.000001\n edges repel 1 10 }\n"
     "agent a { count 3; status s { } }\n", 2, "grid spacings"),
    ("world { size 100 x 100 }\nagent a {\n count 10000000\n sense 50\n"
     " status s { let k = count(neighbors(50)) } }\n", 4, "pairs"),
    ("agent a {\n count 1000000\n memory m 100000\n status s { } }\n", 3, "GiB"),
    ("field f { decay 0.1 }\nworld { grid 1 }\nagent a { count 3\n"
     " status s { deposit(f, 1, 500) } }\n", 4, "grid nodes per agent"),
    ("agent a { count 30000000; status s { } }\nagent b {\n count 30000000\n"
     " status s { } }\n", 1, "agents in all"),
    ("world { size 100 x 100\n grid 1e-300 }\nagent a { count 3; status s { } }\n", 2,
     "1e\\+302 nodes along one side"),
    ("field f { decay 0.1 }\nworld { size 100 x 100\n grid 1e-300 }\nagent a { count 3\n"
     " status s { deposit(f, 1, 10) } }\n", 3, "1e\\+302 nodes along one side"),
    # the default grid: the world's size is what made it too big
    ("field f { decay 0.1 }\nworld { edges wrap\n size 1e9 x 1e9 }\nagent a { count 3\n"
     " status s { deposit(f, 1) } }\n", 3, "nodes"),
])
def test_resource_estimates_are_located_at_the_option(tmp_path, capsys, source, line, words):
    rc, out = run_cli(tmp_path, source, "check", capsys=capsys)
    assert rc == 2
    assert re.search(rf"hostile.swarm:{line}:\d+: error: .*{words}", out), out


def test_a_grid_coarser_than_the_world_is_a_warning_at_the_grid(compile_src):
    """Fields on it would hold one value along that side: legal, but surely a slip."""
    prog = compile_src("field f { decay 0.1 }\nworld { size 100 x 300\n grid 200 }\n"
                       "agent a { count 3\n status s { deposit(f, 1) } }\n")
    (warning,) = [str(w) for w in prog.info.warnings]
    assert ":3:2: warning: the grid spacing 200 is larger than the world's width" in warning
    assert compile_src("field f { decay 0.1 }\nworld { size 100 x 300\n grid 100 }\n"
                       "agent a { count 3\n status s { deposit(f, 1) } }\n").info.warnings == []


# ---- deep nesting and long chains ----

DEEP = {
    "not": lambda n: "if " + "not " * n + "true then 1 else 0",
    "neg": lambda n: "-" * n + "1",
    "abs": lambda n: "abs(" * n + "1" + ")" * n,
    "pow": lambda n: " ^ ".join(["1"] * n),
    "if": lambda n: "if true then " * n + "1" + " else 0" * n,
    "vec": lambda n: "(1, " * n + "1" + ")" * n,
}


def _status_with(expr: str) -> str:
    return "agent a {\n  count 3\n  var v = 0\n  status s {\n    v = " + expr + "\n  }\n}\n"


@pytest.mark.parametrize("shape", sorted(DEEP))
@pytest.mark.parametrize("command", ["check", "graph", "run", "test"])
def test_deep_nesting_gives_a_located_error(tmp_path, capsys, shape, command):
    rc, out = run_cli(tmp_path, _status_with(DEEP[shape](3000)), command, capsys=capsys)
    assert rc == 2
    assert re.search(r"hostile.swarm:5:\d+: error: nested too deeply", out), out


@pytest.mark.parametrize("op", ["+", "-", "*", "/"])
def test_long_chains_run_and_keep_left_to_right_arithmetic(backend, tmp_path, op):
    """A 5,000-term chain compiles to one flat closure with exactly the binary result."""
    import numpy as np

    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    terms = [f"{1 + (i % 7) / 3000:.6f}" for i in range(5000)]
    prog = compile_source(_status_with(f" {op} ".join(terms)), "chain.swarm")
    sim = Simulation(prog, seed=0)
    sim.step()
    expected = float(terms[0])
    for t in terms[1:]:
        expected = {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.divide}[op](
            expected, float(t))
    got = sim.agents.cols["v"]
    assert np.array_equal(got, np.full(3, expected), equal_nan=True)


@pytest.mark.parametrize("word", ["and", "or"])
def test_long_logical_chains(backend, tmp_path, capsys, word):
    cond = f" {word} ".join(["v < 1"] * 3000 + ["false"])
    src = ("agent a {\n  count 3\n  var v = 0\n  status s { when " + cond + " -> t }\n"
           "  status t { }\n}\n")
    rc, out = run_cli(tmp_path, src, "run", "--steps", "1", capsys=capsys)
    assert rc == 0, out
    assert ("t 3" if word == "or" else "s 3") in out


def test_deep_nesting_through_the_python_api(tmp_path):
    from swarmdsl import SwarmSyntaxError, load_program

    path = tmp_path / "deep.swarm"
    path.write_text(_status_with(DEEP["not"](5000).replace("true", "v > 0")))
    with pytest.raises(SwarmSyntaxError, match="nested too deeply") as err:
        load_program(path)
    assert err.value.span.line == 5


def test_nesting_at_the_limit_is_accepted_everywhere(backend, tmp_path, capsys):
    """The documented limit is a promise: just under it, every command works."""
    depth = nesting.MAX_NESTING - 12
    for command in ("check", "graph", "run"):
        rc, out = run_cli(tmp_path, _status_with(DEEP["neg"](depth)), command, capsys=capsys)
        assert rc == 0, out


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(st.lists(st.sampled_from(["not ", "-", "abs(", "(", "+", "if true then "]),
                min_size=1, max_size=400))
def test_generated_deep_expressions(backend, tmp_path, capsys, prefix):
    """Random stacks of prefixes: a located error or a clean compile, nothing else."""
    assert_stack_refused_or_run(tmp_path, capsys, prefix, [])


def assert_stack_refused_or_run(tmp_path, capsys, prefix: list[str], tail: list[str]) -> None:
    """The expression `prefix` + 1 + `tail` (brackets closed) is refused with a located
    error (exit 2) or checks and runs a tick."""
    expr = "".join(prefix) + "1" + "".join(tail) + \
        ")" * sum(p in ("abs(", "(", "max(1, ") for p in prefix) + \
        " else 0" * prefix.count("if true then ")
    rc, out = run_cli(tmp_path, _status_with(expr), "check", capsys=capsys)
    assert rc in (0, 2)
    if rc == 2:
        assert LOCATED.search(out), out
    else:
        rc, out = run_cli(tmp_path, _status_with(expr), "run", "--steps", "1",
                          capsys=capsys)
        assert rc in (0, 2), out


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(st.lists(st.sampled_from(["not ", "-", "abs(", "(", "+", "if true then ", "max(1, ",
                                 "1 + ", "2 * ", "2 ^ ", "(1, 1).x + "]),
                min_size=1, max_size=3000),
       st.lists(st.sampled_from([" + 1", " * 1", " - 1", " / 1", " ^ 1", " % 7"]),
                max_size=5000))
def test_long_generated_deep_and_long_expressions(backend, tmp_path, capsys, prefix, tail):
    """The long form: thousands of prefixes and chained terms, mixed."""
    assert_stack_refused_or_run(tmp_path, capsys, prefix, tail)


# ---- other content ----

def test_a_file_that_is_not_utf8_is_refused_at_the_first_bad_byte(tmp_path, capsys):
    path = tmp_path / "latin1.swarm"
    path.write_bytes("agent a {\n  count 3 # caf\u00e9\n".encode("latin-1") + b"}\n")
    assert cli.main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:2:16: error: the file is not UTF-8 text: byte 0xe9" in err


def test_byte_order_mark_is_accepted_and_columns_stay_true(tmp_path, capsys):
    rc, out = run_cli(tmp_path, "\ufeffagent a { count 3; status s { } }\n", "check",
                      capsys=capsys)
    assert rc == 0, out
    rc, out = run_cli(tmp_path, "\ufeffagent a { count zz; status s { } }\n", "check",
                      capsys=capsys)
    assert "hostile.swarm:1:17: error" in out


def test_standard_json_turns_non_finite_numbers_into_null():
    import numpy as np

    from swarmdsl.runtime.jsonsafe import standard_json

    data = {"a": float("nan"), "b": [np.float64("inf"), -float("inf"), 1.5],
            "c": {"d": np.int64(3)}}
    text = json.dumps(standard_json(data), allow_nan=False)
    assert json.loads(text) == {"a": None, "b": [None, None, 1.5], "c": {"d": 3}}


def test_run_json_is_standard_json_when_a_metric_is_nan(backend, tmp_path, capsys):
    src = ("param p = 1e15\nparam q = -0.0\nagent a { count 3; status s { } }\n"
           "metric m = mean(sqrt(-1 - pos.x))\n")
    rc, out = run_cli(tmp_path, src, "run", "--steps", "1", "--out", str(tmp_path / "o"),
                      capsys=capsys)
    assert rc == 0, out
    text = (tmp_path / "o" / "run.json").read_text()
    data = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON: {c}"))
    assert data["params"]["p"] == 1e15
    assert data["metrics"]["m"]["last"] is None  # NaN written as null


# ---- NaN where it is made, and numpy's warnings ----

@pytest.mark.parametrize("body,line,words", [
    ("  status s {\n    let x = sqrt(-1 - pos.x)\n    velocity += (x, 0)\n  }\n", 4,
     "`x` is NaN for agent"),
    ("  status s {\n    let d = (log(-1 - pos.x), 0)\n    velocity += d\n  }\n", 4,
     "`d` is NaN for agent"),
    ("  status s {\n    when log(-1 - pos.x) > 0 -> t\n  }\n  status t { }\n", 4,
     "left side of this comparison is NaN"),
    ("  status s {\n    when 0 < (0 * inf) -> t\n  }\n  status t { }\n", 4,
     "right side of this comparison is NaN"),
    ("  var w = sqrt(-1 - pos.x)\n  status s { }\n", 3,
     "initial value of `w` is NaN"),
    ("  message m num\n  status s {\n    broadcast(m, log(-1 - pos.x))\n  }\n", 5,
     "the broadcast `m` is NaN"),
    ("  velocity (inf - inf + pos.x, 0)\n  status s { }\n", 3, "`velocity` is NaN"),
])
def test_nan_is_reported_where_it_is_made(backend, tmp_path, capsys, body, line, words):
    src = "agent a {\n  count 3\n" + body + "}\n"
    rc, out = run_cli(tmp_path, src, "run", "--steps", "2", capsys=capsys)
    assert rc == 2, out
    assert re.search(rf"hostile.swarm:{line}:\d+: error: .*{re.escape(words)}", out), out
    assert "RuntimeWarning" not in out and ".py:" not in out


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=pytest.mark.skipif(
    importlib.util.find_spec("numba") is None, reason="numba is not installed"))])
@pytest.mark.parametrize("src,where,words", [
    ("agent a { count 3; velocity (1 / (index - 1), 0); status s { } }", "1:29",
     "`velocity` is infinite for agent 1 of `a` while placing agents"),
    ("world { size 100 x 100; edges wrap }\n"
     "agent a { count 3; velocity (1 / (index - 1), 0); status s { } }", "2:29",
     "`velocity` is infinite for agent 1 of `a` while placing agents"),
    ("agent a { count 3; place (50, -1 / (index - 2)); status s { } }", "1:26",
     "`place` is infinite for agent 2 of `a` while placing agents"),
    ("agent a { count 3; heading 1 / (index - 1); status s { } }", "1:28",
     "`heading` is infinite for agent 1 of `a` while placing agents"),
    ("agent a { count 3; var u = 1 / (index - 2); status s { } }", "1:28",
     "the initial value of `u` is infinite for agent 2 of `a` while placing agents"),
    ("agent a { count 3; var v = (0, -1 / index); status s { } }", "1:28",
     "the initial value of `v` is infinite for agent 0 of `a` while placing agents"),
])
def test_an_infinite_initial_value_is_refused_when_placing(tmp_path, capsys, backend, src,
                                                          where, words):
    """As a NaN is: an infinite velocity would carry the agent wall to wall every tick."""
    rc, out = run_cli(tmp_path, src + "\n", "run", "--steps", "3", "--backend", backend,
                      "--out", str(tmp_path / "o"), capsys=capsys)
    assert rc == 2, out
    assert f"hostile.swarm:{where}: error: {words}\n" in out, out
    assert "guard the division" in out and ".py:" not in out


def test_an_infinite_max_speed_is_no_limit_not_an_error(backend, tmp_path, capsys):
    src = "agent a { count 3; max_speed if index == 0 then 2 else inf; status s { } }\n"
    rc, out = run_cli(tmp_path, src, "run", "--steps", "2", "--out", str(tmp_path / "o"),
                      capsys=capsys)
    assert rc == 0, out


def test_nan_inside_a_neighbour_filter_is_each_pairs_own_business(backend, tmp_path, capsys):
    """A NaN that only decides whether a pair counts is not an error of the agent."""
    src = ("agent a {\n  count 20\n  var k = 0\n  status s {\n"
           "    k = count(neighbors(200) where sqrt(-1 - other.pos.x) > 0)\n  }\n}\n")
    rc, out = run_cli(tmp_path, src, "run", "--steps", "2", capsys=capsys)
    assert rc == 0, out


def test_numpy_warnings_are_never_printed(backend, tmp_path):
    """Run as a user would (a subprocess, default warning filters): no internal paths."""
    import os
    import subprocess
    import sys

    path = tmp_path / "w.swarm"
    path.write_text("agent a {\n  count 5\n  var v = 0\n  status s {\n"
                    "    v = min(1 / (pos.x - pos.x), 1)\n  }\n}\n")
    env = dict(os.environ, PYTHONWARNINGS="default")
    proc = subprocess.run([sys.executable, "-m", "swarmdsl", "run", str(path), "--headless",
                           "--steps", "3"], capture_output=True, text=True, env=env,
                          timeout=120)
    assert "Warning" not in proc.stderr and ".py:" not in proc.stderr, proc.stderr
    assert proc.returncode in (0, 2)
