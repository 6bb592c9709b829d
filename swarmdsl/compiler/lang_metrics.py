"""`metric NAME = EXPR`: the numbers an experiment measures, checked and compiled.

A metric is an observer, like a swarm property, so it follows the same rules (swarm
aggregates, no neighbour queries, no random draws) and reuses that checker and code
generator. A top-level metric reduces over every agent; one declared inside an `agent`
block reduces over that kind only and is reported as `kind.NAME`. Its value is one
number per recorded tick (a condition counts as 1 or 0).

Metrics alone may also measure the swarm's geometry, which needs neighbours:
`clusters(R)`, `largest_cluster(R)` (clusters: connected components of the agents linked
within the constant link radius R) and `mean_nearest_distance()`, each over the agents
the metric reduces over, or those of them meeting a condition (`clusters(R, status ==
resting)`). They read positions only (`runtime/metrics.py` computes them), so they
observe without acting, and a batch computes them replica by replica.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.compiler import ast, checker, program, typing_rules
from swarmdsl.compiler.builtins import BOOL, NUM, TYPE_TEXT, VEC, Refused, declare_calls
from swarmdsl.compiler.checker import Checker
from swarmdsl.compiler.codegen import broadcast
from swarmdsl.compiler.info import AGENT_STATE
from swarmdsl.compiler.lang_properties import (
    _EachAgentScope,
    _PropertyGen,
    _PropertyView,
    _SwarmScope,
    warn_partial_vars,
)
from swarmdsl.compiler.metric_ranges import metric_bounds
from swarmdsl.errors import NotPerReplica
from swarmdsl.runtime.frame import AgentFrame

ERR = "error"

# the swarm's geometry, metrics only: name -> whether its first argument is a link radius
# (runtime/metrics.py's SWARM_MEASURES, imported only when a program is built: `check`
# loads no runtime it does not use; tests/test_metrics.py holds the two lists equal)
MEASURES = {"clusters": True, "largest_cluster": True, "mean_nearest_distance": False}
_USAGE = {"clusters": "`clusters(R)` or `clusters(R, COND)`, R a constant link radius",
          "largest_cluster": "`largest_cluster(R)` or `largest_cluster(R, COND)`, R a "
                             "constant link radius",
          "mean_nearest_distance": "`mean_nearest_distance()` or "
                                   "`mean_nearest_distance(COND)`"}


@dataclass(frozen=True)
class MetricInfo:
    name: str               # qualified: `polarisation` or `boid.speed`
    kind: str | None
    decl: ast.MetricDecl
    # the least and most it can be, None where unknown (`metric_ranges.py`): plots'
    # axes and bands stay within them
    bounds: tuple[float | None, float | None] = (None, None)


@dataclass(frozen=True)
class CompiledMetric:
    info: MetricInfo
    kind_index: int | None
    value: object           # closure(frame) -> scalar


class _MetricView(_PropertyView):
    """The property rules, with aggregates of a per-kind metric ranging over its kind."""

    remembers = False     # a metric is one number per tick: `previous` is refused

    def visit_Where(self, e: ast.Where, scope) -> str:
        return self._no_neighbours(e)

    def visit_Call(self, e: ast.Call, scope) -> str:
        if e.name in ("neighbors", "neighbours"):
            return self._no_neighbours(e)
        if e.name in MEASURES:
            return self._measure(e, scope)
        return super().visit_Call(e, scope)

    def _no_neighbours(self, e: ast.Expr) -> str:
        return self.fail("metrics cannot query neighbours: they observe the swarm "
                         "from outside", e.span, "keep a variable the agents update, "
                         "e.g. `var crowd = 0` and `crowd = count(neighbors(5))`, "
                         "then `metric crowd = mean(crowd)`; for clusters and spacing "
                         "use `clusters(R)`, `largest_cluster(R)` or "
                         "`mean_nearest_distance()`")

    def _measure(self, e: ast.Call, scope) -> str:
        """`clusters(R [, COND])`, `largest_cluster(R [, COND])`,
        `mean_nearest_distance([COND]) [else D]`: one number of the swarm (or of the
        metric's kind), over the agents meeting COND when given."""
        name, radius = e.name, MEASURES[e.name]
        if isinstance(scope, _EachAgentScope):
            return self.fail(f"`{name}` measures the whole swarm: it cannot go inside a "
                             "swarm aggregate", e.span)
        if e.each is not None:
            return self.fail(f"`{name}` takes no `:` expression", e.each.span,
                             f"write {_USAGE[name]}")
        fixed = 1 if radius else 0
        if len(e.args) not in (fixed, fixed + 1):
            return self.fail(f"`{name}` takes {fixed}{' or 2' if radius else ' or 1'} "
                             f"argument{'s' * radius}, got {len(e.args)}", e.span,
                             f"write {_USAGE[name]}")
        if radius:
            r = e.args[0]
            if self.expect(r, NUM, scope, f"the link radius of `{name}`") != ERR:
                value = self._const(r, f"the link radius of `{name}`")
                if value is not None and not value > 0:
                    self.fail(f"the link radius of `{name}` must be positive, got "
                              f"{value:g}", r.span)
        if len(e.args) > fixed:
            each_kind = scope.kind if scope.kind is not None else (
                self.kinds[0] if len(self.kinds) == 1 else None)
            self.expect(e.args[-1], BOOL, _EachAgentScope(each_kind),
                        f"the condition of `{name}` (which agents it measures)")
        if e.default is not None:
            if radius:
                self.fail(f"`{name}` of no agents is well defined (0); `else` is only "
                          "for `mean_nearest_distance`", e.default.span)
            else:
                self.expect(e.default, NUM, scope, f"the `else` of `{name}`")
        self.facts.set_name(e, ("swarm_measure", name))
        return NUM

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
                      kind.name if kind else None, d,
                      metric_bounds(d.expr, view.facts, view.params))


def _metric_hint(call: str, first: str, var: str, d: ast.MetricDecl) -> str:
    if call in ("count", "all", "any"):
        return f"narrow it to the kind: `{call}(kind == {first} and ...)`"
    return (f"declare the metric inside `agent {first}` to reduce over that kind "
            f"(reported as `{first}.{d.name}`)")


def _measure_elsewhere(chk: Checker, e: ast.Call, scope) -> str:
    """CALL_RULES entry: a swarm measure outside a metric (a status, a property)."""
    for a in e.args:
        chk.expr(a, scope)
    return chk.fail(f"`{e.name}` measures the whole swarm: it is for `metric` "
                    "declarations", e.span, f"e.g. `metric {e.name} = {e.name}("
                    f"{'10' if MEASURES[e.name] else ''})`")


class _MetricGen(_PropertyGen):
    """Property codegen whose aggregates range over one kind when the metric has one."""

    kind_index: int | None = None

    def visit_Call(self, e: ast.Call):
        res = self.facts.name_of(e)
        if res is not None and res[0] == "swarm_measure":
            return self._measure(e, res[1])
        return super().visit_Call(e)

    def _measure(self, e: ast.Call, name: str):
        """The closure of a swarm measure: positions of the agents it reduces over
        (those meeting its condition), measured by `runtime/metrics.py`; in a batch's
        frame (`segments`), each replica's on their own, one value per replica."""
        from swarmdsl.runtime import metrics as measures

        has_radius = MEASURES[name]
        radius = self.expr(e.args[0]) if has_radius else None
        cond = self.expr(e.args[-1]) if len(e.args) > int(has_radius) else None
        default = self.expr(e.default) if e.default is not None else None
        agents_of = self._aggregated_agents()
        if name == "mean_nearest_distance":
            def measure(pos, _r, box):
                return measures.mean_nearest_distance(pos, box)
        else:
            measure = (measures.cluster_count if name == "clusters"
                       else measures.largest_cluster)

        def measured(f):
            segments = getattr(f, "segments", None)   # a batch's frame (runtime/batch.py)
            if segments is None and getattr(f.sim, "replicas", None) is not None:
                raise NotPerReplica(f"`{name}` inside another swarm aggregate")
            every = agents_of(f)
            every.tick = f.tick
            rows = every.idx
            keep = None if cond is None else np.asarray(
                broadcast(cond(every), every.n, BOOL), dtype=bool)
            r = float(radius(f)) if radius is not None else None
            pos, box = f.sim.agents.cols["pos"], f.sim.world.box
            if segments is None:
                value = measure(pos[rows if keep is None else rows[keep]], r, box)
                if default is not None and np.isnan(value):
                    return float(default(f))
                return value
            if default is not None:
                raise NotPerReplica(f"`{name}` with `else`")
            bounds = segments(rows).tolist()
            out = np.empty(len(bounds) - 1)
            for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
                part = rows[a:b] if keep is None else rows[a:b][keep[a:b]]
                out[k] = measure(pos[part], r, box)
            return out
        return measured

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
    return prog.metrics


checker.PROGRAM_CHECK_HOOKS.append(check_metrics)
typing_rules.CALL_RULES.update(dict.fromkeys(MEASURES, _measure_elsewhere))
declare_calls(MEASURES, batch=True,   # the swarm's geometry, measured per replica
              kilobot=Refused("metrics are measured by the simulator, not on a robot"))
program.PROGRAM_HOOKS.append(compile_metrics)

__all__ = ["CompiledMetric", "MetricInfo", "metrics_of"]
