"""A layout handed to the Python API is checked as `run --example` checks a saved one.

Its shape when it is built (`Layout(...)`, `Layout.from_json`), its fit to the program
before a `Simulation` places anyone; each refusal is a `SwarmOptionError` naming the
entry, the same words the `--example` replay prints after the file's name.
"""

from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl import SwarmOptionError
from swarmdsl.cli import main
from swarmdsl.compiler import compile_source
from swarmdsl.runtime.layout import AgentSpec, Layout
from swarmdsl.runtime.runner import Run
from swarmdsl.runtime.simulation import Simulation
from swarmdsl.testing import run_program, state_arrays

SOURCE = """world { size 30 x 20 }
agent a {
  count 5
  var t = uniform(0, 4)
  var f = chance(0.5)
  var v = (1, 2)
  status s { t = t + random() }
}
agent b { count 3; status s { } }
"""
COUNTS = {"a": 5, "b": 3}


@pytest.fixture(scope="module")
def program():
    return compile_source(SOURCE, "two.swarm")


def _json(*agents, kinds=("a",)):
    return {"kinds": list(kinds), "agents": list(agents)}


# (layout JSON, the message the API and the --example replay both give)
SHAPE = {
    "agent of a kind not listed": (_json({"kind": "zzz", "id": 0}),
                                   'layout.agents[0]: kind "zzz" is not in layout.kinds (a)'),
    "duplicate ids": (_json({"kind": "a", "id": 3}, {"kind": "a", "id": 3}),
                      "layout.agents[1]: id 3 is also layout.agents[0]'s; agent ids must "
                      "be distinct"),
    "duplicate indexes": (_json({"kind": "a", "id": 0, "index": 2},
                                {"kind": "a", "id": 1, "index": 2}),
                          "layout.agents[1]: index 2 is also layout.agents[0]'s"),
    "negative id": (_json({"kind": "a", "id": -1}),
                    'layout.agents[0]: "id": -1 is not a whole number from 0'),
    "NaN position": (_json({"kind": "a", "id": 0, "pos": [float("nan"), 1]}),
                     'layout.agents[0]: "pos" must be two finite numbers [x, y], got '
                     "[NaN, 1]"),
    "infinite position": (_json({"kind": "a", "id": 0, "pos": [1, float("inf")]}),
                          'layout.agents[0]: "pos" must be two finite numbers'),
    "text value": (_json({"kind": "a", "id": 0, "vars": {"t": "hot"}}),
                   'layout.agents[0]: variable t: "hot" is not a value'),
    "kind listed twice": (_json(kinds=("a", "a")), 'layout.kinds lists a kind twice'),
    "no id": (_json({"kind": "a"}), 'layout.agents[0]: no "id" entry'),
    "unknown agent entry": (_json({"kind": "a", "id": 0, "speed": 2}),
                            'layout.agents[0]: unknown entry "speed" (an agent has kind, '
                            "id, index, pos, vars)"),
}

FIT = {
    "kind the program lacks": (_json({"kind": "zzz", "id": 0}, kinds=("a", "zzz")),
                               'layout.kinds: no agent kind "zzz" in two.swarm (kinds: a, '
                               "b)"),
    "unknown variable": (_json({"kind": "a", "id": 0}, {"kind": "a", "id": 5,
                                                        "vars": {"heat": 1}}),
                         'layout.agents[1] (id 5, a): "heat" is not a variable of `a` (its '
                         "variables: t, f, v)"),
    "number for a bool": (_json({"kind": "a", "id": 0, "vars": {"f": 0.5}}),
                          "layout.agents[0] (id 0, a): variable f is a bool, not 0.5"),
    "vector for a number": (_json({"kind": "a", "id": 0, "vars": {"t": [1, 2]}}),
                            "layout.agents[0] (id 0, a): variable t is a num, not [1.0, 2.0]"),
    "position outside": (_json({"kind": "a", "id": 7, "pos": [31, 2]}),
                         "layout.agents[0] (id 7, a): pos [31, 2] is outside the world "
                         "(30 x 20)"),
    "index past the count": (_json({"kind": "b", "id": 0, "index": 3}, kinds=("b",)),
                             "layout.agents[0] (id 0, b): index 3 is not below the count "
                             "of `b`, 3"),
    "id of an agent the program places": (
        _json({"kind": "b", "id": 2}, kinds=("b",)),
        "layout.agents[0] (id 2, b): id 2 is also an agent of `a`'s, which the layout "
        "leaves to the program (ids 0 to 4); agent ids must be distinct"),
    "too many agents": (_json(*({"kind": "b", "id": i} for i in range(4)), kinds=("b",)),
                        "layout: 4 agents of `b`, the program places at most 3"),
}


def _message(err) -> str:
    return err.value.message


@pytest.mark.parametrize("name", sorted(SHAPE))
def test_a_malformed_layout_is_refused_by_from_json_naming_the_entry(name):
    data, message = SHAPE[name]
    with pytest.raises(SwarmOptionError) as err:
        Layout.from_json(json.loads(json.dumps(data)))
    assert _message(err) == message or _message(err).startswith(message)


@pytest.mark.parametrize("name", sorted(FIT))
def test_a_layout_that_does_not_fit_is_refused_by_the_simulation(program, name):
    data, message = FIT[name]
    layout = Layout.from_json(data)       # well-formed: only the program can refuse it
    with pytest.raises(SwarmOptionError) as err:
        Simulation(program, 0, layout)
    assert _message(err) == message


@pytest.mark.parametrize("name", sorted({**SHAPE, **FIT}))
def test_the_api_and_the_example_replay_give_the_same_message(tmp_path, capsys, name):
    """`--example` adds its file's name and nothing else: one rule, one wording."""
    data, message = {**SHAPE, **FIT}[name]
    path = tmp_path / "two.swarm"
    path.write_text(SOURCE)
    case = tmp_path / "case.json"
    case.write_text(json.dumps({"format": "swarmdsl-example-1", "params": {}, "seed": 0,
                                "steps": 1, "layout": data,
                                "sha256": hashlib.sha256(SOURCE.encode()).hexdigest()}))
    assert main(["run", str(path), "--headless", "--example", str(case)]) == 2
    captured = capsys.readouterr()
    message = message.replace("in two.swarm", f"in {path}")  # the program as compiled
    (error,) = [line for line in captured.err.splitlines() if line.startswith("error:")]
    assert error.startswith(f"error: --example {case}: {message}")
    after = captured.err[captured.err.index("error: --example"):]   # the program's
    assert "saved for another" not in after and "hint" not in after  # warnings come first
    assert "Traceback" not in captured.err and "ran " not in captured.out


def test_a_layout_built_in_python_is_checked_as_one_read_from_json(program):
    with pytest.raises(SwarmOptionError, match=r"layout.agents\[1\]: id 4 is also "
                                               r"layout.agents\[0\]'s"):
        Layout((AgentSpec("a", 4), AgentSpec("a", 4)), ("a",))
    with pytest.raises(SwarmOptionError, match=r'layout.agents\[0\]: "pos" must be two '
                                               r"finite numbers \[x, y\], got \[NaN, 1.0\]"):
        Layout((AgentSpec("a", 0, (math.nan, 1.0)),), ("a",))
    with pytest.raises(SwarmOptionError, match=r'layout.agents\[0\]: kind "b" is not in '
                                               r"layout.kinds \(a\)"):
        Layout((AgentSpec("b", 0),), ("a",))
    with pytest.raises(SwarmOptionError, match=r"layout.agents\[0\] must be an AgentSpec, "
                                               r'got \{"kind": "a", "id": 0\}'):
        Layout(({"kind": "a", "id": 0},), ("a",))


def test_an_agent_of_a_kind_the_program_lacks_is_refused_not_dropped(program):
    layout = Layout((AgentSpec("a", 0), AgentSpec("ghost", 1)), ("a", "ghost"))
    with pytest.raises(SwarmOptionError, match='no agent kind "ghost" in two.swarm'):
        Simulation(program, 0, layout)


def test_from_json_names_where_the_layout_came_from():
    with pytest.raises(SwarmOptionError) as err:
        Layout.from_json(_json({"kind": "a", "id": 1}, {"kind": "a", "id": 1}), "swarm.json")
    assert _message(err).startswith("swarm.json: layout.agents[1]: id 1 is also")
    with pytest.raises(SwarmOptionError) as err:
        Layout.from_json([1, 2], "swarm.json")
    assert _message(err) == ('swarm.json: layout must be an object with "kinds" and '
                             '"agents", got [1, 2]')


def test_something_other_than_a_layout_is_refused_by_the_simulation(program):
    with pytest.raises(SwarmOptionError, match="the layout must be a swarmdsl Layout "
                                               r"\(Layout.from_json reads one\), got dict"):
        Simulation(program, 0, _json({"kind": "a", "id": 0}))


def test_every_entry_point_that_takes_a_layout_refuses_a_misfit(program, tmp_path):
    """`Run` refuses it before its outputs exist, `run_program` before any tick."""
    layout = Layout.from_json(FIT["unknown variable"][0])
    out = tmp_path / "out"
    with pytest.raises(SwarmOptionError, match='"heat" is not a variable of `a`'):
        Run(program, seed=0, steps=2, out=out, layout=layout)
    assert not out.exists()
    with pytest.raises(SwarmOptionError, match='"heat" is not a variable of `a`'):
        run_program(program, 2, layout=layout)


def test_numpy_values_are_accepted_as_python_ones(backend, program):
    """The API is often fed from arrays: numpy ids, positions and values fit."""
    layout = Layout((AgentSpec("a", np.int64(9), (np.float64(1.5), np.float32(2.0)),
                               (("f", np.bool_(True)), ("t", np.float64(0.5))),
                               np.int64(1)),), ("a",))
    sim = Simulation(program, 0, layout)
    s = state_arrays(sim)
    row = int(np.flatnonzero(s["id"] == 9)[0])
    assert s["index"][row] == 1 and tuple(s["pos"][row]) == (1.5, 2.0)
    assert bool(s["f"][row]) and s["t"][row] == 0.5


def _values(kind: str):
    if kind == "b":
        return st.just(())
    options = st.fixed_dictionaries({}, optional={
        "t": st.floats(-1e6, 1e6, allow_nan=False),
        "f": st.booleans(),
        "v": st.tuples(st.floats(-1e6, 1e6, allow_nan=False),
                       st.floats(-1e6, 1e6, allow_nan=False))})
    return options.map(lambda d: tuple(d.items()))


@st.composite
def layouts(draw):
    """Layouts that fit SOURCE: some kinds, at most their count of agents each, distinct
    ids (none of 0..7, the ids of a kind the program places), distinct indexes below
    the count, positions inside the world."""
    kinds = draw(st.lists(st.sampled_from(sorted(COUNTS)), unique=True))
    ids = iter(draw(st.lists(st.integers(8, 2**63 - 1), unique=True, min_size=8,
                             max_size=8)))
    agents = []
    for kind in kinds:
        n = draw(st.integers(0, COUNTS[kind]))
        slots = draw(st.permutations(range(COUNTS[kind])))[:n]
        for slot in slots:
            pos = draw(st.none() | st.tuples(st.floats(0, 30), st.floats(0, 20)))
            index = draw(st.none() | st.just(slot))
            agents.append(AgentSpec(kind, next(ids), pos, draw(_values(kind)), index))
    return Layout(tuple(draw(st.permutations(agents))), tuple(kinds))


@settings(max_examples=40, deadline=None)
@given(layout=layouts(), seed=st.integers(0, 2**32 - 1))
def test_a_valid_layout_round_trips_through_json_and_places_the_same_agents(backend, layout, seed):
    program = compile_source(SOURCE, "two.swarm")
    again = Layout.from_json(json.loads(json.dumps(layout.to_json())))
    assert again == layout
    placed, replaced = state_arrays(Simulation(program, seed, layout)), \
        state_arrays(Simulation(program, seed, again))
    for col in placed:
        assert np.array_equal(placed[col], replaced[col]), col
    for a in layout.agents:     # and each agent starts as its entry says
        row = int(np.flatnonzero(placed["id"] == a.id)[0])
        assert placed["kind_name"][row] == a.kind
        if a.pos is not None:
            assert tuple(placed["pos"][row]) == a.pos
        if a.index is not None:
            assert placed["index"][row] == a.index
        for name, value in a.values:
            assert np.array_equal(placed[name][row], value), name
    for kind, count in COUNTS.items():  # a kind the layout leaves out keeps its count
        expected = len(layout.of(kind)) if kind in layout.kinds else count
        assert int(np.sum(placed["kind_name"] == kind)) == expected


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=3),
                    lambda kids: st.lists(kids, max_size=3)
                    | st.dictionaries(st.text(max_size=3), kids, max_size=3), max_leaves=6)
AGENT_KEYS = st.sampled_from(["kind", "id", "index", "pos", "vars", "zz"])


@settings(max_examples=150, deadline=None)
@given(layout=layouts(), entry=st.integers(0, 7), key=AGENT_KEYS, value=JSON)
def test_a_damaged_layout_is_an_option_error_naming_the_layout(backend, layout, entry, key, value):
    """Any one entry of a valid layout's JSON replaced by any JSON value: the layout
    is still read and placed, or refused with an option error, never another exception."""
    program = compile_source(SOURCE, "two.swarm")
    data = layout.to_json()
    if data["agents"]:
        data["agents"][entry % len(data["agents"])][key] = value
    else:
        data["kinds" if key == "kind" else "agents"] = value
    try:
        Simulation(program, 0, Layout.from_json(data))
    except SwarmOptionError as err:
        assert err.message.startswith(("layout", "the layout")), err.message


def test_a_layout_of_numpy_ids_saves_as_json():
    """A layout built from numpy arrays (ids from `np.arange`, accepted as documented)
    gave a `to_json()` that `json.dumps` refused: "int64 is not JSON serializable"."""
    import json

    from swarmdsl.runtime.layout import AgentSpec, Layout

    agents = tuple(AgentSpec("boid", i, pos=(np.float64(5), 5.0), index=np.int32(i))
                   for i in np.arange(2, dtype=np.int64))
    layout = Layout(agents, ("boid",))
    assert Layout.from_json(json.loads(json.dumps(layout.to_json()))) == layout
