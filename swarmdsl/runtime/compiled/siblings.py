"""Sums over one neighbour set in one loop over its pairs.

A status body often takes several aggregates of one `let` set: boids' separation,
cohesion, alignment and neighbour count, the swarmalators' pull, phase sync and count.
Each fused aggregate is its own loop, and every loop reads the whole pair table again
(a third of a large swarm's tick went to reading it four times). Here the `count`,
`sum`, `mean`, `any` and `all` aggregates over one set in one statement list (one
`let` set, or `neighbors(r)` with the same radius written the same way) become siblings: the first of them to run computes the others too, in one loop that
visits each pair once, and each sibling takes its sums when its own statement runs.
Each sibling adds its terms in the same order as its own loop would, so the results
are the same bits.

Computing a sibling before its statement runs is only right when nothing it reads
has changed in between, so siblings are grouped statically: a later aggregate joins
an earlier one's loop only if the statements between them are `let`s and assignments
that define or write nothing its owner-side values (the plan's hoisted columns) or its
set read. Anything else between them (a `when`, an action) keeps them apart.
"""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import VEC
from swarmdsl.runtime.compiled import threads
from swarmdsl.runtime.compiled.fused import (_NO_ROWS, SUMS, Direct, FusedAggregate,
                                             other_table, owner_table, run_kernel, search)
from swarmdsl.runtime.compiled.plan import Planner, remap

MAX_SIBLINGS = 4   # kernels.MAX_SIBLINGS (not imported: that module imports numba)
_USED = object()   # a sibling's sums, already taken this frame


def group(cg, stmts) -> None:
    """Make siblings of the fused sums over each set in statement list `stmts`
    (called once the list is compiled; nested lists are grouped on their own)."""
    parts = {p.node_id: p for p in getattr(cg.program, "fused_parts", ())
             if isinstance(p, FusedAggregate) and p.plan is not None}
    by_set: dict = {}
    for i, st in enumerate(stmts):
        if not isinstance(st, ast.LetStmt | ast.AssignStmt):
            continue
        for node in _outer_aggregates(cg, st.value):
            part = parts.get(id(node))
            key = _set_key(cg, part.plan) if part is not None else None
            if key is not None and part.plan.name in SUMS:
                by_set.setdefault(key, []).append((i, part))
    for members in by_set.values():
        if len(members) > 1:
            Siblings(cg, stmts, members)


def _set_key(cg, plan):
    """What makes two sums' sets the same set: the `let` holding it, or the radius of
    `neighbors(r)` (the same syntax; a radius that draws or aggregates has none, as it
    is worked out anew each time it is evaluated)."""
    if plan.neighbors_call:
        if plan.radius is None:
            return ("neighbors", None)
        if not Planner(cg, False).owner_only(plan.radius):
            return None
        return ("neighbors", _shape(cg, plan.radius))
    res = cg.facts.name_of(plan.source, ())
    return ("let", res[1]) if res[:1] == ("local",) else None


def _outer_aggregates(cg, e):
    """The aggregate calls in `e` that no other aggregate encloses (an inner one is an
    owner-side value of its outer one, computed while the outer one's table is built)."""
    stack = [e]
    while stack:
        n = stack.pop()
        if isinstance(n, ast.Call) and cg.facts.name_of(n, ())[:1] == ("agg",):
            yield n
            continue
        stack.extend(n.children())


def _reads(cg, part) -> tuple[set, set, bool]:
    """(lets, columns, opaque) the owner side of `part` reads: its hoisted values and
    its set. `opaque`: it reads something whose writers are not known (an extension's
    name), so no statement may come between it and its loop."""
    plan = part.plan
    lets, cols, opaque = set(), set(), False
    exprs = [key for key, _vt in plan.hoisted if not isinstance(key, str)]
    if plan.neighbors_call:   # its limit: the sense column and the radius
        cols.add("sense")
        exprs += [plan.radius] if plan.radius is not None else []
    else:
        lets.add(cg.facts.name_of(plan.source)[1])
    if any(key == "pos" for key, _vt in plan.hoisted):
        cols.add("pos")
    for e in exprs:
        for n in ast.walk(e):
            if not isinstance(n, ast.Name):
                continue
            res = cg.facts.name_of(n, ())
            cat = res[0] if res else None
            if cat == "local":
                lets.add(res[1])
            elif cat in ("var", "state"):
                cols.add("vel" if res[1] == "speed" else res[1])
            elif cat not in ("const", "global", "kind", "status"):
                opaque = True
    return lets, cols, opaque


def _unchanged(cg, between, reads) -> bool:
    """Whether the statements `between` leave everything in `reads` as it was."""
    lets, cols, opaque = reads
    for st in between:
        if opaque:
            return False
        if isinstance(st, ast.LetStmt):
            if st.name in lets:
                return False
        elif isinstance(st, ast.AssignStmt):
            col = cg.facts.name_of(st)[1]
            if col in cols or (col == "vel" and "speed" in cols):
                return False
        else:
            return False
    return True


def _shape(cg, e):
    """A key equal for owner-side expressions that compute the same values (the same
    syntax, names resolved alike): siblings read such a column once."""
    if isinstance(e, str):
        return e
    key = (ast.shape(e), tuple(cg.facts.name_of(n) for n in ast.walk(e)))
    try:
        hash(key)
    except TypeError:   # an unhashable resolution: this column is not shared
        return ("id", id(e))
    return key


class Siblings:
    """The fused sums over one set in one statement list, and which of them each one's
    loop computes (itself and the later ones nothing between them changes)."""

    def __init__(self, cg, stmts, members):
        self.members = [p for _i, p in members]
        self.batches = {}
        for a, (i, first) in enumerate(members):
            batch = [first]
            for k, (j, other) in enumerate(members):
                if (k != a and j >= i and len(batch) < MAX_SIBLINGS
                        and _unchanged(cg, stmts[i:j], _reads(cg, other))):
                    batch.append(other)
            self.batches[first] = batch
        self.shapes = {p: [_shape(cg, key) for key, _vt in p.plan.hoisted]
                       for p in self.members}
        self.layouts: dict = {}     # batch (tuple of parts) -> its _Layout
        self.partners: dict = {}    # part -> the siblings it has shared a loop with
        for p in self.members:
            p.siblings = self

    def sums(self, part, f, backend):
        """`part`'s (out, cnt) as its own loop would give them, computing its batch's
        when none is waiting; None: run `part` on its own."""
        waiting = f.__dict__.setdefault("_sibling_sums", {})
        got = waiting.get(part)
        if got is not None and got is not _USED:
            waiting[part] = _USED
            return got
        batch = tuple(p for p in self.batches[part]
                      if p is part or (p.plan is not None and waiting.get(p) is None))
        if len(batch) < 2 or f.n == 0:
            return None
        done = self._run(batch, f, backend)
        if done is None:
            return None
        waiting.update(done)
        waiting[part] = _USED
        return done[part]

    def _run(self, batch, f, backend):
        """{part: (out, cnt)} for every part of `batch` from one loop, or None."""
        got = [p._pairs(f) for p in batch]
        first = got[0]
        if first is None or any(
                g is None or any(x is not y for x, y in zip(g[:-1], first[:-1], strict=True))
                for g in got[1:]):
            return None   # not one pair layout: each on its own
        groups, off, rows, J, D, DL, K, ranks, order, limit = first
        layout = self.layouts.get(batch, False)
        if layout is False:
            layout = self.layouts[batch] = _Layout(self, batch)
        if layout.plan is None:
            return None
        m = f.n
        S = layout.S = owner_table(f, layout.hoisted, layout.s_width, limit, order,
                                   layout.S)
        O = other_table(f, backend, ranks if ranks.size else None, layout.others_key,
                        layout.others)
        out = tuple(np.empty((m, 2)) for _p in batch)
        cnt = tuple(np.empty(m, np.int64) for _p in batch)
        dest = _NO_ROWS if order is None else order
        if J is None:   # the pairs are not written: search the cell list `off` directly
            if layout.direct is None:
                layout.direct = Direct(layout.plan, layout.span)
            if not search(layout.direct, f, backend, off, groups, K, S, O, out, cnt,
                          dest):
                return None
        else:
            from swarmdsl.runtime.compiled.kernels import sums_kernel

            args = (groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, dest,
                    threads.chunks(m))
            if not run_kernel(layout, backend, args, sums_kernel):
                return None
        for p in batch:
            self.partners.setdefault(p, set()).update(q for q in batch if q is not p)
        return {p: (out[g], cnt[g]) for g, p in enumerate(batch)}

    def note(self, part) -> str:
        """What `-v` adds to `part`'s line: the siblings it shared a loop with."""
        got = sorted((q.span.line, q.span.col) for q in self.partners.get(part, ()))
        return f" (one pair loop with {', '.join(f'{a}:{b}' for a, b in got)})" if got else ""


class _Layout:
    """One batch's shared tables (owner columns read once however many siblings read
    them; neighbour columns once each) and its kernel, compiled on first use."""

    def __init__(self, siblings, batch):
        self.span = batch[0].span
        self.kernel = None
        self.reason = None
        self.S = None   # the owner table, written again each call (nothing else holds it)
        self.direct = None   # its kernel that searches the cell list, made on first use
        self.hoisted, self.others, others_key = [], [], []
        s_at, o_at = {}, {}
        self.s_width = o_width = 0
        trees = []
        for p in batch:
            s_map, o_map = {}, {}
            c = 0
            for (key, vt, fn), shape in zip(p.hoisted, siblings.shapes[p], strict=True):
                if shape not in s_at:
                    s_at[shape] = self.s_width
                    self.hoisted.append((key, vt, fn))
                    self.s_width += 2 if vt == VEC else 1
                for w in range(2 if vt == VEC else 1):
                    s_map[c + w] = s_at[shape] + w
                c += 2 if vt == VEC else 1
            c = 0
            for (cat, col, vt), reader in zip(p.plan.others, p.others, strict=True):
                if (cat, col) not in o_at:
                    o_at[(cat, col)] = o_width
                    self.others.append(reader)
                    others_key.append((cat, col, vt))
                    o_width += 2 if vt == VEC else 1
                for w in range(2 if vt == VEC else 1):
                    o_map[c + w] = o_at[(cat, col)] + w
                c += 2 if vt == VEC else 1
            plan = p.plan
            trees.append((plan.width, remap(plan.cond, s_map, o_map),
                          tuple(remap(t, s_map, o_map) for t in plan.each)))
        self.others_key = tuple(others_key)
        self.plan = ("siblings", tuple(trees))
