"""Every construct is one declared row with a form, or a declared refusal, on every target
(`ops/targets.py`): numpy (the reference closures), numba (the kernels' scalar trees),
batch (replicas in one store) and kilobot (the exported C).

Here, per target, every row of every table: functions and operators (`ops/`),
aggregates and extension calls (`compiler/builtins.py`), actions (`compiler/actions.py`),
tree composites and decorators (`runtime/trees.py`). A new row that says nothing for a
target fails here; then a refusal is shown to be located where the construct is used,
one refused construct per table."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from swarmdsl.cli import main
from swarmdsl.compiler import (
    ast,
    compile_source,
    extensions,  # noqa: F401  (registers their rows)
)
from swarmdsl.compiler.actions import ACTIONS, STATEMENTS
from swarmdsl.compiler.builtins import AGGREGATES, CALLS, AggregateC
from swarmdsl.compiler.tree_ast import TreeStmt
from swarmdsl.compiler.tree_long import LONG
from swarmdsl.compiler.typing_rules import CALL_RULES
from swarmdsl.export.kilobot_c import ACTION_C, STATEMENT_C
from swarmdsl.ops import scalars
from swarmdsl.ops.functions import FUNCTIONS
from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS, NEGATE
from swarmdsl.ops.targets import Refused
from swarmdsl.ops.types import VEC
from swarmdsl.runtime import trees
from swarmdsl.runtime.batch import batch_refusal

ROOT = Path(__file__).resolve().parent.parent
GRADIENT = (ROOT / "programs" / "kilobot" / "gradient.swarm").read_text()
OPERATORS = [*ARITHMETIC.values(), *COMPARISONS.values(), NEGATE]
TREE_ROWS = [*trees.COMPOSITES.values(), *trees.DECORATORS.values()]
# The extension calls whose C the exporter writes, by their resolution
# (`export/kilobot_c.py` `KindC.call` and `aggregate`).
CALLS_IN_C = {"heard", "trilaterate", "nn"}


def _declared(form) -> bool:
    """A target's entry of a row: a form (a template, True, a C description) or a
    `Refused` with its reason; None (nothing said) is not one."""
    if isinstance(form, Refused):
        return bool(form.why.strip())
    return form is not None and form is not False


# ---- every row, every target ----

@pytest.mark.parametrize("row", FUNCTIONS.values(), ids=list(FUNCTIONS))
def test_every_function_row_has_every_targets_form_or_refusal(row):
    assert callable(row.numpy)
    # numba: a scalar form or a lowering; a draw keeps the reference closure (its
    # stream is the run's), which `random=True` declares
    assert row.compiled or row.random, f"`{row.name}` has no form for the numba kernels"
    if row.scalar is not None:
        assert scalars.scalar(row.name) is row.scalar
    assert _declared(row.batch), row.name
    assert isinstance(row.kilobot, str | Refused) and _declared(row.kilobot), row.name


@pytest.mark.parametrize("op", OPERATORS, ids=[f"{o.node}" for o in OPERATORS])
def test_every_operator_row_has_every_targets_form_or_refusal(op):
    assert callable(op.numpy) and callable(op.fold)
    assert scalars.scalar(op.node) is op.scalar          # the kernels find its node
    assert _declared(op.batch)
    assert _declared(op.kilobot), op.symbol
    # a vector form only for operand types the type rule has, and one for each
    # vector case the type rule allows but arithmetic of statuses and kinds
    assert set(op.kilobot_vec) <= set(op.types)
    if op in ARITHMETIC.values() or op is NEGATE:
        assert {t for t in op.types if VEC in t} == set(op.kilobot_vec), op.symbol


@pytest.mark.parametrize("name", list(AGGREGATES))
def test_every_aggregate_row_has_every_targets_form_or_refusal(name):
    row = AGGREGATES[name]
    assert _declared(row.batch)
    assert isinstance(row.kilobot, AggregateC | Refused), name
    if isinstance(row.kilobot, AggregateC):   # a vector EACH the type rule allows has C
        assert (VEC in row.each_types) == (row.kilobot.step_vec is not None), name
        assert (row.kilobot.step_vec is None) == (row.kilobot.result_vec is None)
    # numpy (from the pairs) and numba (a kernel family's loop, then the row's finish)
    assert callable(row.pairs) and callable(row.finish), name
    assert row.kernel in ("sum", "min", "max", "nearest"), name


def test_a_new_aggregate_is_its_row_on_both_backends(monkeypatch):
    """An aggregate added as one row (here `total`, a copy of `sum`'s forms) is checked,
    run on numpy and on numba's kernels, with the same values."""
    pytest.importorskip("numba")
    from conftest import run_both

    monkeypatch.setitem(AGGREGATES, "total", AGGREGATES["sum"])
    text = """
world { size 30 x 30; edges wrap }
agent a {
  count 40
  sense 5
  var t = 0
  var s = 0
  status go {
    t = total(neighbors() : other.id)
    s = sum(neighbors() : other.id)
    velocity = (1, 0.5)
  }
}
"""
    prog, (ref, fast) = run_both(text, steps=3, other="numba")
    for sim in (ref, fast):
        assert np.array_equal(sim.agents.cols["t"], sim.agents.cols["s"])
        assert sim.agents.cols["t"].any()
    assert ref.agents.cols["t"].tobytes() == fast.agents.cols["t"].tobytes()
    assert any("total: compiled" in line for line in fast.backend.summary(prog))


def test_every_extension_call_is_a_declared_row():
    """A call an extension adds to the checker has its row: batch and C say something."""
    undeclared = sorted(set(CALL_RULES) - set(CALLS))
    assert not undeclared, f"calls without a row (`builtins.declare_calls`): {undeclared}"
    for row in CALLS.values():
        assert _declared(row.batch) and _declared(row.kilobot), row.name
    assert {n for n, r in CALLS.items() if r.kilobot is True} == CALLS_IN_C


@pytest.mark.parametrize("name", sorted(ACTIONS))
def test_every_action_row_has_every_targets_form_or_refusal(name):
    spec = ACTIONS[name]
    assert callable(spec.check) and callable(spec.compile)
    assert spec.batch is True or isinstance(spec.batch, Refused), name
    assert spec.kilobot is True or isinstance(spec.kilobot, Refused), name
    # the exporter writes C exactly for the actions whose rows say it does
    assert (spec.kilobot is True) == (name in ACTION_C), name


def test_the_exporter_writes_no_action_without_a_row():
    assert set(ACTION_C) <= set(ACTIONS)


def _subclasses(cls) -> set:
    out, stack = set(), [cls]
    while stack:
        for sub in stack.pop().__subclasses__():
            out.add(sub)
            stack.append(sub)
    return out


def test_every_statement_kind_is_a_declared_row():
    """Every AST statement class the language has (the core's and the extensions') has
    a row; the exporter writes C exactly for the kinds whose rows say it does."""
    kinds = _subclasses(ast.Stmt)
    assert kinds and kinds == set(STATEMENTS), kinds ^ set(STATEMENTS)
    for row in STATEMENTS.values():
        assert row.doc and _declared(row.batch) and _declared(row.kilobot), row.cls
    assert {c for c, r in STATEMENTS.items() if r.kilobot is True} == set(STATEMENT_C)


@pytest.mark.parametrize("row", TREE_ROWS, ids=[r.name for r in TREE_ROWS])
def test_every_tree_node_row_has_every_targets_form_or_refusal(row):
    assert callable(row.make) and callable(row.outcomes) and row.doc
    assert _declared(row.batch) and _declared(row.kilobot)
    assert not row.forever or row.counted


@pytest.mark.parametrize("name", list(LONG))
def test_every_long_action_row_has_every_targets_form_or_refusal(name):
    row = LONG[name]
    assert callable(row.check) and callable(row.outcomes) and callable(row.build)
    assert row.doc and 0 <= row.lo <= row.hi and row.usage.startswith(f"{name}(")
    assert _declared(row.batch) and _declared(row.kilobot)
    assert CALLS[name].batch == row.batch and CALLS[name].kilobot == row.kilobot


def test_a_long_action_without_a_row_is_an_internal_error(monkeypatch):
    """Before rows, a long action the compiler did not know was built as a `follow`."""
    from swarmdsl.compiler import tree_long

    monkeypatch.delitem(tree_long.LONG, "wait")
    with pytest.raises(LookupError, match="no row declares the long action `wait`"):
        tree_long.long_action("wait")


def _terminal_words(name: str) -> set[str]:
    from swarmdsl.compiler.parse import parser

    (t,) = [t for t in parser().terminals if t.name == name]
    pattern = t.pattern.value
    return set(pattern[3:-1].split("|")) if pattern.startswith("(?:") else {pattern}


def test_the_grammars_tree_keywords_are_the_rows():
    """A keyword the grammar gains without a row (or a row no keyword writes) fails
    here, not as another kind's behaviour at run time."""
    counted = {r.name for r in trees.DECORATORS.values() if r.counted}
    plain = {r.name for r in trees.DECORATORS.values() if not r.counted}
    assert _terminal_words("COUNTED_KW") == counted
    forced = {f"force {w}" for w in _terminal_words("TREE_OUTCOME")}
    assert _terminal_words("INVERT_KW") | forced == plain
    assert _terminal_words("SEQ_KW") | _terminal_words("PARALLEL_KW") == set(trees.COMPOSITES)


def test_a_tree_kind_without_a_row_is_an_internal_error_not_a_default(monkeypatch):
    """Before rows, a decorator forgotten in the compiler silently ran as `cooldown`."""
    monkeypatch.delitem(trees.DECORATORS, "timeout")
    text = ("world { size 10 x 10; steps 1 }\nagent a {\n  count 1\n  var n = 0\n"
            "  status s {\n    tree timeout 3 sequence { n += 1 }\n  }\n}\n")
    with pytest.raises(LookupError, match="no row declares the tree decorator `timeout`"):
        compile_source(text, "t.swarm")


# ---- a refusal is located where its construct is used, one per table ----

def _kilobot_error(tmp_path, capsys, text: str) -> tuple[str, str]:
    """The first located error of `check --target kilobot` on `text`: (where, rest)."""
    path = tmp_path / "p.swarm"
    path.write_text(text)
    assert main(["check", "--target", "kilobot", str(path)]) == 2
    err = capsys.readouterr().err
    m = re.match(rf"{re.escape(str(path))}:(\d+:\d+): error: (.*)", err.splitlines()[0])
    assert m, err
    return m[1], err


def _at(text: str, needle: str) -> str:
    """`line:col` of the first `needle` in `text` (1-based)."""
    before = text[:text.index(needle)]
    return f"{before.count(chr(10)) + 1}:{len(before) - before.rfind(chr(10))}"


def test_a_refused_function_is_located_with_its_rows_reason(tmp_path, capsys):
    text = GRADIENT.replace("led(red)", "led(red)\n    hop = normal(0, 1)")
    where, err = _kilobot_error(tmp_path, capsys, text)
    assert where == _at(text, "normal(0, 1)")
    assert "the function `normal` cannot run on a Kilobot" in err
    assert f"hint: {FUNCTIONS['normal'].kilobot.why}" in err


def test_a_refused_operator_is_located_with_its_rows_reason(tmp_path, capsys, monkeypatch):
    why = "no modulo on this robot"
    monkeypatch.setitem(ARITHMETIC, "%", replace(ARITHMETIC["%"], kilobot=Refused(why)))
    where, err = _kilobot_error(tmp_path, capsys, GRADIENT)
    assert where == _at(GRADIENT, "hop % 2")
    assert "the operator `%` cannot run on a Kilobot" in err and f"hint: {why}" in err


def test_a_refused_aggregate_is_located_with_its_rows_reason(tmp_path, capsys, monkeypatch):
    why = "no minimum on this robot"
    monkeypatch.setitem(AGGREGATES, "min", AGGREGATES["min"]._replace(kilobot=Refused(why)))
    where, err = _kilobot_error(tmp_path, capsys, GRADIENT)
    assert where == _at(GRADIENT, "min(heard()")
    assert "the aggregate `min` cannot run on a Kilobot" in err and f"hint: {why}" in err


def test_a_refused_call_and_action_are_located_with_their_rows_reasons(tmp_path, capsys):
    text = GRADIENT.replace("world {", "field heat { }\nworld {").replace(
        "  final status seed {\n", "  final status seed {\n    deposit(heat, 1)\n")
    path = tmp_path / "p.swarm"
    path.write_text(text)
    assert main(["check", "--target", "kilobot", str(path)]) == 2
    err = capsys.readouterr().err
    assert (f"{path}:{_at(text, 'deposit(heat')}: error: the action `deposit(...)` "
            "cannot run on a Kilobot") in err
    assert f"hint: {ACTIONS['deposit'].kilobot.why}" in err
    text = GRADIENT.replace("world {", "field heat { }\nworld {").replace(
        "when id == 0 -> seed", "when id == 0 and sample(heat) > 1 -> seed")
    path.write_text(text)
    assert main(["check", "--target", "kilobot", str(path)]) == 2
    err = capsys.readouterr().err
    assert (f"{path}:{_at(text, 'sample(heat)')}: error: the function `sample` cannot run "
            "on a Kilobot") in err
    assert f"hint: {CALLS['sample'].kilobot.why}" in err


def test_a_refused_tree_is_located_with_its_rows_reason(tmp_path, capsys):
    text = GRADIENT.replace("    led(off)\n", "    tree repeat 2 sequence { led(off) }\n")
    where, err = _kilobot_error(tmp_path, capsys, text)
    assert where == _at(text, "tree repeat")
    assert "error: the tree cannot run on a Kilobot" in err
    assert f"hint: {STATEMENTS[TreeStmt].kilobot.why}" in err


ROBOT = """world { size 100 x 100; steps 5 }
agent a {
  robot kilobot
  count 3
  place (20 + 20 * index, 50)
  var n = 0
  status s {
    tree repeat 2 sequence { n += 1 }
    forward(0.7)
  }
}
"""


def test_a_refused_action_sends_a_batch_solo_naming_its_line():
    why = batch_refusal(compile_source(ROBOT, "r.swarm"))
    assert why == "the action `forward` is not batched yet (`forward(...)`, line 9)"


def test_a_tree_node_whose_row_refuses_batches_is_named_with_its_line(monkeypatch):
    text = ROBOT.replace("    forward(0.7)\n", "")
    assert batch_refusal(compile_source(text, "r.swarm")) is None
    monkeypatch.setitem(trees.DECORATORS, "repeat", replace(
        trees.DECORATORS["repeat"], batch=Refused("its counter is per run")))
    assert batch_refusal(compile_source(text, "r.swarm")) == (
        "the tree node `repeat` is not batched yet: its counter is per run "
        "(a behaviour tree, line 8)")


def test_a_statement_kind_whose_row_refuses_batches_is_named_with_its_line(monkeypatch):
    text = ROBOT.replace("    forward(0.7)\n", "")
    monkeypatch.setitem(STATEMENTS, ast.AssignStmt, replace(STATEMENTS[ast.AssignStmt],
                                                            batch=False))
    assert batch_refusal(compile_source(text, "r.swarm")) == (
        "the statement `AssignStmt` is not batched yet (`n += ...`, line 8)")



def _tree_statements(text):
    from swarmdsl.compiler.parse import parse

    core = (ast.LetStmt, ast.AssignStmt, ast.WhenStmt, ast.ActionStmt)
    return [st for status in ast.walk(parse(text)) if isinstance(status, ast.StatusDecl)
            for st in status.body if not isinstance(st, core)]


def test_an_extensions_parse_rules_are_its_own_registration(monkeypatch):
    """A statement of its own syntax needs nothing in the parser: rules registered with
    `syntax_rules`, after the parser was imported or while the extensions are imported
    at the first rule no method builds, build the AST."""
    from swarmdsl.compiler import parse as p
    from swarmdsl.compiler import syntax_rules

    text = (Path(__file__).parent.parent / "programs" / "aco_bt.swarm").read_text()
    trees = _tree_statements(text)
    assert len(trees) >= 2 and all(isinstance(st, TreeStmt) for st in trees)

    class Late:
        def tree_stmt(self, meta, c):
            return TreeStmt(self._s(meta), "late")

    monkeypatch.setattr(syntax_rules, "MIXINS", list(syntax_rules.MIXINS))
    monkeypatch.setattr(p, "_taken", list(p._taken))
    monkeypatch.delattr(p.ToAst, "tree_stmt")
    monkeypatch.setattr(p, "_extensions_imported", [False])
    monkeypatch.setattr(p, "_import_extensions", lambda: syntax_rules.register(Late))
    assert [st.root for st in _tree_statements(text)] == ["late"] * len(trees)
    assert p._extensions_imported == [True]
    syntax_rules.register(type("Later", (), {
        "tree_stmt": lambda self, meta, c: TreeStmt(self._s(meta), "later")}))
    assert [st.root for st in _tree_statements(text)] == ["later"] * len(trees)
