"""The columns of `agents.parquet` a variable would take, and those already taken.

Every per-agent variable of every kind is recorded under its own name (a vector as
`NAME_x` and `NAME_y`), beside the recorder's fixed columns (`runtime/columns.py`:
`FIXED_COLUMNS`, apart from `runtime/record.py`, so that checking a program imports none
of the recorder) and the values the runtime keeps for each agent (`msg_tick`, `led`,
...). The recorder trusts these names to be distinct: two columns of one name make the
file unreadable, and a variable named like a runtime value is overwritten by it. So the
checker refuses such a variable where it is declared, from the tables here, which the
modules that add those columns fill in where they add them.
"""

from __future__ import annotations

from swarmdsl.compiler.builtins import TYPE_TEXT, VALUE_TYPES, VEC
from swarmdsl.runtime.columns import (  # noqa: F401
    FIXED_COLUMNS,
    LEAF_RECORDED,
    RESULT_RECORDED,
    vector_columns,
)

# Values the runtime keeps for each agent and records like variables:
# name -> (type, what it holds).
RUNTIME_VALUES: dict[str, tuple[str, str]] = {}
# The same for values that depend on the program (`msg_NAME` of each message value):
# fn(checker) -> {name: (type, what it holds)}.
RUNTIME_VALUE_HOOKS: list = []
# Columns a run may ask the recorder for: name -> what it holds, and when.
REQUESTED_COLUMNS: dict[str, str] = {}


def recorded_as(name: str, vtype: str) -> tuple[str, ...]:
    """The columns of agents.parquet a variable of type `vtype` is recorded in."""
    return vector_columns(name) if vtype == VEC else (name,)


def taken(chk) -> dict[str, str]:
    """Every name a variable may not take (as its name or as one of its columns) ->
    what agents.parquet or the runtime already keeps under it."""
    out = {name: what for name, (_t, what) in FIXED_COLUMNS.items()}
    out.update(REQUESTED_COLUMNS)
    values = dict(RUNTIME_VALUES)
    for hook in RUNTIME_VALUE_HOOKS:
        values.update(hook(chk))
    for name, (vtype, what) in values.items():
        out.setdefault(name, what)
        if vtype == VEC:
            for axis, column in zip("xy", recorded_as(name, vtype), strict=True):
                out.setdefault(column, f"the {axis} part of {what}")
    return out


class ColumnTable:
    """The columns the variables checked so far take, over every kind."""

    def __init__(self):
        self.first: dict[str, tuple] = {}     # variable name -> (kind, VarInfo) declared first
        self.owners: dict[str, tuple] = {}    # column -> (VarInfo, "x" | "y" | None)
        self.taken: dict[str, str] | None = None

    def claim(self, chk, kind, v) -> None:
        """Give variable `v` of `kind` its columns, or report why it cannot have them.
        Kinds share a variable's column when they share its name, so they must agree on
        its type; no other column may be taken twice, nor a name the recorder or the
        runtime keeps a value under."""
        earlier = self.first.get(v.name)
        if earlier is not None:
            ek, ev = earlier
            if v.type != ev.type and v.type in VALUE_TYPES and ev.type in VALUE_TYPES:
                chk.fail(f"`{v.name}` is {TYPE_TEXT[ev.type]} in kind `{ek.name}` (line "
                         f"{ev.decl.name_span.line}) but {TYPE_TEXT[v.type]} here: two "
                         "kinds may share a variable name only with the same type",
                         v.decl.name_span)
            return
        self.first[v.name] = (kind, v)
        if self.taken is None:   # at the first variable: every kind's message is known
            self.taken = taken(chk)
        own = recorded_as(v.name, v.type) if v.type in VALUE_TYPES else (v.name,)
        # a vector's own name is no column, but the runtime keeps its values by name
        for column in dict.fromkeys((v.name, *own)):
            what = self.taken.get(column)
            if what is None and column in own and column in self.owners:
                other, part = self.owners[column]
                line = other.decl.name_span.line
                what = (f"the {part} part of vector `{other.name}` (line {line})" if part
                        else f"variable `{other.name}` (line {line})")
            if what is None:
                continue
            if column == v.name:
                chk.fail(f"`{v.name}` is the name of a column of agents.parquet, which "
                         f"holds {what}", v.decl.name_span, "choose another name")
            else:
                names = " and ".join(f"`{n}`" for n in own)
                chk.fail(f"`{v.name}` cannot be recorded in agents.parquet: its column "
                         f"`{column}` holds {what}", v.decl.name_span,
                         f"a vector is recorded as {names}; choose another name")
            return
        parts = ("x", "y") if len(own) == 2 else (None,)
        for part, column in zip(parts, own, strict=True):
            self.owners[column] = (v, part)
