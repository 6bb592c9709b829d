"""The long actions of behaviour trees (`move_to`, `wait`, `retrace`, `follow`): one row
each, with what every stage needs of it.

A long action is a tree leaf that runs over several ticks. Its row holds its usage and
argument count (the syntax table `tree_ast.LONG_ACTIONS` is read off these rows), the
check of its arguments (`lang_trees`), the results it can give (`tree_outcomes`), the
leaf that ticks (`tree_codegen`, building a `runtime/tree_leaves.py` node), whether a
batch runs it and its Kilobot form. The stages look a name up here and have no branch
of their own, so a long action is declared once, and a name without a row is an
internal error (`long_action`), never another action's behaviour. What a row needs
of the checker and the compiler it asks of the stage that calls it (the expander's
`err`, `refuse_negative`, `uses_fields`; the builder's `target`), so this module
imports none of them and every stage can import it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from swarmdsl.compiler import ast
from swarmdsl.compiler.actions import ACTIONS
from swarmdsl.compiler.builtins import FIELD, MEMORY, NUM, REGION, TYPE_TEXT, VEC
from swarmdsl.ops.targets import Refused

NOT_ON_A_KILOBOT = Refused("behaviour trees are not translated to C yet")


@dataclass(frozen=True)
class LongAction:
    """`check(expander, call)`: its arguments, once their count is right (`expander` is
    `lang_trees._Expander`: `chk`, `scope`, `err`, `_count`, `refuse_negative`,
    `uses_fields`); `outcomes(call, const)`: what it can return (`const(expr)`: a
    constant's value or None); `build(builder, call, index)`: the leaf that ticks
    (`builder` is `tree_codegen._Builder`: `gen`, `layout`, `tree`, `count`, `kind`,
    `target`)."""

    name: str
    usage: str
    lo: int
    hi: int
    doc: str
    check: Callable
    outcomes: Callable
    build: Callable
    batch: bool | Refused = True      # a leaf's memory is agent columns: per replica
    kilobot: Refused = NOT_ON_A_KILOBOT


def _speed(ex, call) -> None:
    """The optional last argument of `move_to` and `follow`: a speed, not negative."""
    row = LONG[call.name]
    if len(call.args) == row.hi and \
            ex.chk.expect(call.args[-1], NUM, ex.scope, f"the speed of `{call.name}`") == NUM:
        ex.refuse_negative(call.args[-1], f"the speed of `{call.name}`")


def _check_move_to(ex, call) -> None:
    chk, a = ex.chk, call.args
    t = chk.expr(a[0], ex.scope)
    if t not in (VEC, REGION, ex.err):
        chk.fail(f"the target of `move_to` must be a vector or a region, got "
                 f"{TYPE_TEXT.get(t, t)}", a[0].span)
    if chk.expect(a[1], NUM, ex.scope, "the tolerance of `move_to`") == NUM:
        ex.refuse_negative(a[1], "the tolerance of `move_to`")
    _speed(ex, call)


def _check_wait(ex, call) -> None:
    ex._count(call.args[0], "the ticks of `wait`")


def _named(ex, call, want: str, what: str) -> None:
    """The first argument: a declared path memory or field, by its name."""
    a0 = call.args[0]
    t = ex.chk.expr(a0, ex.scope)
    if t != ex.err and (t != want or not isinstance(a0, ast.Name)):
        ex.chk.fail(f"`{call.name}` needs {what} here, got {TYPE_TEXT.get(t, t)}", a0.span)


def _check_retrace(ex, call) -> None:
    _named(ex, call, MEMORY, "a path memory (declare it with `memory NAME K`)")


def _check_follow(ex, call) -> None:
    _named(ex, call, FIELD, "a field")
    ex.uses_fields()
    _speed(ex, call)


def _wait_outcomes(call, const) -> frozenset:
    n = const(call.args[0]) if call.args else None
    return frozenset("S") if n is not None and n <= 0 else frozenset("SR")


def _build_wait(b, call, i):
    from swarmdsl.runtime import tree_leaves as leaf

    a = call.args
    return leaf.Wait(b.layout, b.tree, i, b.count(a[0], a[0].span), call.span)


def _build_move_to(b, call, i):
    from swarmdsl.runtime import tree_leaves as leaf

    gen, a = b.gen, call.args
    speed = gen.expr(a[2]) if len(a) > 2 else None
    return leaf.MoveTo(b.target(a[0]), gen.expr(a[1]), speed, call.span)


def _build_retrace(b, call, i):
    from swarmdsl.runtime import tree_leaves as leaf

    a = call.args
    st = ast.ActionStmt(call.span, "retrace", call.name_span, a)
    name = a[0].id
    return leaf.Retrace(ACTIONS["retrace"].compile(b.gen, st, b.kind),
                        lambda f: f.sim.environment.memories[name].length(
                            f.sim.agents.cols, f.idx), call.span)


def _build_follow(b, call, i):
    from swarmdsl.runtime import tree_leaves as leaf

    a = call.args
    name = a[0].id
    speed = b.gen.expr(a[1]) if len(a) > 1 else None
    return leaf.Follow(lambda f: f.sim.environment.fields[name], speed, call.span)


LONG: dict[str, LongAction] = {row.name: row for row in [
    LongAction("move_to", "move_to(TARGET, tol[, speed])", 2, 3,
               "steers at a point or a region: success once within `tol`, never fails",
               _check_move_to, lambda call, const: frozenset("SR"), _build_move_to),
    LongAction("wait", "wait(N)", 1, 1, "running on its first N ticks, success on the next",
               _check_wait, _wait_outcomes, _build_wait),
    LongAction("retrace", "retrace(MEMORY)", 1, 1,
               "back along a path memory, a point a tick: success once it is empty",
               _check_retrace, lambda call, const: frozenset("SR"), _build_retrace),
    LongAction("follow", "follow(FIELD[, speed])", 1, 2,
               "up a field's gradient: success at a peak, failure where flat at 0",
               _check_follow, lambda call, const: frozenset("SFR"), _build_follow),
]}


def long_action(name: str) -> LongAction:
    """The row of long action `name`; a name without one is a bug, never a default."""
    row = LONG.get(name)
    if row is None:
        raise LookupError(f"no row declares the long action `{name}` (compiler/tree_long.py)")
    return row
