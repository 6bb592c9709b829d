"""`swarmdsl test` shrinks to the smallest failing swarm, and its replays are exact.

The buggy programs are generated with a known minimum: a crowd of `k` agents of kind
`a` within `r` of one of them breaks an invariant, and nothing else does, so the
smallest failing swarm has exactly `k` agents (and no agent of the bystander kind).
"""

from __future__ import annotations

import json
import shlex

import numpy as np
import pytest
from conftest import WALK, shipped
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.testing import search

CROWD = """param n = 10 in 1..14
param m = 3 in 0..4
param r = {r}
world {{ size 120 x 90; edges wrap }}
agent a {{
  count n
  var crowd = 0
  var heat = uniform(0, 2)
  status idle {{ crowd = count(neighbors(r) where other.kind == a) }}
  invariant calm: crowd < {k1}
}}
agent b {{
  count m
  velocity random_direction() * 0.3
  status roam {{ }}
}}
"""


def crowd_program(k: int, r: float = 4.0) -> str:
    """Fails iff some `a` has k-1 other `a`s within r: at least k agents of kind a."""
    return CROWD.format(k1=k - 1, r=r)


def _hunt(k: int, seed: int):
    """A hunt of a few ticks: the invariant breaks at tick 1 or never (`a` stands
    still). The budget only ends a hunt that hangs, never decides the verdict."""
    return search(crowd_program(k), max_examples=150, time_budget=600, steps=3,
                  hypothesis_seed_value=seed).counterexample


@pytest.mark.parametrize(("k", "seed"), [(2, 0), (4, 2)])   # k = 3: the replay test below
def test_shrinks_to_exactly_k_agents(backend, k, seed):
    ce = _hunt(k, seed)
    assert ce is not None
    kinds = [a.kind for a in ce.example.layout.agents]
    assert ce.agents == k and kinds == ["a"] * k, ce.describe("crowd.swarm")
    (v,) = ce.violations
    assert v.name == "a.calm" and v.tick == 1


def test_the_time_budget_ends_a_hunt_asked_for_a_huge_number_of_runs(backend):
    # Past the budget no run is made, but hypothesis went on drawing swarms up to
    # max_examples: `--examples 100000 --time-budget 1` took minutes and grew memory.
    import time

    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    never = ("param n = 5 in 1..10\nworld { size 40 x 40 }\n"
             "agent a {\n  count n\n  status s { }\n  invariant ok: true\n}\n")
    Simulation(compile_source(never, "never.swarm"), 0).run(1)   # compiled: not timed
    t0 = time.perf_counter()
    report = search(never, max_examples=20_000, time_budget=0.5, hypothesis_seed_value=0)
    assert report.counterexample is None
    assert time.perf_counter() - t0 < 10


@pytest.mark.slow
def test_shrinks_to_exactly_k_agents_in_most_hunts(backend):
    hits = total = 0
    for k in (2, 3, 4, 5):
        for seed in range(5):
            ce = _hunt(k, 100 + seed)
            total += 1
            hits += ce is not None and ce.agents == k
    assert hits / total >= 0.8, f"{hits}/{total} hunts reached the minimum"


def _replay(tmp_path, capsys, argv):
    out = tmp_path / "replay"
    code = main([*argv, "--out", str(out)])
    err = capsys.readouterr().err
    return code, json.loads((out / "run.json").read_text()), err


@pytest.mark.parametrize(("k", "seed"), [(2, 3), (3, 4)])
def test_the_printed_command_and_the_saved_example_replay_the_failure(backend, tmp_path,
                                                                      capsys, monkeypatch,
                                                                      k, seed):
    path = tmp_path / "crowd.swarm"
    path.write_text(crowd_program(k, r=5.0))
    case = tmp_path / "case.json"
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    assert main(["test", str(path), "--quiet", "--set", "r=5", "--hypothesis-seed",
                 str(seed), "--steps", "3", "--save-example", str(case)]) == 1
    out = capsys.readouterr().out
    assert not (tmp_path / ".hypothesis").exists()
    saved = json.loads(case.read_text())
    assert saved["params"]["r"] == "5"           # fixed params are part of the replay
    failure = saved["failure"]
    (line,) = [x for x in out.splitlines() if x.strip().startswith("reproduce:")]
    argv = shlex.split(line.split("reproduce:", 1)[1])
    assert argv[:2] == ["swarmdsl", "run"] and "--example" in argv
    code, run_json, err = _replay(tmp_path, capsys, argv[1:])
    assert code == 1
    v = run_json["violation"]
    assert (v["property"], v["tick"], v["agents"]) == (failure["property"], failure["tick"],
                                                      failure["agents"])
    assert run_json["finished"] == "violation" and run_json["last_tick"] == v["tick"]
    assert run_json["agents"] == k
    assert f"violated at tick {v['tick']} for agent" in err
    # without the example, the same seed and params give another swarm
    code, _, _ = _replay(tmp_path, capsys, ["run", str(path), "--headless", "--check",
                                            "--steps", str(v["tick"]), "--seed",
                                            str(saved["seed"]), "--set", f"n={k}",
                                            "--set", "m=0"])
    assert code == 0


def test_the_report_counts_search_and_shrinking_apart(backend, tmp_path, capsys, monkeypatch):
    path = tmp_path / "crowd.swarm"
    path.write_text(crowd_program(3))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    # no bystanders (`--set m=0`): the hunt shrinks in 137 runs, not 238
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "5", "--steps", "3",
                 "--set", "m=0"]) == 1
    out = capsys.readouterr().out
    head = out.splitlines()[0]
    assert "counterexample found after " in head and " more (" in head
    found = int(head.split("found after ")[1].split(" run")[0])
    assert found >= 1 and "shrunk in" in head
    # every starting agent is listed with its initial state
    agents = [x for x in out.splitlines() if x.strip().startswith("agent ")]
    assert len(agents) == 3 and all("pos=(" in a and "crowd=0" in a for a in agents)
    # with no --save-example the example goes to the user cache folder
    saved = list((tmp_path / "cache" / "swarmdsl" / "examples").glob("crowd-*.json"))
    assert len(saved) == 1 and str(saved[0]) in out
    assert not (tmp_path / ".hypothesis").exists()


ALWAYS_FAILS = ("world { size 10 x 10 }\nagent a { count 1; var t = 0\n"
                "  status s { t = t + 1 }\n  invariant low: t < 1 }\n")


def test_save_example_into_a_missing_folder_creates_it(backend, tmp_path, capsys, monkeypatch):
    path = tmp_path / "low.swarm"
    path.write_text(ALWAYS_FAILS)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    case = tmp_path / "new" / "cases" / "case.json"
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "0", "--examples", "5",
                 "--save-example", str(case)]) == 1
    out = capsys.readouterr().out
    assert json.loads(case.read_text())["failure"]["property"] == "a.low"
    assert f"--example {case}" in out


def test_a_failed_save_still_prints_the_counterexample(backend, tmp_path, capsys, monkeypatch):
    import errno

    from swarmdsl.runtime import outputs

    def replace_with(path, write):
        raise OSError(errno.ENOSPC, "No space left on device")

    path = tmp_path / "low.swarm"
    path.write_text(ALWAYS_FAILS)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setattr(outputs, "replace_with", replace_with)
    case = tmp_path / "case.json"
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "0", "--examples", "5",
                 "--save-example", str(case)]) == 2
    captured = capsys.readouterr()
    assert "counterexample found after" in captured.out
    assert "invariant `a.low` violated at tick 1 for agent 0" in captured.out
    assert "agent 0 (a, s): pos=(" in captured.out
    assert f"--save-example {case}: cannot write: No space left on device" in captured.err
    assert "reproduce:" not in captured.out and not case.exists()


def test_an_unwritable_cache_folder_still_prints_the_counterexample(backend, tmp_path,
                                                                     capsys, monkeypatch):
    path = tmp_path / "low.swarm"
    path.write_text(ALWAYS_FAILS)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cache").write_text("a file, not a folder")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "0", "--examples", "5"]) == 1
    captured = capsys.readouterr()
    assert "invariant `a.low` violated at tick 1 for agent 0" in captured.out
    assert "warning: the example was not saved: " in captured.err
    assert "cannot write" in captured.err


def test_run_reports_a_violation_with_its_tick_and_plural(backend, tmp_path, capsys):
    path = tmp_path / "count.swarm"
    path.write_text("world { size 10 x 10 }\nagent a { count 1; var t = 0\n"
                    "  status s { t = t + 1 }\n  invariant low: t < 1 }\n")
    assert main(["run", str(path), "--headless", "--steps", "5", "--check",
                 "--out", str(tmp_path / "o")]) == 1
    captured = capsys.readouterr()
    assert "stopped by a property violation after 1 tick of 1 agent " in captured.out
    assert "violated at tick 1 for agent 0" in captured.err
    run_json = json.loads((tmp_path / "o" / "run.json").read_text())
    assert run_json["violation"]["tick"] == 1 and run_json["last_tick"] == 1


def test_run_property_option_checks_only_that_property(backend, tmp_path, capsys):
    path = tmp_path / "two.swarm"
    path.write_text("world { size 10 x 10 }\nagent a { count 2; var t = 0\n"
                    "  status s { t = t + 1 }\n  invariant low: t < 2\n"
                    "  invariant lower: t < 1 }\n")
    assert main(["run", str(path), "--headless", "--steps", "5", "--property", "low"]) == 1
    assert "`a.low` violated at tick 2" in capsys.readouterr().err
    assert main(["run", str(path), "--headless", "--steps", "5", "--property", "nope"]) == 2
    assert "--property nope: no such property (the program has: a.low, a.lower)" in \
        capsys.readouterr().err


def test_a_bad_example_file_is_an_option_error(tmp_path, capsys):
    path = tmp_path / "p.swarm"
    path.write_text("world { size 10 x 10 }\nagent a { count 1; status s { } }\n")
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2]")
    assert main(["run", str(path), "--headless", "--example", str(bad)]) == 2
    assert "not a saved example" in capsys.readouterr().err
    bad.write_text('{"format": "swarmdsl-example-1", "params": {}, "seed": 0, "steps": 2, '
                   '"layout": '
                   '{"kinds": ["a"], "agents": [{"kind": "a", "id": 1}, {"kind": "a", '
                   '"id": 1}]}}')
    assert main(["run", str(path), "--headless", "--example", str(bad)]) == 2
    assert "distinct" in capsys.readouterr().err


LONER = """world { size 60 x 60; edges wrap }
agent walker { count 8; velocity random_direction()
  var t = uniform(0, 5)
  status go { velocity = velocity + (normal(0, 0.3), normal(0, 0.3)); t = t + random()
    when chance(0.1) -> rest }
  status rest { velocity = (0, 0); when random() < 0.3 -> go } }
"""


@settings(max_examples=10, deadline=None)
@given(keep=st.sets(st.integers(0, 7), min_size=1, max_size=7), seed=st.integers(0, 999))
def test_a_layout_of_some_agents_replays_their_paths_in_the_full_swarm(backend, keep, seed):
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.layout import AgentSpec, Layout
    from swarmdsl.runtime.simulation import Simulation

    full = Simulation(compile_source(LONER, "l.swarm"), seed, backend=backend)
    layout = Layout(tuple(AgentSpec("walker", i) for i in sorted(keep)), ("walker",))
    text = LONER.replace("count 8", f"count {len(keep)}")
    part = Simulation(compile_source(text, "l.swarm"), seed, layout, backend=backend)
    assert_part_follows_full(full, part, keep, ("pos", "vel", "t", "status"))


def assert_part_follows_full(full, part, keep, cols, ticks=10):
    """Agents `keep` of the whole swarm `full` and the swarm `part` of only them take the
    same paths, tick by tick."""
    from swarmdsl.testing import state_arrays

    for _ in range(ticks):
        full.step()
        part.step()
        a, b = state_arrays(full), state_arrays(part)
        rows = np.isin(a["id"], sorted(keep))
        assert np.array_equal(a["id"][rows], b["id"])
        for col in cols:
            assert np.array_equal(a[col][rows], b[col]), col


LINED = """world { size 60 x 60; edges wrap }
agent walker { count 8; velocity random_direction() * (1 + index / 4)
  var t = uniform(0, 5) + index
  initial if index == 0 then rest else go
  status go { velocity = velocity + (normal(0, 0.3), normal(0, 0.3)); t = t + random()
    when chance(0.1) -> rest }
  status rest { velocity = (0, 0); when random() < 0.3 or t > index + 6 -> go } }
"""


@settings(max_examples=10, deadline=None)
@given(keep=st.sets(st.integers(0, 7), min_size=1, max_size=7), seed=st.integers(0, 999))
def test_a_part_of_a_constant_count_swarm_replays_its_paths_in_the_full_swarm(backend, keep,
                                                                              seed):
    """The program is unchanged (`count 8`): the layout's agents keep their ids and
    indexes, so a program reading `index` runs them as in the whole swarm."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.layout import AgentSpec, Layout
    from swarmdsl.runtime.simulation import Simulation

    prog = compile_source(LINED, "l.swarm")
    full = Simulation(prog, seed, backend=backend)
    layout = Layout(tuple(AgentSpec("walker", i, index=i) for i in sorted(keep)),
                    ("walker",))
    layout = Layout.from_json(json.loads(json.dumps(layout.to_json())))   # as saved
    part = Simulation(prog, seed, layout, backend=backend)
    assert part.agents.n == len(keep)
    assert_part_follows_full(full, part, keep, ("pos", "vel", "t", "status", "index"))


def test_a_layout_with_more_agents_than_the_count_is_an_option_error():
    from swarmdsl.compiler import compile_source
    from swarmdsl.compiler.errors import SwarmOptionError
    from swarmdsl.runtime.layout import AgentSpec, Layout
    from swarmdsl.runtime.simulation import Simulation

    layout = Layout(tuple(AgentSpec("walker", i) for i in range(9)), ("walker",))
    with pytest.raises(SwarmOptionError, match="9 agents of `walker`, the program "
                                               "places at most 8"):
        Simulation(compile_source(LINED, "l.swarm"), 0, layout)
    with pytest.raises(SwarmOptionError, match=r'layout.agents\[0\]: "index": -1 is not a '
                                               "whole number from 0"):
        Layout.from_json({"kinds": ["walker"], "agents": [{"kind": "walker", "id": 0,
                                                            "index": -1}]})


FAILING = {
    "always": """param n = 6 in 1..8
world { size 30 x 30 }
agent a {
  count n
  velocity random_direction()
  var asked = false
  var told = false
  status s { asked = chance(0.3); told = chance(0.2) }
  always answered: asked -> eventually told within 2
}
""",
    "swarm_eventually": """param n = 6 in 1..8
param goal = 3 in 1..6
world { size 30 x 30 }
agent a {
  count n
  var t = uniform(0, 4)
  status s { t = t + random() }
}
eventually reached within 3: all(t > goal)
""",
    "fault": """param n = 6 in 1..8
world { size 30 x 30 }
agent a {
  count n
  var w = 0
  status s { let near = neighbors(2); w = sum(near : dist) / count(near) }
  invariant fine: w >= 0
}
""",
}


# the same failures in kinds drawn as a part of their count (constant, or an expression)
FAILING["always_constant"] = FAILING["always"].replace("count n", "count 6")
FAILING["swarm_eventually_constant"] = FAILING["swarm_eventually"].replace("count n",
                                                                           "count 6")
FAILING["fault_expression"] = FAILING["fault"].replace("count n", "count 2 * n - 1")


@pytest.mark.parametrize("name", sorted(FAILING))
def test_saved_examples_replay_every_kind_of_failure(backend, tmp_path, capsys, monkeypatch,
                                                     name):
    path = tmp_path / f"{name}.swarm"
    path.write_text(FAILING[name])
    case = tmp_path / "case.json"
    monkeypatch.chdir(tmp_path)
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "0", "--examples", "40",
                 "--save-example", str(case)]) == 1
    capsys.readouterr()
    failure = json.loads(case.read_text())["failure"]
    code, run_json, err = _replay(tmp_path, capsys, ["run", str(path), "--headless",
                                                     "--example", str(case)])
    if "fault" in failure:
        assert code == 2 and run_json["finished"] == "fault"
        assert failure["fault"].split("error: ", 1)[1] in err
        return
    assert code == 1
    v = run_json["violation"]
    assert (v["property"], v["tick"], v["agents"]) == (failure["property"], failure["tick"],
                                                      failure["agents"])
    assert v["message"] == failure["message"]


FITTED = """param n = 3 in 1..8
world { size 30 x 30 }
agent a {
  count n
  velocity random_direction()
  var t = uniform(0, 4)
  var f = chance(0.5)
  var v = (1, 2)
  status s { t = t + random() }
  invariant low: t < 50
}
"""


def _fitted_example(tmp_path):
    """A program and a well-formed example of it, as `swarmdsl test` saves one."""
    import hashlib

    path = tmp_path / "fitted.swarm"
    path.write_text(FITTED)
    data = {"format": "swarmdsl-example-1", "program": "fitted.swarm",
            "sha256": hashlib.sha256(FITTED.encode()).hexdigest(), "params": {"n": "3"},
            "seed": 0, "steps": 4, "properties": None,
            "layout": {"kinds": ["a"], "agents": [
                {"kind": "a", "id": 0, "index": 0, "pos": [1.5, 2.5],
                 "vars": {"t": 1.0, "f": True, "v": [1.0, 2.0]}},
                {"kind": "a", "id": 2, "index": 2}]},
            "failure": None}
    return path, data


def _agent(**entries):
    def change(d):
        d["layout"]["agents"][0].update(entries)
    return change


def _drop(*keys):
    def change(d):
        *inner, last = keys
        for k in inner:
            d = d[k]
        del d[last]
    return change


def _set(key, value):
    def change(d):
        d[key] = value
    return change


def _layout(kinds, agents):
    return _set("layout", {"kinds": kinds, "agents": agents})


MALFORMED = {
    "unknown kind": (_agent(kind="zzz"), 'layout.agents[0]: kind "zzz" is not in '
                     "layout.kinds (a)"),
    "kind the program lacks": (_layout(["a", "zzz"], [{"kind": "zzz", "id": 5}]),
                               'layout.kinds: no agent kind "zzz" in '),
    "status entry": (_agent(status="zzz"), 'layout.agents[0]: unknown entry "status" '
                     "(an agent has kind, id, index, pos, vars)"),
    "status as a variable": (_agent(vars={"status": 3}), '(id 0, a): "status" is not a '
                             "variable of `a` (its variables: t, f, v)"),
    "long position": (_agent(pos=[1, 2, 3]), '"pos" must be two finite numbers [x, y], '
                      "got [1, 2, 3]"),
    "NaN position": (_agent(pos=[float("nan"), 2]), '"pos" must be two finite numbers'),
    "short vector": (_agent(vars={"v": [1]}), "variable v: [1] is not a value"),
    "text value": (_agent(vars={"t": "abc"}), 'variable t: "abc" is not a value'),
    "bool for a number": (_agent(vars={"t": True}), "variable t is a num, not true"),
    "number for a bool": (_agent(vars={"f": 0.5}), "variable f is a bool, not 0.5"),
    "position outside": (_agent(pos=[100, 2]), "pos [100, 2] is outside the world "
                         "(30 x 30)"),
    "index past the count": (_agent(index=7), "index 7 is not below the count of `a`, 3"),
    "too many agents": (_layout(["a"], [{"kind": "a", "id": i} for i in range(4)]),
                        "layout: 4 agents of `a`, the program places at most 3"),
    "no seed": (_drop("seed"), 'no "seed" entry'),
    "no params": (_drop("params"), 'no "params" entry'),
    "no agent id": (_drop("layout", "agents", 0, "id"), 'layout.agents[0]: no "id" entry'),
    "negative seed": (_set("seed", -5), '"seed": -5 is not a whole number from 0'),
    "fractional steps": (_set("steps", 1.5), '"steps": 1.5 is not a whole number from 0'),
    "text id": (_agent(id="x"), 'layout.agents[0]: "id": "x" is not a whole number'),
    "param not a number": (_set("params", {"n": "abc"}), "param n=abc: `abc` is not a "
                           "number"),
    "param out of range": (_set("params", {"n": "99"}), "param n=99: outside the declared "
                           "range 1..8"),
    "unknown param": (_set("params", {"n": "3", "zz": "1"}), "param zz=1: the program has "
                      "no param `zz` (params: n)"),
    "null param": (_set("params", {"n": None}), "param n: null is not a param value"),
    "unknown property": (_set("properties", ["nope"]), 'properties: no property "nope" in '),
    "unknown entry": (_set("note", "hi"), 'unknown entry "note" (an example has format,'),
}


def test_the_well_formed_example_replays(backend, tmp_path, capsys):
    """The example every malformed one below is a change of runs as it is."""
    path, data = _fitted_example(tmp_path)
    case = tmp_path / "case.json"
    case.write_text(json.dumps(data))
    assert main(["run", str(path), "--headless", "--example", str(case)]) == 0
    assert "ran 4 ticks" in capsys.readouterr().out


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_a_malformed_example_is_an_error_naming_example_and_entry(tmp_path, capsys, name):
    """Refused before the run starts, on any backend (the well-formed example runs:
    above)."""
    change, message = MALFORMED[name]
    path, data = _fitted_example(tmp_path)
    case = tmp_path / "case.json"
    change(data)
    case.write_text(json.dumps(data))
    capsys.readouterr()
    assert main(["run", str(path), "--headless", "--example", str(case)]) == 2
    captured = capsys.readouterr()
    assert f"error: --example {case}: " in captured.err
    assert message in captured.err
    assert "--set" not in captured.err and "Traceback" not in captured.err
    assert "ran " not in captured.out


def test_a_saved_example_with_an_agent_of_an_unknown_kind_is_refused(backend, tmp_path,
                                                                      capsys, monkeypatch):
    path = tmp_path / "low.swarm"
    path.write_text(ALWAYS_FAILS)
    monkeypatch.chdir(tmp_path)
    case = tmp_path / "case.json"
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "0", "--examples", "5",
                 "--save-example", str(case)]) == 1
    data = json.loads(case.read_text())
    data["layout"] = {"kinds": ["a"], "agents": [{"kind": "zzz", "id": 0}]}
    case.write_text(json.dumps(data))
    capsys.readouterr()
    assert main(["run", str(path), "--headless", "--example", str(case)]) == 2
    captured = capsys.readouterr()
    assert f'error: --example {case}: layout.agents[0]: kind "zzz"' in captured.err
    assert "ran " not in captured.out


def test_an_example_of_another_program_is_warned_about_with_both_hashes(backend, tmp_path,
                                                                         capsys):
    import hashlib

    path, data = _fitted_example(tmp_path)
    case = tmp_path / "case.json"
    case.write_text(json.dumps(data))
    assert main(["run", str(path), "--headless", "--example", str(case)]) == 0
    assert "--example" not in capsys.readouterr().err
    data.update(sha256="ab" * 32, program="other.swarm")
    case.write_text(json.dumps(data))
    assert main(["run", str(path), "--headless", "--example", str(case)]) == 0
    now = hashlib.sha256(FITTED.encode()).hexdigest()[:12]
    assert (f"warning: --example {case} was saved for another version of the program; "
            "the replay may differ (it records sha256 abababababab of other.swarm, "
            f"fitted.swarm has sha256 {now})") in capsys.readouterr().err
    # and when its params or kinds do not fit, the error says why they might not
    data["params"] = {"n": "3", "speed": "2"}
    case.write_text(json.dumps(data))
    assert main(["run", str(path), "--headless", "--example", str(case)]) == 2
    err = capsys.readouterr().err
    assert f"error: --example {case}: param speed=2: the program has no param" in err
    assert "hint: the example was saved for another program (it records sha256 " in err


def test_a_program_with_crlf_line_ends_is_the_one_its_example_was_saved_for(backend,
                                                                           tmp_path, capsys):
    path = tmp_path / "crlf.swarm"
    path.write_bytes(ALWAYS_FAILS.replace("\n", "\r\n").encode())
    case = tmp_path / "case.json"
    assert main(["test", str(path), "--quiet", "--hypothesis-seed", "0", "--examples", "5",
                 "--save-example", str(case)]) == 1
    capsys.readouterr()
    assert main(["run", str(path), "--headless", "--example", str(case)]) == 1
    assert "--example" not in capsys.readouterr().err


def test_a_counterexample_prints_whole_values_whole_and_others_readably(backend):
    """`led=5.26344e+06` hid the value's last digits (it was 5263440)."""
    ce = search("world { size 20 x 20 }\nagent a {\n  count 1\n  var code = 5263440\n"
                "  var f = 1234567.25\n  var tiny = 0.000012\n  status s { }\n"
                "  invariant small: code < 100\n}\n", max_examples=2,
                hypothesis_seed_value=0).counterexample
    (line,) = [x for x in ce.describe("t.swarm").splitlines() if x.strip().startswith("agent 0 (")]
    assert "code=5263440," in line and "f=1234567.2" in line and "tiny=1.2e-05" in line


@given(st.one_of(st.integers(-2**53 + 1, 2**53 - 1).map(float),
                 st.floats(allow_nan=False, allow_infinity=False)))
def test_number_text_is_whole_for_whole_numbers_and_close_otherwise(x):
    from swarmdsl.testing.search import number_text

    text = number_text(x)
    if x == int(x) and abs(x) < 2**53:
        assert text == str(int(x))
    assert float(text) == pytest.approx(x, rel=1e-5, abs=1e-300)
    if 1e-4 <= abs(x) < 1e16:
        assert "e" not in text


def test_a_tiny_time_budget_still_tries_one_run(backend, tmp_path, capsys):
    """`--time-budget 0.001` reported "no counterexample to 1 property in 0 runs" and
    exit 0: a pass for a program it never ran."""
    path = tmp_path / "checked.swarm"
    path.write_text(WALK.read_text().replace("  metric",
                                             "  invariant counted: laps >= 0\n  metric"))
    assert main(["test", str(path), "--time-budget", "0.001", "--quiet", "--seeds", "0"]) == 0
    assert "no counterexample to 1 property in 1 run of up to" in capsys.readouterr().out
    # the runs of the program as written are made whatever the budget
    assert main(["test", str(path), "--time-budget", "0.001", "--quiet"]) == 0
    assert "in 3 runs of up to 20 ticks: 3 of the program as written (6 agents, seeds " \
        "0-2) (" in capsys.readouterr().out


def test_a_seeded_hunt_is_the_same_whatever_ran_before_it(backend, tmp_path, monkeypatch):
    """The same seed gave another hunt after other work in the process (168 runs instead
    of 162 after 5 ticks of aco.swarm): hypothesis drew literals from the source of the
    modules imported so far, and that run had imported more of swarmdsl. A module of the
    user's own imported between two hunts (new to the process, whatever ran before this
    test) did the same."""
    import importlib.util
    import random
    import sys

    def hunt():
        report = search(crowd_program(2), max_examples=150, time_budget=600, steps=3,
                        hypothesis_seed_value=1)
        assert report.counterexample is not None
        return report.examples, report.shrink_runs, report.counterexample.example

    first = hunt()
    shipped("spring1d.swarm").run(5)
    helper = tmp_path / "swarm_helpers.py"
    rng = random.Random(backend)    # literals new to the process on each backend
    levels = [round(rng.uniform(0, 90), 4) for _ in range(8)] + rng.sample(range(99), 4)
    helper.write_text(f"LEVELS = {tuple(levels)!r}\n")
    spec = importlib.util.spec_from_file_location("swarm_helpers", helper)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "swarm_helpers", module)
    spec.loader.exec_module(module)
    assert hunt() == first
