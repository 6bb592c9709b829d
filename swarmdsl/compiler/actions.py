"""Statement kinds and action statements, one row each with what every target does.

An action statement `name(args)` is an effect that is not an assignment (deposit,
remember, broadcast, ...): one `ActionSpec`, registered by the module that adds it, with
its checker rule, its codegen rule and its other targets. A statement kind (`let`, an
assignment, `when`, an action, `tree`) is one `StatementRow` declaring the same for the
kind as a whole; its check and closure are the checker's and codegen's (or, for an
extension's kind, `checker.STMT_RULES` and `codegen.STMT_CODEGEN`), registered next to
its row."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from swarmdsl.compiler import ast
from swarmdsl.ops.targets import Refused


@dataclass(frozen=True)
class ActionSpec:
    """`check(checker, stmt, scope, kind)` reports misuse; `compile(codegen, stmt, kind)`
    returns a closure `run(frame)` that applies the effect for `frame.active` agents
    (the numpy reference; the numba backend runs the same closure inside its fused
    status when it has no statement kernel for it).

    `batch`: whether R replicas in one store run the effect bit-identical to their solo
    runs (`compiler/batching.py`): an effect on agent columns or on each replica's own
    grid is; a `Refused` sends the program solo. `kilobot`: True when the exporter
    writes its C (`export/kilobot_c.py` `KindC.action`: an effect on the robot's own
    state, motors, LED or outgoing message), else a `Refused` saying why a Kilobot
    cannot run it (the located error's hint). Both are keywords without a default on
    purpose: a new action says what each target does (`tests/test_rows_complete.py`)."""

    name: str
    check: Callable
    compile: Callable
    doc: str
    batch: bool | Refused | None = None
    kilobot: bool | Refused | None = None


ACTIONS: dict[str, ActionSpec] = {}


def register(spec: ActionSpec) -> ActionSpec:
    ACTIONS[spec.name] = spec
    return spec


@dataclass(frozen=True)
class StatementRow:
    """A kind of statement (its AST class `cls`): `doc`, its one line; `batch`, whether
    a batch of replicas runs it (`compiler/batching.py`: a kind no row declares is
    refused, never batched by default); `kilobot`, True when the exporter writes its C
    (`export/kilobot_c.py` `STATEMENT_C`), else a `Refused` (the located error's hint).
    An action statement's own row (`ActionSpec`) is asked as well."""

    cls: type
    doc: str
    batch: bool | Refused
    kilobot: bool | Refused


STATEMENTS: dict[type, StatementRow] = {}


def declare_statement(cls: type, doc: str, *, batch: bool | Refused,
                      kilobot: bool | Refused) -> StatementRow:
    STATEMENTS[cls] = row = StatementRow(cls, doc, batch, kilobot)
    return row


# The core's kinds: each works on agent columns, row by row (a batch runs them), and
# each has its C in the exporter.
declare_statement(ast.LetStmt, "`let NAME = EXPR`: a value named for the rest of the body",
                  batch=True, kilobot=True)
declare_statement(ast.AssignStmt, "`NAME = EXPR` (or `+=`, ...): a variable or `velocity` "
                  "set for the next tick", batch=True, kilobot=True)
declare_statement(ast.WhenStmt, "`when COND -> STATUS { ... }`: a transition",
                  batch=True, kilobot=True)
declare_statement(ast.ActionStmt, "`name(args)`: an action (its own row says the rest)",
                  batch=True, kilobot=True)
