"""What a declaration may be called: a name that would hide another, share a column of
`agents.parquet` with one, or be overwritten by the runtime is refused where it is
declared, naming the earlier declaration's line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.compiler import columns, compile_source
from swarmdsl.compiler.errors import SwarmError
from swarmdsl.compiler.info import BUILTIN_NAMES
from swarmdsl.runtime.record import FIXED_COLUMNS, Recorder
from swarmdsl.runtime.simulation import Simulation

pq = pytest.importorskip("pyarrow.parquet")


def _error(text: str) -> SwarmError:
    with pytest.raises(SwarmError) as err:
        compile_source(text, "test.swarm")
    return err.value


# ---- columns of agents.parquet ----

@pytest.mark.parametrize(("text", "message"), [
    ("agent a { count 3; var x = 0; status s { x += 1 } }",
     "1:24: `x` is the name of a column of agents.parquet, which holds the agent's x "
     "position"),
    ("agent a { count 3; var vy = 0; status s { vy += 1 } }",
     "1:24: `vy` is the name of a column of agents.parquet, which holds the agent's y "
     "velocity"),
    # a vector is recorded as `p_x` and `p_y`, in either order of declaration
    ("agent a { count 3; var p = (1, 2); var p_x = 5; status s { p_x += 1; p += (1, 1) } }",
     "1:40: `p_x` is the name of a column of agents.parquet, which holds the x part of "
     "vector `p` (line 1)"),
    ("agent a {\n  count 3\n  var p_y = 5\n  var p = (1, 2)\n  status s { }\n}",
     "4:7: `p` cannot be recorded in agents.parquet: its column `p_y` holds variable "
     "`p_y` (line 3)"),
    # ... and in two kinds: they share one table
    ("agent a { count 1; var p = (1, 2); status s { } }\n"
     "agent b { count 1; var p_x = 5; status s { } }",
     "2:24: `p_x` is the name of a column of agents.parquet, which holds the x part of "
     "vector `p` (line 1)"),
    # the runtime's own values: the last broadcast, its tick, the LED colour
    ("agent a { count 3; message score num; var msg_score = 1; status s { "
     "broadcast(score, msg_score) } }",
     "1:43: `msg_score` is the name of a column of agents.parquet, which holds the agent's "
     "last broadcast of message value `score`"),
    ("agent a { count 3; var msg_tick = 2; status s { } }",
     "1:24: `msg_tick` is the name of a column of agents.parquet, which holds the tick the "
     "agent last broadcast"),
    ("agent a { count 3; var led = 3; status s { led += 1 } }",
     "1:24: `led` is the name of a column of agents.parquet, which holds the agent's LED "
     "colour"),
    ("agent a { count 3; var believed_y = 0; status s { } }",
     "1:24: `believed_y` is the name of a column of agents.parquet, which holds the y part "
     "of the agent's believed position"),
    ("agent a { count 3; var tree_leaf = 0; status s { } }",
     "1:24: `tree_leaf` is the name of a column of agents.parquet, which holds each agent's "
     "active tree leaf (with `--tree-leaf`)"),
    # `msg_tick` is the tick of the last broadcast: no message value may take its column
    ("agent a { count 3; message tick num; status s { broadcast(tick, 5) } }",
     "1:28: message value `tick` would be kept as `msg_tick`, which holds the tick the "
     "agent last broadcast"),
])
def test_a_variable_that_would_share_a_column_is_refused_at_its_declaration(
        assert_located_error, text, message):
    assert_located_error(text, message)


def test_the_hint_says_how_a_vector_is_recorded():
    err = _error("agent a { count 1; var v_x = 0; var v = (0, 0); status s { } }")
    assert err.diagnostics[0].hint == ("a vector is recorded as `v_x` and `v_y`; choose "
                                       "another name")


@pytest.mark.parametrize(("first", "second", "message"), [
    ("1", "(1, 2)", "`e` is a number in kind `a` (line 1) but a vector here"),
    ("(1, 1)", "5", "`e` is a vector in kind `a` (line 1) but a number here"),
    ("1", "true", "`e` is a number in kind `a` (line 1) but a boolean here"),
])
def test_two_kinds_share_a_variable_name_only_with_one_type(
        assert_located_error, first, second, message):
    assert_located_error(
        f"agent a {{ count 3; var e = {first}; status s {{ }} }}\n"
        f"agent c {{ count 2; var e = {second}; status s {{ }} }}",
        f"2:24: {message}: two kinds may share a variable name only with the same type")


def test_two_kinds_with_one_variable_of_one_type_record_it_in_one_column(backend, tmp_path):
    prog = compile_source("agent a { count 2; var e = (1, 2); status s { e += (1, 0) } }\n"
                          "agent c { count 1; attr e = (5, 6); status s { } }", "t.swarm")
    sim = Simulation(prog, 0)
    rec = Recorder(tmp_path / "out", sim)
    rec.record()
    sim.step()
    rec.record()
    rec.close(1)
    table = pq.read_table(tmp_path / "out" / "agents.parquet").to_pandas()
    last = table[table.tick == 1].sort_values("id")
    assert last.e_x.tolist() == [2.0, 2.0, 5.0] and last.e_y.tolist() == [2.0, 2.0, 6.0]


def _taken_names() -> list[str]:
    """Every name the recorder or the runtime keeps a column under, whatever the program."""
    names = set(FIXED_COLUMNS) | set(columns.REQUESTED_COLUMNS)
    for name, (vtype, _what) in columns.RUNTIME_VALUES.items():
        names |= {name, *columns.recorded_as(name, vtype)}
    return sorted(names)


@settings(max_examples=40, deadline=None)
@given(name=st.sampled_from(_taken_names()), value=st.sampled_from(["0", "true", "(0, 0)"]))
def test_no_name_the_runtime_records_is_a_variable(name, value):
    err = _error(f"agent a {{ count 2\n  var {name} = {value}\n  status s {{ }}\n}}")
    first = err.diagnostics[0]
    assert (first.span.line, first.span.col) == (2, 7)
    assert (first.message.startswith(f"`{name}` is the name of a column of agents.parquet")
            or first.message == f"`{name}` is the name of a built-in value; choose another "
                                "name"), first.message


_NAME = st.one_of(st.sampled_from(_taken_names() + ["p", "p_x", "p_y", "q", "q_x", "e"]),
                  st.from_regex(r"[a-z][a-z0-9]{0,3}(_[xy])?", fullmatch=True))
_VALUE = st.sampled_from(["index", "index > 1", "(index, 2)"])


@settings(max_examples=30, deadline=None)
@given(decls=st.lists(st.tuples(st.integers(0, 1), _NAME, _VALUE), min_size=1, max_size=4))
def test_a_program_the_checker_accepts_records_every_variable_in_its_own_column(
        backend, tmp_path_factory, decls):
    """The oracle is the file itself: whatever the names, either the checker refuses
    the program at one of its variables, or agents.parquet reads back with one column
    per name and each variable's initial values in its columns."""
    kinds = [[(n, v) for k, n, v in decls if k == i] for i in (0, 1)]
    lines = []
    for i, kind in enumerate(kinds):
        lines.append(f"agent k{i} {{\n  count 2")
        lines += [f"  var {n} = {v}" for n, v in kind]
        lines.append("  status s { }\n}")
    text = "\n".join(lines)
    try:
        prog = compile_source(text, "t.swarm")
    except SwarmError as err:
        var_lines = {i + 1 for i, line in enumerate(text.splitlines())
                     if line.startswith("  var ")}
        assert {d.span.line for d in err.diagnostics} <= var_lines, str(err)
        return
    out = tmp_path_factory.mktemp("out")
    sim = Simulation(prog, 0)
    rec = Recorder(out, sim)
    rec.record()
    rec.close(0)
    table = pq.read_table(out / "agents.parquet")
    assert len(set(table.column_names)) == len(table.column_names)
    rows = table.to_pandas()
    for i, kind in enumerate(kinds):
        mine = rows[rows.kind == f"k{i}"].sort_values("id")
        for name, value in kind:
            index = np.arange(2.0)
            if value == "(index, 2)":
                assert mine[f"{name}_x"].tolist() == index.tolist()
                assert mine[f"{name}_y"].tolist() == [2.0, 2.0]
            else:
                want = index > 1 if value == "index > 1" else index
                assert mine[name].tolist() == want.tolist()


def test_every_column_the_writer_adds_is_one_the_checker_refuses(backend, tmp_path):
    """Messages of every type, beliefs, the LED and both tree recordings: each column of
    agents.parquet that is not one of the program's variables is a name the checker
    keeps from variables. A new column the writer or the runtime adds fails here until
    it is registered in `compiler/columns.py`."""
    from swarmdsl.runtime.trees import record_active_leaf, record_tree_memory

    prog = compile_source("""agent a {
  robot kilobot
  count 3
  believe pos
  message score num seen bool at vec
  var e = 0
  var p = (0, 0)
  status s {
    broadcast(score, 1)
    broadcast(seen, true)
    broadcast(at, believed)
    led(red)
    e = count(heard())
    p = believed
    tree sequence { wait(2); e > 5 }
  }
}""", "t.swarm")
    sim = Simulation(prog, 0)
    record_active_leaf(sim)
    record_tree_memory(sim)
    written = Recorder(tmp_path / "out", sim).schema.names
    own = {"e", "p_x", "p_y"}
    taken = columns.taken(prog.info)
    runtime = [n for n in written if n not in own and ":" not in n]
    assert {"tick", "x", "msg_score", "msg_at_x", "msg_tick", "led", "believed_y",
            "located", "tree_leaf"} <= set(runtime)
    assert [n for n in runtime if n not in taken] == []
    # and every value the runtime keeps beside the variables, by its own name
    kept = set(prog.var_specs) - {"e", "p"}
    assert kept and [n for n in kept if n not in taken] == []


def test_a_program_with_an_unreadable_output_is_refused_by_check_and_run(tmp_path, capsys):
    path = tmp_path / "varx.swarm"
    path.write_text("agent a { count 3; var x = 0; status s { x += 1 } }\n")
    assert main(["check", str(path)]) == 2
    first, quoted, caret = capsys.readouterr().err.splitlines()[:3]
    assert first == (f"{path}:1:24: error: `x` is the name of a column of agents.parquet, "
                     "which holds the agent's x position")
    assert caret.index("^") == len("   1 | ") + 23
    out = tmp_path / "out"
    assert main(["run", str(path), "--headless", "--steps", "2", "--out", str(out)]) == 2
    assert not (out / "agents.parquet").exists()


# ---- built-in names ----

@pytest.mark.parametrize(("text", "message"), [
    ("agent a { count 3; var tick = 100; var t = 0; status s { t = tick } }",
     "1:24: `tick` is the name of a built-in value; choose another name"),
    ("agent a { count 3; var speed = 1; status s { } }",
     "1:24: `speed` is the name of a built-in value; choose another name"),
    ("param tick = 3\nagent a { count 3; status s { } }",
     "1:7: `tick` is the name of a built-in value; choose another name"),
    ("param pi = 3\nagent a { count 3; status s { } }",
     "1:7: `pi` is the name of a built-in value; choose another name"),
    ("agent a { count 3; status s { let dist = 2; velocity = (dist, 0) } }",
     "1:35: `let dist` would hide the built-in value `dist`"),
    ("agent a { count 3; status other { } }",
     "1:27: `other` is the name of a built-in value; choose another name"),
    ("agent believed { count 3; status s { } }",
     "1:7: `believed` is the name of a built-in value; choose another name"),
    ("agent a { count 3; var msg = 1; status s { } }",
     "1:24: `msg` is the name of a built-in value; choose another name"),
])
def test_a_declaration_named_like_a_built_in_is_refused(assert_located_error, text, message):
    assert_located_error(text, message)


@settings(max_examples=30, deadline=None)
@given(name=st.sampled_from(sorted(BUILTIN_NAMES)),
       where=st.sampled_from(["param", "var", "status", "agent", "field"]))
def test_no_declaration_takes_a_built_in_name(name, where):
    decl = {"param": f"param {name} = 1\nagent a {{ count 1; status s {{ }} }}",
            "var": f"agent a {{ count 1; var {name} = 1; status s {{ }} }}",
            "status": f"agent a {{ count 1; status {name} {{ }} }}",
            "agent": f"agent {name} {{ count 1; status s {{ }} }}",
            "field": f"field {name} {{ }}\nagent a {{ count 1; status s {{ }} }}"}[where]
    err = _error(decl)
    assert f"`{name}` is the name of a built-in value; choose another name" in [
        d.message for d in err.diagnostics]


# ---- a kind's names against the program's ----

@pytest.mark.parametrize(("text", "message"), [
    ("field f { initial 7 }\nagent a { count 3; var f = 1; status s { f += 1 } }",
     "2:24: `f` is already declared as a field at line 1"),
    ("param r = 10\nagent a { count 3; var r = r * 2; status s { } }",
     "2:24: `r` is already declared as a param at line 1"),
    ("nest home = circle(50, 50, 5)\nagent a { count 3; attr home = 1; status s { } }",
     "2:25: `home` is already declared as a `nest` region at line 1"),
    ("agent prey { count 3; var hunter = 0; status s { } }\n"
     "agent hunter { count 2; status chase { } }",
     "1:27: `hunter` is already declared as an agent kind at line 2"),
    ("agent prey { count 3; status hunter { } }\nagent hunter { count 2; status chase { } }",
     "1:30: `hunter` is already declared as an agent kind at line 2"),
    ("param go = 1\nagent a { count 3; status go { } }",
     "2:27: `go` is already declared as a param at line 1"),
    ("field heat { }\nagent a { count 3; status s { let heat = 2; velocity = (heat, 0) } }",
     "2:35: `let heat` would hide the field `heat` (line 1)"),
    ("agent a {\n  count 3\n  var e = 1\n  status s { let e = 2; velocity = (e, 0) }\n}",
     "4:18: `let e` would hide the variable `e` (line 3)"),
    ("agent a {\n  count 3\n  var e = 1\n  attr e = 2\n  status s { }\n}",
     "4:8: `e` is already declared in `a` (line 3)"),
    # a kind's memories, label sets, maps and objectives are names its code reads too
    ("param trail = 3\nagent a { count 2; memory trail 10; status s { } }",
     "2:27: `trail` is already declared as a param at line 1"),
    ("food apple = circle(5, 5, 2)\nagent a { count 2; labels apple; status s { } }",
     "2:27: `apple` is already declared as a `food` region at line 1"),
    ("param seen = 3\nagent a { count 2; map seen 10 20; status s { } }",
     "2:24: `seen` is already declared as a param at line 1"),
    ("nest home = circle(50, 50, 5)\nagent a { count 2; objective home = (1, 1); "
     "status s { } }",
     "2:30: `home` is already declared as a `nest` region at line 1"),
    ("agent a { count 2; memory tick 10; status s { } }",
     "1:27: `tick` is the name of a built-in value; choose another name"),
])
def test_a_name_taken_at_top_level_is_refused_in_a_kind(assert_located_error, text, message):
    assert_located_error(text, message)


def test_a_status_may_share_its_own_kinds_name_and_the_kind_stays_comparable(other_backend):
    """`agent reference { status reference { } }` (the shipped matrix programs): compared
    with a kind the name is the kind, compared with a status it is the status."""
    pytest.importorskip("numba")
    from conftest import run_both

    prog, sims = run_both("""world { size 20 x 20 }
agent reference { count 3; place (index, 0); status reference { } }
agent cell {
  count 2
  place (index, 1)
  var kinds = 0
  var statuses = 0
  status s {
    kinds = count(neighbors(50) where other.kind == reference)
    statuses = count(neighbors(50) where reference == other.status)
  }
}
metric refs = count(kind == reference)
""")
    for sim in sims:
        cols = sim.agents.cols
        cells = cols["kind"] == prog.info.kind("cell").index
        assert cols["kinds"][cells].tolist() == [3.0, 3.0]
        assert cols["statuses"][cells].tolist() == [3.0, 3.0]


SHIPPED = sorted((Path(__file__).resolve().parent.parent / "programs").glob("*.swarm")) + \
    sorted((Path(__file__).resolve().parent.parent / "benchmarks" / "models").glob("*.swarm"))


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_programs_keep_their_names(path, capsys):
    assert main(["check", str(path)]) == 0, capsys.readouterr().err
    assert not re.search(r"error", capsys.readouterr().err)
