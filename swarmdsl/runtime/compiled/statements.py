"""A `let` or assignment with two paths: one fused loop over the agents, or the reference.

`codegen` wraps every number or vector `let` and every assignment in a statement
closure from `wrap`. When the statement has a plan (`stmt_plan`) and the run is on the
numba backend, the closure evaluates the plan's hoisted columns with the reference
closures (state reads, `let` values, random draws, aggregates, in source order), and
one kernel computes the value, the operator, the NaN or non-finite check and the masked
write. A failing check raises the reference's located error, worked out from the
kernel's result by the same code. Otherwise, and for good if numba refuses to compile
the kernel (found before any column is evaluated, so no draw is made twice), it runs
the reference closure. `Backend.parts` counts both, and `swarmdsl run -v` prints them.
"""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler import ast, nan_guard
from swarmdsl.compiler.builtins import VEC
from swarmdsl.runtime.compiled.fused import first_compile, listed, part_line
from swarmdsl.runtime.compiled.plan import Unsupported
from swarmdsl.runtime.compiled.stmt_plan import plan_statement
from swarmdsl.runtime.frame import AgentFrame


def wrap(cg, st, reference, built: dict, target_type: str | None = None, nonfinite=None,
         let_guard=None):
    """The statement closure: fused where a plan exists, else `reference` itself.

    `built` holds the reference's closures of the value's nodes by id (the hoisted
    columns are read through them). For an assignment, `target_type` is its column's
    type and `nonfinite(f, new, bad)` the reference's error for non-finite values; for
    a `let`, `let_guard` is the NaN guard's (what, hint)."""
    try:
        plan = plan_statement(cg, st, target_type)
    except Unsupported:
        return reference
    return listed(cg, FusedStatement(cg, st, plan, reference, built, nonfinite, let_guard),
                  "fused_statements")


class FusedStatement:
    def __init__(self, cg, st, plan, reference, built, nonfinite, let_guard):
        self.span = st.span
        self.plan = plan
        self.reason = None
        self.reference = reference
        self.nonfinite = nonfinite
        self.let_guard = let_guard
        self.kernel = None
        if isinstance(st, ast.LetStmt):
            self.label, self.target = f"statement `let {st.name} = ...`", st.name
        else:
            self.label = f"statement `{st.target} {st.op} ...`"
            self.target = cg.facts.name_of(st)[1]

        def closure(e):
            got = built.get(id(e))
            return got if got is not None else cg.expr(e)

        self.columns = [(vt, closure(e)) for e, vt in plan.columns]
        self.s_width = sum(2 if vt == VEC else 1 for vt, _fn in self.columns) + len(
            plan.stages)   # the hoisted columns, then the kernel's own
        consts = [v if isinstance(v, float) else 0.0 for v in plan.consts]
        self.consts = np.array([consts or [0.0]])
        self.per_call = [(c, closure(v)) for c, v in enumerate(plan.consts)
                         if not isinstance(v, float)]

    def __call__(self, f):
        backend = getattr(f.sim, "backend", None)
        if backend is None or not backend.fused or f.n == 0:
            return self.reference(f)
        if self.plan is not None and type(f) is AgentFrame:
            cur = None
            if self.plan.what == "assign":
                cur = f.state(self.target)
                if cur.dtype != np.float64 or cur.shape[1:] != self._shape(1)[1:]:
                    cur = None   # not a float column as the plan assumed
            if (cur is not None or self.plan.what == "let") and self._ready(backend):
                backend.note(self, True)
                return self._fused(f, cur)
        backend.note(self, False)
        return self.reference(f)

    def _shape(self, m: int) -> tuple:
        return (m, 2) if self.plan.width == 2 else (m,)

    def _ready(self, backend) -> bool:
        """Whether the kernel is compiled: compiled here on first use, on one idle
        agent, so a refusal is known before any column is evaluated (and no draw is
        lost)."""
        if self.kernel is not None:
            return True
        from swarmdsl.runtime.compiled.stmt_kernels import kernel

        w = self.plan.width

        def build():
            k = kernel(self.plan)
            k(_agent_table(1, self.s_width)[0], self.consts, np.zeros((1, w)),
              np.zeros(1, bool), np.zeros((1, w)))
            return k
        return first_compile(self, backend, build)

    def _fused(self, f, cur):
        m, w = f.n, self.plan.width
        S, T = _agent_table(m, self.s_width)
        c, per_agent = 0, False
        for vt, fn in self.columns:   # source order, as the reference evaluates them
            v = fn(f)
            per_agent = per_agent or np.ndim(v) > (1 if vt == VEC else 0)
            if vt == VEC:
                T[c:c + 2] = np.transpose(v) if np.ndim(v) == 2 else np.reshape(v, (2, 1))
                c += 2
            else:
                T[c] = v
                c += 1
        K = self.consts
        if self.per_call:
            K = K.copy()
            for slot, fn in self.per_call:
                K[0, slot] = fn(f)
        if cur is None:   # a let: its value only
            cur2 = _NO_CUR[w]
        else:
            cur2 = _writable(cur, cur.dtype).reshape(m, w)
        out = np.empty((m, w))
        active = _writable(f.active, np.bool_)
        compiling = self.kernel.compile_seconds
        bad = self.kernel(S, K, cur2, active, out)
        if self.kernel.compile_seconds != compiling:   # its threaded form, compiled now
            f.sim.backend.compile_seconds += self.kernel.compile_seconds - compiling
        new = out.reshape(self._shape(m))
        if bad >= 0:
            self._raise(f, new, per_agent)
        if cur is None:
            f.locals[self.target] = new
        else:
            f.overlay[self.target] = new
        return None

    def _raise(self, f, new, per_agent: bool):
        """The reference's error for this result (its running agents' rows hold the
        value the reference computes, so the same code finds the same agent)."""
        if self.plan.what == "assign":
            bad = ~np.isfinite(new)
            if bad.ndim == 2:
                bad = bad.any(axis=1)
            raise self.nonfinite(f, new, bad & f.active)
        what, hint = self.let_guard
        # a value the same for every agent was checked once, as the reference does
        rows = nan_guard.nan_rows(new if per_agent else new[0], f)
        raise nan_guard.nan_error(f, int(rows[0]), self.span, what, hint)


_NO_CUR = {1: np.zeros((0, 1)), 2: np.zeros((0, 2))}


def _writable(a, dtype) -> np.ndarray:
    """`np.require(a, dtype, ("C", "W"))`, without its cost (several microseconds a
    call, a few per tick of every run) when `a` already is."""
    if (type(a) is np.ndarray and a.dtype == dtype and a.flags.c_contiguous
            and a.flags.writeable):
        return a
    return np.require(a, dtype, ("C", "W"))


def _agent_table(m: int, width: int):
    """(S, T): the kernel's (m, width) table S as a view of T (width, m), which the
    columns fill one contiguous row each (S's rows would take strided writes, 6x
    slower). The padding keeps S from being contiguous whatever m and width, so numba
    sees one array type and compiles the kernel once."""
    T = np.empty((max(width, 2), m + 1))[:, :m]
    return T.T, T


def summary(program, backend) -> list[str]:
    """`swarmdsl run -v` lines for the fused statements: compiled, or why not."""
    return [part_line(part, part.label, backend.parts.get(part, (0, 0)),
                      "not an agent frame or not a float column")
            for part in getattr(program, "fused_statements", [])]
