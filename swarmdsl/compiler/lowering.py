"""The seam between the compiler and a backend: where a backend puts its own code in
place of the reference closures.

`codegen.CodeGen` builds every node as a numpy closure over whole arrays (the
reference, what the numpy backend runs). At four places it hands that closure to the
program's `Lowering`, which returns the closure to run instead: a backend compiles the
parts it can (the numba backend: `runtime/compiled/lowering.py`) and keeps the reference
for the rest. The compiler knows backends only through this protocol: nothing under
`compiler/` imports one.

A lowered closure must give the reference's results bit for bit on every backend it may
meet at run time (a program compiled once may run on either): it takes its own path only
when the run's backend can (`frame.sim.backend`), and the reference otherwise.
"""

from __future__ import annotations

from typing import Protocol


class Lowering(Protocol):
    """Hooks `CodeGen` calls while it compiles. Each gets the code generator `gen` (the
    checked types and names, `gen.expr` to compile a subexpression), the node and the
    reference closure built for it, and returns the closure to run."""

    name: str

    def aggregate(self, gen, call, reference):
        """A neighbour aggregate (`sum(S, each)`, `count(S)`, ...): `call` is its
        `ast.Call`, `reference(frame) -> array` its reference closure."""

    def filter(self, gen, where, source, reference):
        """A neighbour filter `S where COND`: `source` is the closure of `S`,
        `reference(frame, pairs)` filters the pairs `source` gave."""

    def statement(self, gen, stmt, reference, built: dict, target_type=None,
                  nonfinite=None, let_guard=None):
        """A `let` or an assignment. `built` maps id(node) to the closure already built
        for each node of its value; an assignment gives its `target_type` and
        `nonfinite(frame, new, bad)`, the located error for non-finite values; a `let`
        gives `let_guard`, the words of its NaN error."""

    def statement_list(self, gen, stmts) -> None:
        """Called once the statements of one body are compiled (after `statement` for
        each): a backend may group their parts (the numba backend shares one loop among
        sums over one neighbour set)."""


class Reference:
    """The identity lowering: the reference closures as they are. What
    `swarmdsl check` compiles (it never runs the program) and a program compiled
    without a lowering holds until a backend lowers it (`Program.lower`)."""

    name = "reference"

    def aggregate(self, gen, call, reference):
        return reference

    def filter(self, gen, where, source, reference):
        return lambda f: reference(f, source(f))

    def statement(self, gen, stmt, reference, built: dict, target_type=None,
                  nonfinite=None, let_guard=None):
        return reference

    def statement_list(self, gen, stmts) -> None:
        return None


REFERENCE = Reference()
