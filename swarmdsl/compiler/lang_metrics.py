"""`metric NAME = EXPR`: the numbers an experiment measures, checked and compiled.

A metric is an observer, like a swarm property, so it follows the same rules (swarm
aggregates, no neighbour queries, no random draws) and reuses that checker and code
generator. A top-level metric reduces over every agent; one declared inside an `agent`
block reduces over that kind only and is reported as `kind.NAME`. Its value is one
number per recorded tick (a condition counts as 1 or 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.compiler import ast, checker, program
from swarmdsl.compiler.builtins import BOOL, NUM, TYPE_TEXT, VEC
from swarmdsl.compiler.checker import Checker
from swarmdsl.compiler.info import AGENT_STATE
from swarmdsl.compiler.lang_properties import (
    _EachAgentScope,
    _PropertyGen,
    _PropertyView,
    _SwarmScope,
    warn_partial_vars,
)
from swarmdsl.runtime.frame import AgentFrame

ERR = "error"


@dataclass(frozen=True)
class MetricInfo:
    name: str               # qualified: `polarisation` or `boid.speed`
    kind: str | None
    decl: ast.MetricDecl


@dataclass(frozen=True)
class CompiledMetric:
    info: MetricInfo
    kind_index: int | None
    value: object           # closure(frame) -> scalar


class _MetricView(_PropertyView):
    """The property rules, with aggregates of a per-kind metric ranging over its kind."""

    remembers = False     # a metric is one number per tick: `previous` is refused

    def _expr(self, e: ast.Expr, scope) -> str:
        if isinstance(e, ast.Where) or (isinstance(e, ast.Call)
                                        and e.name in ("neighbors", "neighbours")):
            return self.fail("metrics cannot query neighbours: they observe the swarm "
                             "from outside", e.span, "keep a variable the agents update, "
                             "e.g. `var crowd = 0` and `crowd = count(neighbors(5))`, "
                             "then `metric crowd = mean(crowd)`")
        return super()._expr(e, scope)

    def name(self, e: ast.Name, scope) -> str:
        n = e.id
        if isinstance(scope, _SwarmScope) and n not in self.params and (
                n in AGENT_STATE or any(n in k.vars for k in self.kinds)):
            return self.fail(f"`{n}` is a value of each agent; a metric reads it through "
                             "count, all, any, sum, mean, min or max", e.span,
                             f"e.g. `mean({n})`")
        return super().name(e, scope)

    def _swarm_aggregate(self, e: ast.Call, scope):
        if scope.kind is None or isinstance(scope, _EachAgentScope):
            return super()._swarm_aggregate(e, scope)
        return self._aggregate_over(e, scope, scope.kind, "the agents")


def check_metrics(chk: Checker) -> None:
    """PROGRAM_CHECK_HOOKS entry: type-check every metric, record `MetricInfo`s."""
    view = _MetricView(chk)
    found: list[MetricInfo] = []
    for d in chk.tree.decls_of(ast.MetricDecl):
        found.append(_check_one(view, d, None))
    for k in chk.kinds:
        seen: dict[str, ast.MetricDecl] = {}
        for d in k.decl.items_of(ast.MetricDecl):
            if d.name in seen:
                chk.fail(f"metric `{k.name}.{d.name}` is already declared (line "
                         f"{seen[d.name].name_span.line})", d.name_span)
                continue
            seen[d.name] = d
            found.append(_check_one(view, d, k))
    chk.extra["metrics"] = [m for m in found if m is not None]


def _check_one(view: _MetricView, d: ast.MetricDecl, kind) -> MetricInfo | None:
    t = view.expr(d.expr, _SwarmScope(kind))
    if t == VEC:
        view.fail("a metric is one number, got a vector", d.expr.span,
                  "take its length, e.g. `length(mean(normalize(vel)))`, or one component")
        return None
    if t not in (NUM, BOOL, ERR):
        view.fail(f"a metric is a number (or a condition, counted 1 or 0), got "
                  f"{TYPE_TEXT.get(t, t)}", d.expr.span)
        return None
    if t == ERR:
        return None
    if kind is None:
        warn_partial_vars(view, d.expr, lambda c, k, v: _metric_hint(c, k, v, d))
    return MetricInfo(f"{kind.name}.{d.name}" if kind else d.name,
                      kind.name if kind else None, d)


def _metric_hint(call: str, first: str, var: str, d: ast.MetricDecl) -> str:
    if call in ("count", "all", "any"):
        return f"narrow it to the kind: `{call}(kind == {first} and ...)`"
    return (f"declare the metric inside `agent {first}` to reduce over that kind "
            f"(reported as `{first}.{d.name}`)")


class _MetricGen(_PropertyGen):
    """Property codegen whose aggregates range over one kind when the metric has one."""

    kind_index: int | None = None

    def _aggregated_agents(self):
        ki = self.kind_index
        if ki is None:
            return super()._aggregated_agents()

        def of_kind(f):
            rows = np.flatnonzero(f.sim.agents.cols["kind"] == ki)
            return AgentFrame(f.sim, rows, f.sim.program.kinds[ki], None)
        return of_kind


def compile_metrics(info, prog, gen) -> None:
    """PROGRAM_HOOKS entry: compile each metric into a closure over a swarm frame."""
    mg = _MetricGen(info, prog)
    compiled = []
    for m in info.extra.get("metrics", []):
        k = info.kind(m.kind) if m.kind else None
        mg.kind_index = k.index if k else None
        compiled.append(CompiledMetric(m, mg.kind_index, mg.expr(m.decl.expr)))
    info.extra["compiled_metrics"] = compiled


def metrics_of(prog) -> list[CompiledMetric]:
    """The compiled metrics of a Program: top-level ones first, then per kind."""
    return list(prog.info.extra.get("compiled_metrics", []))


checker.PROGRAM_CHECK_HOOKS.append(check_metrics)
program.PROGRAM_HOOKS.append(compile_metrics)

__all__ = ["CompiledMetric", "MetricInfo", "metrics_of"]
