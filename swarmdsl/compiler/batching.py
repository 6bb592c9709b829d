"""Whether a program's replicas can run as one batch, read off its constructs' rows.

A batch (`runtime/batch.py`) runs R replicas of one program in one agent store, each
bit-identical to its solo run. Whether a construct can be laid out per replica is a
property of the construct, so each row declares it beside its other forms: a function
(`ops/functions.py`, `batch=`), an aggregate (`builtins.AGGREGATES`), an extension's
call (`builtins.CALLS`, declared by the module that adds it), an action
(`actions.ActionSpec.batch`), a statement kind (`actions.STATEMENTS`), a tree node
(`runtime/trees.py`), and a runtime plug-in (its factory marked `per_replica` by the
hook that adds it). Why this lives in the compiler and not in `runtime/batch.py`: the
rows are the compiler's (and the runtime may not import the compiler), so the program
answers `Program.batch_refusal()`, a method the runtime's `RunnableProgram` protocol
declares, and the batch only asks it. A name or kind no row declares is refused, never
batched by default.
"""

from __future__ import annotations

from swarmdsl.compiler import ast
from swarmdsl.compiler.actions import ACTIONS, STATEMENTS
from swarmdsl.compiler.builtins import AGGREGATES, CALLS, FUNCTIONS
from swarmdsl.ops.targets import Refused


def per_replica(make, runs: str | None = None):
    """Mark a runtime plug-in factory `make(sim)` as one a batch may make per replica:
    the extension works row by row or pair by pair (draws by rows) and keeps no state of
    a replica's own beyond agent columns and what `runtime/batch_fields.py` splits.
    `runs`: what it does every tick, in words (`run -v` says it keeps the whole-tick
    kernel out: "its messages run in Python every tick")."""
    make.per_replica = True
    if runs is not None:
        make.runs = runs
    return make


def batch_refusal(program) -> str | None:
    """Why `program` cannot run as replicas bit-identical to its solo runs, in words a
    user reads in `-v` (e.g. "the action `forward` is not batched yet (`forward(...)`,
    line 12)"), the first construct in the text; None when it can."""
    trees = {n.name for n in _walk(program.info.tree) if type(n).__name__ == "TreeDecl"}
    for node in sorted(_walk(program.info.tree), key=_where):
        why = _refused_declaration(node)
        if why is None and isinstance(node, ast.Call) and node.name not in trees \
                and not _runs(_call_row(node.name)):
            why = f"`{node.name}()` is not batched yet"
        if isinstance(node, ast.ActionStmt) and not _runs(ACTIONS.get(node.name)):
            why = f"the action `{node.name}` is not batched yet"
        if why is None and isinstance(node, ast.Stmt) \
                and not _runs(STATEMENTS.get(type(node))):
            why = f"the statement `{type(node).__name__}` is not batched yet"
        if why is None:
            why = _tree_node(node)
        if why is not None:
            return f"{why} ({_construct(node)}, line {node.span.line})"
    for make in program.extensions:   # a plug-in no declaration above accounts for
        if not getattr(make, "per_replica", False):
            return (f"a runtime extension of this program ({make.__module__}) is not "
                    "batched yet")
    return None


def _call_row(name: str):
    """The row of a call: a function, an aggregate, an extension's call or an action
    (a tree leaf `deposit(...)` is a call), the first that declares the name."""
    for table in (FUNCTIONS, AGGREGATES, CALLS, ACTIONS):
        row = table.get(name)
        if row is not None:
            return row
    return None


def _runs(row) -> bool:
    """Whether a row declares that a batch runs it (no row, no `batch`: it does not)."""
    return row is not None and getattr(row, "batch", None) is True


def _tree_node(node) -> str | None:
    """A composite or decorator whose row (`runtime/trees.py`) refuses batches: why,
    or None (a leaf is its expression's, action's or long action's call)."""
    from swarmdsl.compiler.tree_ast import Composite, Decorator

    if not isinstance(node, Composite | Decorator):
        return None
    from swarmdsl.runtime.trees import composite_row, decorator_row

    row = (composite_row if isinstance(node, Composite) else decorator_row)(node.kind)
    if row.batch is True:
        return None
    why = f": {row.batch.why}" if isinstance(row.batch, Refused) else ""
    return f"the tree node `{row.name}` is not batched yet{why}"


def _refused_declaration(node) -> str | None:
    """Why a declaration's run-time state is not laid out per replica yet, or None."""
    if type(node).__name__ == "FieldDecl":
        for opt in node.options:   # a twin sampled anew every tick, drawing per node:
            if opt.name == "twin" and _reads_tick(opt) and _draws(opt):   # each run's
                return "a physical twin that draws at every tick is not batched yet"
    return None


def _walk(node):
    """`node` and every AST node under it."""
    stack = [node]
    while stack:
        n = stack.pop()
        yield n
        stack.extend(n.children())


def _reads_tick(node) -> bool:
    return any(isinstance(n, ast.Name) and n.id == "tick" for n in _walk(node))


def _draws(node) -> bool:
    return any(isinstance(n, ast.Call) and getattr(FUNCTIONS.get(n.name), "random", False)
               for n in _walk(node))


def _where(node) -> tuple[int, int]:
    span = node.span
    return (span.line, span.col) if span is not None else (0, 0)


def _construct(node) -> str:
    """How the user wrote the refused construct, shortly."""
    name = type(node).__name__
    if name == "FieldDecl":
        return f"`field {node.name}`"
    if name == "RegionDecl":
        return f"`{node.keyword} {node.name}`"
    if name == "RobotDecl":
        return f"`robot {node.name}`"
    if name == "ObjectiveDecl":
        return f"`objective {node.name}`"
    if name in ("ActionStmt", "Call"):
        return f"`{node.name}(...)`"
    if name == "AssignStmt":
        return f"`{node.target} {node.op} ...`"
    if isinstance(node, ast.Stmt) and not name.startswith("Tree"):
        return "a statement"
    return "a behaviour tree" if name.startswith("Tree") or name in (
        "Composite", "Decorator", "Leaf") else "a field reading"
