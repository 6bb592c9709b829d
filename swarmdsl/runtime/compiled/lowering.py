"""The numba backend's `compiler.lowering.Lowering`: each aggregate, filter, `let` and
assignment the kernels can run becomes a closure with both paths (`fused.py`,
`statements.py`), and sums over one neighbour set share a loop (`siblings.py`).

Planning imports only these Python modules, never numba: numba loads when a numba run
first calls a kernel.
"""

from __future__ import annotations


class NumbaLowering:
    name = "numba"

    def aggregate(self, gen, call, reference):
        from swarmdsl.runtime.compiled.fused import wrap

        return wrap(gen, call, reference)

    def filter(self, gen, where, source, reference):
        from swarmdsl.runtime.compiled.fused import wrap_filter

        return wrap_filter(gen, where, source, reference)

    def statement(self, gen, stmt, reference, built: dict, target_type=None,
                  nonfinite=None, let_guard=None):
        from swarmdsl.runtime.compiled import statements

        return statements.wrap(gen, stmt, reference, built, target_type, nonfinite, let_guard)

    def statement_list(self, gen, stmts) -> None:
        from swarmdsl.runtime.compiled import siblings

        siblings.group(gen, stmts)


NUMBA = NumbaLowering()
