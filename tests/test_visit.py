"""The visitor base (`compiler/visit.py`) and the walkers on it: every node class of the
language is handled by every walker, or refused on purpose, so a new node class cannot
be forgotten by one of them; and the checked facts have one home (`compiler/facts.py`)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from swarmdsl.compiler import ast, checker, codegen, extensions, visit  # noqa: F401
from swarmdsl.compiler.consteval import NotConstant, _Folder, const_value
from swarmdsl.compiler.facts import Facts
from swarmdsl.compiler.metric_ranges import _Ranges
from swarmdsl.errors import Span
from swarmdsl.export.kilobot_c import KindC
from swarmdsl.internal import InternalError
from swarmdsl.lsp.index import _Builder
from swarmdsl.runtime.compiled.plan import Planner, Unsupported
from swarmdsl.runtime.compiled.stmt_plan import StatementPlanner

ROOT = Path(__file__).resolve().parents[1]
SPAN = Span("t.swarm", 1, 1, 1, 2)

# walker -> the extension tables it reads for the classes it has no method for
WALKERS = {
    checker.Checker: {**checker.EXPR_RULES, **checker.STMT_RULES},
    codegen.CodeGen: {**codegen.EXPR_CODEGEN, **codegen.STMT_CODEGEN},
    _Folder: {},
    _Ranges: {},
    Planner: {},
    StatementPlanner: {},
    _Builder: {},
    KindC: {},
}


def _cases():
    for walker, rules in WALKERS.items():
        for family in walker.NODES:
            for cls in visit.node_classes(family):
                yield pytest.param(walker, rules, cls, id=f"{walker.__name__}-{cls.__name__}")


@pytest.mark.parametrize(("walker", "rules", "cls"), list(_cases()))
def test_every_walker_handles_or_refuses_every_node_class(walker, rules, cls):
    assert walker.handles(cls, rules), (
        f"{walker.__name__} has no visit_{cls.__name__}, no extension rule for it, and "
        f"does not list it in REFUSED: add one of them")


def test_the_language_has_the_node_classes_the_walkers_were_written_for():
    """A guard on the test above: it must see the extensions' classes too."""
    names = {c.__name__ for c in visit.node_classes(ast.Expr)}
    assert {"Name", "Call", "Chain", "FieldAt", "TreeResult", "Forever"} <= names
    assert "TreeStmt" in {c.__name__ for c in visit.node_classes(ast.Stmt)}


def test_an_unknown_node_class_is_an_internal_error_not_a_silent_skip():
    @ast.node
    class Mystery(ast.Expr):
        pass

    class Walker(visit.Visitor):
        def visit_Num(self, e):
            return e.value

    assert Walker().visit(ast.Num(SPAN, 2.0, False)) == 2.0
    with pytest.raises(InternalError, match="Walker has no rule for Mystery"):
        Walker().visit(Mystery(SPAN))
    with pytest.raises(InternalError, match="Mystery"):
        const_value(Mystery(SPAN), {})


def test_a_refused_class_goes_to_the_walkers_refuse():
    name = ast.Name(SPAN, "x")
    attr = ast.Attr(SPAN, name, "x", SPAN)
    with pytest.raises(NotConstant):
        const_value(attr, {})
    assert const_value(ast.Neg(SPAN, name), {"x": 2}) == -2
    with pytest.raises(Unsupported, match="a string has no compiled form"):
        Planner.refuse(Planner.__new__(Planner), ast.StrLit(SPAN, "s"))


def test_an_extension_rule_is_read_at_each_visit():
    @ast.node
    class Late(ast.Expr):
        pass

    table: dict = {}

    class Walker(visit.Visitor):
        def extension_rule(self, node_cls):
            return table.get(node_cls)

    with pytest.raises(InternalError):
        Walker().visit(Late(SPAN))
    table[Late] = lambda walker, node: "late"
    assert Walker().visit(Late(SPAN)) == "late"


def test_children_walk_a_chain_s_terms_in_source_order():
    a, b, c = (ast.Name(SPAN, n) for n in "abc")
    chain = ast.Chain(SPAN, a, (("+", b), ("-", c)))
    assert list(visit.children(chain)) == [a, b, c]
    call = ast.Call(SPAN, "sum", SPAN, (a,), b, None)
    assert list(visit.children(call)) == [a, b]


def test_facts_are_per_node_identity_not_equality():
    facts = Facts()
    x1, x2 = ast.Name(SPAN, "x"), ast.Name(SPAN, "x")
    assert x1 == x2
    facts.set_name(x1, ("local", "x"))
    facts.set_type(x1, "number")
    assert facts.name_of(x1) == ("local", "x") and facts.is_name(x1, "local", "x")
    assert facts.name_of(x2) is None and facts.type_of(x2) is None
    assert facts.category(x1) == "local" and facts.category(x2) == ""


# Modules outside the compiler's walkers that still read the checker's facts by
# `id(node)` through the legacy views (`ProgramInfo.names`/`.types`): the kilobot export
# and the numba backend's statement fusion. Shrink this list; never grow it.
KNOWN_ID_READERS: set[str] = set()
_ID_LOOKUP = re.compile(r"\b(names|types)(\.get)?[\[(]id\(")


def test_the_checked_facts_are_read_through_their_home_only():
    found = set()
    for path in (ROOT / "swarmdsl").rglob("*.py"):
        rel = path.relative_to(ROOT).as_posix()
        if rel == "swarmdsl/compiler/facts.py":
            continue
        if _ID_LOOKUP.search(path.read_text(encoding="utf-8")):
            found.add(rel)
    assert found <= KNOWN_ID_READERS, sorted(found - KNOWN_ID_READERS)
