"""The status graph of each agent kind, and what the checker reports about it.

Nodes are a kind's statuses; edges are its `when COND -> target` transitions in source
order. Reported: statuses no transition reaches from the initial one (warning), statuses
with no way out (warning) unless declared `final` (an intended end), `final` statuses
that a transition leaves (warning), conditions that are never true (warning),
always-true conditions that hide the `when`s after them, and conditions that can hold
together with different targets, where order decides (notes).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from swarmdsl.compiler import ast
from swarmdsl.compiler.guards import disjoint, truth
from swarmdsl.compiler.hazards import check_divisions
from swarmdsl.compiler.status_gaps import check_gaps
from swarmdsl.errors import Span, SwarmError


@dataclass(frozen=True)
class Transition:
    source: str
    target: str
    guard: ast.Expr
    span: Span              # the `when` statement
    order: int              # position among the source status's `when`s
    never: bool = False     # the guard is never true


@dataclass
class KindGraph:
    kind: str
    statuses: list[str]
    initial: list[str]
    transitions: list[Transition]
    spans: dict[str, Span] = field(default_factory=dict)
    final: set[str] = field(default_factory=set)   # `final status`: intended ends

    def targets(self, status: str) -> set[str]:
        return {t.target for t in self.transitions if t.source == status and not t.never}

    @property
    def reachable(self) -> set[str]:
        seen = set(self.initial)
        frontier = list(seen)
        while frontier:
            for t in self.targets(frontier.pop()):
                if t not in seen:
                    seen.add(t)
                    frontier.append(t)
        return seen

    @property
    def unreachable(self) -> list[str]:
        reached = self.reachable
        return [s for s in self.statuses if s not in reached]

    @property
    def dead_ends(self) -> list[str]:
        """Statuses (of a kind with several) that no live transition leaves, other than
        `final` ones."""
        if len(self.statuses) < 2:
            return []
        return [s for s in self.statuses
                if s not in self.final and not (self.targets(s) - {s})]


def kind_graphs(kinds, params: dict) -> list[KindGraph]:
    """One KindGraph per checked kind (`KindInfo`s from the checker or a ProgramInfo)."""
    out = []
    for k in kinds:
        transitions = []
        for s, decl in k.status_decls.items():
            whens = [st for st in decl.body if isinstance(st, ast.WhenStmt)]
            for i, st in enumerate(whens):
                if st.target in k.status_decls:
                    transitions.append(Transition(s, st.target, st.cond, st.span, i,
                                                  truth(st.cond, params) is False))
        out.append(KindGraph(k.name, list(k.statuses), initial_statuses(k), transitions,
                             {s: d.name_span for s, d in k.status_decls.items()},
                             {s for s, d in k.status_decls.items()
                              if getattr(d, "final", False)}))
    return out


def initial_statuses(k) -> list[str]:
    """The statuses an agent of kind `k` can start in (`initial` may name several)."""
    opt = k.options.get("initial")
    if not k.statuses:
        return []
    if opt is None or not opt.args:
        return [k.statuses[0]]
    found = [n.id for n in ast.walk(opt.args[0])
             if isinstance(n, ast.Name) and n.id in k.status_decls]
    return list(dict.fromkeys(found)) or [k.statuses[0]]


def check_status_graphs(chk) -> None:
    """Called by the checker: status-graph warnings into `chk.warnings`, notes into
    `chk.extra["notes"]` (printed by `swarmdsl check`, not by `run`)."""
    notes: list[SwarmError] = chk.extra.setdefault("notes", [])
    for g in kind_graphs(chk.kinds, chk.params):
        for s in g.unreachable:
            chk.warn(f"status `{s}` of `{g.kind}` is unreachable: no transition leads to it "
                     "from the initial status", g.spans[s])
        for s in g.dead_ends:
            if s in g.reachable:
                chk.warn(f"status `{s}` of `{g.kind}` has no way out: no transition leaves "
                         "it", g.spans[s], "add a `when COND -> other_status` if agents "
                         "should leave it")
        for t in g.transitions:
            if t.source in g.final and t.target != t.source and not t.never:
                chk.warn(f"`{t.source}` of `{g.kind}` is final, but this `when` leaves it "
                         f"for `{t.target}`", t.span, "drop `final`, or the `when`")
            if t.never:
                chk.warn(f"this condition is never true: `{t.source}` never goes to "
                         f"`{t.target}` here", t.guard.span)
        for s in g.statuses:
            _order_notes(chk, g, s, notes)
    check_gaps(chk)
    check_divisions(chk)


def _order_notes(chk, g: KindGraph, status: str, notes: list) -> None:
    whens = [t for t in g.transitions if t.source == status and not t.never]
    for i, a in enumerate(whens):
        if truth(a.guard, chk.params) is True and i + 1 < len(whens):
            notes.append(SwarmError(
                f"this condition is always true: the `when`s after it in `{status}` never "
                "fire", a.guard.span, severity="note"))
            break
        for b in whens[i + 1:]:
            if a.target != b.target and not disjoint(a.guard, b.guard, chk.params):
                notes.append(SwarmError(
                    f"in `{g.kind}.{status}`, this condition and the one on line "
                    f"{a.span.line} can hold together; the first listed wins "
                    f"(`{a.target}` over `{b.target}`)", b.guard.span, severity="note"))
