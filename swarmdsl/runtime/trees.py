"""Behaviour trees ticked for every agent of a status at once.

Each node's `tick(f, mask)` runs over one agent frame: `mask (M,) bool` says which rows
tick the node this tick (masks flow down), and it returns `(succ, fail)` bool arrays
(results flow up; running = mask & ~succ & ~fail). There is no loop over agents: a
composite loops over its children, a leaf evaluates one closure over the frame.

Per-agent memory (the running child, repeat/retry counters, timeout clocks, parallel
results, cooldown deadlines) lives in `AgentStore` columns named `tree<T>:<node>:<what>`,
so it survives removal and compaction. A node's memory is valid only if the node was
ticked on the previous tick (its stamp column holds that tick) *and* the tree was: a
node that completes simply does not write its stamp, a node that is not ticked (a
reactive composite moved on, a fallback succeeded earlier) is thereby reset, and so is
every node when the agent enters the status. Only a parallel that completes with
children still running, and a timeout that fires, halt their subtree explicitly.
Cooldown deadlines persist while the agent stays in the status (tree stamp only).

As with path memories, only the owning agent reads these columns, so nodes write them
straight to the store: nobody can observe the order of writes within a tick.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from swarmdsl.errors import Span
from swarmdsl.ops.targets import Refused
from swarmdsl.runtime.columns import LEAF_RECORDED, RESULT_RECORDED

NEVER = -2  # a stamp no tick minus one can equal
LEAF_COLUMN = "tree:leaf"  # each agent's active leaf (program-wide leaf id; 0: none)
RESULT_COLUMN = "tree:result"  # each agent's tree result this tick, code + 1 (0: none)
RESULT_KEY = "@tree"  # frame local holding this tick's result codes (never an identifier)
RUNNING, SUCCESS, FAILURE = 0, 1, 2


class Layout:
    """The memory columns of one program's trees, handed out as nodes are compiled."""

    def __init__(self):
        self.columns: list[tuple[str, object, object]] = []   # (name, dtype, fill)
        self.trees = 0

    def new_tree(self) -> int:
        self.trees += 1
        return self.trees - 1

    def column(self, name: str, dtype, fill) -> str:
        self.columns.append((name, dtype, fill))
        return name


class TreeMemory:
    """Runtime extension: adds the tree columns to the agent store (before placement,
    so placed agents get their fill values). All its state is in agent columns."""

    def __init__(self, sim, layout: Layout):
        for name, dtype, fill in layout.columns:
            sim.agents.add_column(name, (), dtype, fill)

    def begin_tick(self, sim) -> None:
        for name in (LEAF_COLUMN, RESULT_COLUMN):
            column = sim.agents.cols.get(name)
            if column is not None:
                column[:] = 0   # agents no tree ticks this tick have no leaf, no result

    def decorate_snapshot(self, sim, snap) -> None:
        leaf = sim.agents.cols.get(LEAF_COLUMN)
        if leaf is not None:
            snap.tree_leaf = leaf.copy()
            snap.tree_leaf_names = ["", *sim.program.tree_leaf_names]
            snap.tree_leaf_paths = ["", *sim.program.tree_leaf_paths]

    def state_dict(self, sim) -> dict:
        return {}

    def load_state(self, sim, d) -> None:
        pass


class Ctx:
    """What one tree tick shares among its nodes: the frame and the tree's validity."""

    __slots__ = ("f", "cols", "tick", "tree_valid", "leaf")

    def __init__(self, f, tree_valid):
        self.f = f
        self.cols = f.sim.agents.cols
        self.tick = f.tick
        self.tree_valid = tree_valid
        # the last leaf ticked per row, only while someone records it
        self.leaf = np.zeros(f.n, np.int32) if LEAF_COLUMN in self.cols else None


class Node:
    stateful = False
    can_run = True      # may return running; the compiler clears it when it cannot
    leaf_id = 0         # leaves: their program-wide id (1, 2, ...)
    span: Span

    def tick(self, c: Ctx, mask):  # pragma: no cover - abstract
        raise NotImplementedError

    def halt(self, c: Ctx, mask) -> None:
        """Forget this subtree's memory for the rows in `mask`."""
        for child in self.children():
            child.halt(c, mask)

    def children(self):
        return ()


class Stateful(Node):
    """A node with a stamp column and one value column."""

    stateful = True

    def __init__(self, layout: Layout, tree: int, index: int, what: str, dtype, fill):
        self.stamp = layout.column(f"tree{tree}:{index}:stamp", np.int64, NEVER)
        self.value = layout.column(f"tree{tree}:{index}:{what}", dtype, fill)
        self.fill = fill

    def read(self, c: Ctx):
        idx = c.f.idx
        valid = c.tree_valid & (np.take(c.cols[self.stamp], idx) == c.tick - 1)
        return np.where(valid, np.take(c.cols[self.value], idx), self.fill)

    def write(self, c: Ctx, mask, values) -> None:
        """Keep `values` for the rows in `mask` until the next tick."""
        if mask.any():
            rows = c.f.idx[mask]
            c.cols[self.value][rows] = np.broadcast_to(values, mask.shape)[mask]
            c.cols[self.stamp][rows] = c.tick

    def halt(self, c: Ctx, mask) -> None:
        if mask.any():
            c.cols[self.stamp][c.f.idx[mask]] = NEVER
        super().halt(c, mask)


def none_of(n):
    """An all-false row mask: no row has this result."""
    return np.zeros(n, dtype=bool)


def no_result(n):
    """Neither success nor failure for any of `n` rows: a node no row ticks."""
    return none_of(n), none_of(n)


def tick_rows(node: Node, c: Ctx, mask):
    """Tick `node` for the rows in `mask`, or not at all when there are none."""
    return node.tick(c, mask) if mask.any() else no_result(mask.size)


def per_row(value, n) -> np.ndarray:
    """A per-agent count (repeat N, wait N, ...): compiled counts are already whole
    (rounded down, NaN refused by `tree_codegen`); here only spread to every row."""
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (n,))


# ---- composites ----

class Sequence(Stateful):
    """`sequence` (memory: resumes at the running child) or `reactive sequence`
    (restarts at the first child every tick). `fallback` is the same walk with success
    and failure swapped: it stops at the first child that does not fail."""

    def __init__(self, layout, tree, index, kids, reactive: bool, fallback: bool, span):
        # With no child that can be running, both forms behave alike: no memory needed.
        self.stateful = not reactive and any(k.can_run for k in kids)
        if self.stateful:
            super().__init__(layout, tree, index, "child", np.int64, 0)
        self.kids, self.reactive, self.fallback, self.span = kids, reactive, fallback, span

    def children(self):
        return self.kids

    def halt(self, c, mask):
        if self.stateful:
            Stateful.halt(self, c, mask)
        else:
            Node.halt(self, c, mask)

    def tick(self, c, mask):
        n = mask.size
        start = self.read(c) if self.stateful else None
        pending = mask.copy()      # rows still walking along the children
        running = none_of(n)
        at = np.zeros(n, dtype=np.int64) if self.stateful else None
        for i, child in enumerate(self.kids):
            go = pending if start is None else pending & (start <= i)
            if not go.any():
                if start is None or not pending.any():
                    break
                continue
            s, fl = child.tick(c, go)
            ends = fl if not self.fallback else s   # the result that stops the walk
            if child.can_run:
                r = go & ~s & ~fl
                running |= r
                if at is not None:
                    at[r] = i
                ends = ends | r
            pending ^= ends          # ends lie within pending
        if at is not None:
            self.write(c, running, at)
        stop = mask ^ pending ^ running   # the rows a child stopped, other than running
        if self.fallback:
            return stop, pending
        return pending, stop


class Parallel(Stateful):
    """`parallel K { ... }`: ticks its children side by side; success once K of them
    succeeded, failure once so many failed that K successes are out of reach. The memory
    form does not re-tick a child that already finished; `reactive parallel` re-ticks
    every child every tick. On completion, still-running children are halted."""

    def __init__(self, layout, tree, index, kids, k: int, reactive: bool, span):
        super().__init__(layout, tree, index, "done", np.int64, 0)
        self.kids, self.k, self.reactive, self.span = kids, k, reactive, span

    def children(self):
        return self.kids

    def tick(self, c, mask):
        n = mask.size
        bits = self.read(c) if not self.reactive else np.zeros(n, dtype=np.int64)
        nsucc = np.zeros(n, dtype=np.int64)
        nfail = np.zeros(n, dtype=np.int64)
        for i, child in enumerate(self.kids):
            sb, fb = np.int64(1 << (2 * i)), np.int64(1 << (2 * i + 1))
            had_s, had_f = (bits & sb) != 0, (bits & fb) != 0
            go = mask & ~had_s & ~had_f
            s, fl = tick_rows(child, c, go)
            bits = bits | np.where(s, sb, 0) | np.where(fl, fb, 0)
            nsucc += (had_s | s)
            nfail += (had_f | fl)
        succ = mask & (nsucc >= self.k)
        fail = mask & ~succ & (nfail > len(self.kids) - self.k)
        done = succ | fail
        if done.any():
            for child in self.kids:
                child.halt(c, done)
        if not self.reactive:
            self.write(c, mask & ~done, bits)
        return succ, fail


# ---- decorators ----

class Decorator(Node):
    """A node over one child; a tick none of its rows take part in does nothing (no
    count is evaluated, no memory read)."""

    child: Node

    def children(self):
        return (self.child,)

    def tick(self, c, mask):
        if not mask.any():
            return no_result(mask.size)
        return self.decorate(c, mask)

    def decorate(self, c: Ctx, mask):  # pragma: no cover - abstract
        raise NotImplementedError


class Invert(Decorator):
    def __init__(self, child, mode: str, span):
        self.child, self.mode, self.span = child, mode, span

    def decorate(self, c, mask):
        s, fl = self.child.tick(c, mask)
        if self.mode == "invert":
            return fl, s
        if self.mode == "force success":
            return s | fl, none_of(mask.size)
        return none_of(mask.size), s | fl     # force failure


class Repeat(Decorator, Stateful):
    """`repeat N`: the child must succeed N times, one run per tick (the next run starts
    next tick); a failure fails it. `retry N` is the dual: N attempts, a success
    succeeds. N of 0 or less finishes at once (repeat: success; retry: failure)."""

    def __init__(self, layout, tree, index, child, n, retry: bool, span):
        super().__init__(layout, tree, index, "count", np.int64, 0)
        self.child, self.n, self.retry, self.span = child, n, retry, span

    def decorate(self, c, mask):
        size = mask.size
        limit = per_row(self.n(c.f), size)
        none = mask & ~(limit >= 1)
        go = mask & ~none
        count = self.read(c)
        s, fl = tick_rows(self.child, c, go)
        again, other = (fl, s) if self.retry else (s, fl)
        count = count + again
        finished = again & (count >= limit)
        running = go & ~finished & ~other
        self.write(c, running, count)
        if self.retry:
            return other, none | finished
        return none | finished, other


class Timeout(Decorator, Stateful):
    """`timeout N`: the child gets N ticks; still running on the Nth, it is halted and
    the timeout fails."""

    def __init__(self, layout, tree, index, child, n, span):
        super().__init__(layout, tree, index, "elapsed", np.int64, 0)
        self.child, self.n, self.span = child, n, span

    def decorate(self, c, mask):
        size = mask.size
        elapsed = self.read(c) + 1
        limit = per_row(self.n(c.f), size)    # counts are read before the child runs
        s, fl = self.child.tick(c, mask)
        r = mask & ~s & ~fl
        late = r & (elapsed >= limit)
        if late.any():
            self.child.halt(c, late)
        self.write(c, r & ~late, elapsed)
        return s, fl | late


class Cooldown(Decorator):
    """`cooldown N`: after its child finishes (either way), fails at once without
    ticking the child for the next N ticks. The deadline is kept while the agent stays
    in the status, whether or not the node is ticked meanwhile."""

    def __init__(self, layout, tree, index, child, n, span):
        self.ready = layout.column(f"tree{tree}:{index}:ready", np.int64, -1)
        self.child, self.n, self.span = child, n, span

    def decorate(self, c, mask):
        size = mask.size
        idx = c.f.idx
        ready = np.take(c.cols[self.ready], idx)   # reset when the agent entered
        cooling = mask & (c.tick < ready)
        go = mask & ~cooling
        n = per_row(self.n(c.f), size)            # counts are read before the child runs
        s, fl = tick_rows(self.child, c, go)
        finished = s | fl
        if finished.any():
            c.cols[self.ready][idx[finished]] = c.tick + 1 + np.floor(n[finished]).astype(
                np.int64)
        return s, fl | cooling


class Subtree(Node):
    """A named tree used in place: ticks as its root (kept for drawing and recording)."""

    def __init__(self, name: str, root: Node, span):
        self.name, self.root, self.span = name, root, span

    def children(self):
        return (self.root,)

    def tick(self, c, mask):
        return self.root.tick(c, mask)


# ---- the rows: one per kind of composite and decorator ----

NOT_ON_A_KILOBOT = Refused("behaviour trees are not translated to C yet")


@dataclass(frozen=True)
class NodeRow:
    """One kind of tree node, with what every stage needs of it, so a kind is declared
    once: the parser reads its keyword from the grammar (`COUNTED_KW`, `INVERT_KW`,
    `FORCE_KW`, `SEQ_KW`, `PARALLEL_KW`), and the checker (`compiler/lang_trees.py`),
    the outcome analysis (`compiler/tree_outcomes.py`), the compiler
    (`compiler/tree_codegen.py`), the batch and the exporter all look the kind up here.
    A kind without a row is an internal error wherever it is met
    (`decorator_row`, `composite_row`), never another kind's behaviour.

    - `name`: the kind as the AST holds it (`repeat`, `force success`, `sequence`).
    - `doc`: its one line (the language server's hover).
    - `make`: the node that ticks. A decorator's `make(layout, tree, index, child,
      count, span)` (`count` a closure of the frame, None when not `counted`); a
      composite's `make(layout, tree, index, kids, k, reactive, span)` (`k` parallel's
      threshold, else None).
    - `outcomes`: the results it can give (a sound subset of "SFR"), a decorator's from
      its child's and its constant count (None: known at run time; inf: `forever`), a
      composite's from its children's, `k` and `unreachable(i, word)`, told of a child
      that can never run.
    - `counted`: a decorator written with a count N; `forever`: N may be `forever`.
    - `batch`: a batch of replicas runs it (its memory is agent columns) or `Refused`.
    - `kilobot`: the exported C's form, or `Refused` (trees are not translated yet).
    """

    name: str
    doc: str
    make: Callable
    outcomes: Callable
    counted: bool = False
    forever: bool = False
    batch: bool | Refused = True
    kilobot: Refused = NOT_ON_A_KILOBOT


def _repeat_outcomes(retry: bool):
    def outcomes(child: frozenset, n) -> frozenset:
        done = "F" if retry else "S"
        if n is not None and n < 1:
            return frozenset(done)
        out = set(child)
        if n is None:
            out.add(done)      # a count known only at run time may be below 1
        if n == float("inf"):
            out.discard(done)  # `forever`: no number of runs ends it
        if done in child and (n is None or n > 1):
            out.add("R")       # another run starts next tick
        return frozenset(out)
    return outcomes


def _swap(table: dict):
    return lambda child, n: frozenset(table.get(x, x) for x in child)


# In the order the keywords are offered (completion, misspelt-keyword suggestions).
DECORATORS: dict[str, NodeRow] = {row.name: row for row in [
    NodeRow("repeat", "runs its child until it has succeeded N times, one run a tick; "
            "a failure fails it",
            lambda L, t, i, child, count, span: Repeat(L, t, i, child, count, False, span),
            _repeat_outcomes(retry=False), counted=True, forever=True),
    NodeRow("retry", "runs its child until it succeeds, at most N attempts, one a tick",
            lambda L, t, i, child, count, span: Repeat(L, t, i, child, count, True, span),
            _repeat_outcomes(retry=True), counted=True, forever=True),
    NodeRow("timeout", "fails (halting its child) when the child still runs after N ticks",
            lambda L, t, i, child, count, span: Timeout(L, t, i, child, count, span),
            lambda child, n: child | {"F"} if "R" in child else child, counted=True),
    NodeRow("cooldown", "after its child finishes, fails at once for the next N ticks",
            lambda L, t, i, child, count, span: Cooldown(L, t, i, child, count, span),
            lambda child, n: child | {"F"}, counted=True),
    NodeRow("invert", "swaps success and failure; running stays running",
            lambda L, t, i, child, count, span: Invert(child, "invert", span),
            _swap({"S": "F", "F": "S"})),
    NodeRow("force success", "succeeds whenever its child finishes, either way",
            lambda L, t, i, child, count, span: Invert(child, "force success", span),
            _swap({"F": "S"})),
    NodeRow("force failure", "fails whenever its child finishes, either way",
            lambda L, t, i, child, count, span: Invert(child, "force failure", span),
            _swap({"S": "F"})),
]}


def _walk_outcomes(go: str, stop: str, word: str):
    """`sequence` (go on success, stop on failure) and `fallback` (the dual)."""
    def outcomes(results: list, k, unreachable) -> frozenset:
        out = set()
        for i, r in enumerate(results):
            out |= r & {stop, "R"}
            if go not in r:
                if i + 1 < len(results):
                    unreachable(i + 1, word)
                return frozenset(out)
        return frozenset(out | {go})
    return outcomes


def _parallel_outcomes(results: list, k, unreachable) -> frozenset:
    n = len(results)
    k = int(k) if k is not None and abs(k) < n + 1 else 1   # else refused by the checker
    out = set()
    if sum("S" in r for r in results) >= k:
        out.add("S")
    if sum("F" in r for r in results) > n - k:
        out.add("F")
    if any("R" in r for r in results):
        out.add("R")
    return frozenset(out)


COMPOSITES: dict[str, NodeRow] = {row.name: row for row in [
    NodeRow("sequence", "ticks its children in order while they succeed",
            lambda L, t, i, kids, k, reactive, span: Sequence(L, t, i, kids, reactive,
                                                              False, span),
            _walk_outcomes("S", "F", "succeeds")),
    NodeRow("fallback", "ticks its children in order until one does not fail",
            lambda L, t, i, kids, k, reactive, span: Sequence(L, t, i, kids, reactive,
                                                              True, span),
            _walk_outcomes("F", "S", "fails")),
    NodeRow("parallel", "ticks its children side by side; succeeds once K succeeded",
            lambda L, t, i, kids, k, reactive, span: Parallel(L, t, i, kids, k, reactive,
                                                              span),
            _parallel_outcomes),
]}


def node_keywords() -> tuple[str, ...]:
    """The words that start a tree node, from the rows: the composites, `reactive`,
    then each decorator's first word (`force` once), for the parser's messages, the
    misspelt-keyword suggestions and the language server's completion."""
    words = [*COMPOSITES, "reactive"]
    for name in DECORATORS:
        if name.split()[0] not in words:
            words.append(name.split()[0])
    return tuple(words)


def counted_keywords() -> tuple[str, ...]:
    """The decorators written with a count (`repeat N`): the grammar's `COUNTED_KW`."""
    return tuple(r.name for r in DECORATORS.values() if r.counted)


def decorator_row(kind: str) -> NodeRow:
    """The row of decorator `kind`; a kind without one is a bug (the grammar has a
    keyword no row declares), never a default."""
    row = DECORATORS.get(kind)
    if row is None:
        raise LookupError(f"no row declares the tree decorator `{kind}` (runtime/trees.py)")
    return row


def composite_row(kind: str) -> NodeRow:
    """The row of composite `kind`; a kind without one is a bug, never a default."""
    row = COMPOSITES.get(kind)
    if row is None:
        raise LookupError(f"no row declares the tree composite `{kind}` (runtime/trees.py)")
    return row


# ---- the tree statement ----

class Tree:
    """One status's tree: ticked where `tree` stands in the body, for `f.active` rows."""

    def __init__(self, layout: Layout, tree: int, root: Node, span):
        self.root, self.span = root, span
        self.clocks = [n.ready for n in _nodes(root) if isinstance(n, Cooldown)]
        # A tree of instant nodes only keeps nothing between ticks.
        self.memory = bool(self.clocks) or any(n.stateful for n in _nodes(root))
        if self.memory:
            self.stamp = layout.column(f"tree{tree}:stamp", np.int64, NEVER)

    def __call__(self, f) -> None:
        mask = f.active.copy()
        cols = f.sim.agents.cols
        valid = None
        if self.memory:
            valid = np.take(cols[self.stamp], f.idx) == f.tick - 1
            entering = mask & ~valid
            if self.clocks and entering.any():   # deadlines of an earlier stay are void
                rows = f.idx[entering]
                for col in self.clocks:
                    cols[col][rows] = -1
        c = Ctx(f, valid)
        s, fl = self.root.tick(c, mask)
        result = s.view(np.int8) + fl.view(np.int8) * np.int8(FAILURE)
        f.locals[RESULT_KEY] = result
        if RESULT_COLUMN in cols:
            cols[RESULT_COLUMN][f.idx[mask]] = result[mask] + 1
        if self.memory:
            cols[self.stamp][f.idx[mask]] = f.tick
            f.effects.append(lambda: self._left(f))
        if c.leaf is not None:
            cols[LEAF_COLUMN][f.idx[mask]] = c.leaf[mask]

    def _left(self, f) -> None:
        """After the tick: agents that took a transition (even back to this status)
        leave the tree, so entering the status again starts it afresh."""
        gone = ~f.active
        if gone.any():
            f.sim.agents.cols[self.stamp][f.idx[gone]] = NEVER


def record_active_leaf(sim) -> None:
    """Track each agent's active leaf (the last leaf its tree ticked this tick: the
    running one, or the one that decided the result) and offer it to the recorder as
    the column `tree_leaf`, "LINE:COL text" of the leaf (empty outside trees), and the
    tree's own result as the column `tree_result` (`running`, `success`, `failure`)."""
    if LEAF_COLUMN not in sim.agents.cols:
        sim.agents.add_column(LEAF_COLUMN, (), np.int32, 0)
    if RESULT_COLUMN not in sim.agents.cols:
        sim.agents.add_column(RESULT_COLUMN, (), np.int32, 0)
    names = [None, *getattr(sim.program, "tree_leaf_names", [])]
    results = [None, "running", "success", "failure"]   # RUNNING, SUCCESS, FAILURE + 1
    extra = dict(sim.record_columns)
    extra[LEAF_RECORDED] = ("string", lambda s: (names, s.agents.cols[LEAF_COLUMN]))
    extra[RESULT_RECORDED] = ("string",
                              lambda s: (results, s.agents.cols[RESULT_COLUMN]))
    sim.record_columns = extra


def record_tree_memory(sim) -> None:
    """Offer every tree memory column to the recorder, as int64 columns named
    `tree:KIND.STATUS:NODE:WHAT` (NODE: the node's place in depth-first order, as in
    `swarmdsl graph`; WHAT: `stamp`, `child`, `count`, `elapsed`, `done`, `ready`) and
    `tree:KIND.STATUS:stamp`. Values are as stored: a node's value counts only when its
    stamp is the tick before (see docs/language-trees.md)."""
    prog = sim.program
    extra = dict(sim.record_columns)
    layout = getattr(prog, "tree_layout", None)
    for name, _dtype, _fill in layout.columns if layout is not None else ():
        tree, rest = name[len("tree"):].split(":", 1)
        kind, status, _t = prog.tree_index[int(tree)]
        extra[f"tree:{kind}.{status}:{rest}"] = ("int64", lambda s, _c=name: s.agents.cols[_c])
    sim.record_columns = extra


def _nodes(root: Node):
    stack = [root]
    while stack:
        n = stack.pop()
        yield n
        stack.extend(n.children())
