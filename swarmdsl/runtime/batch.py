"""R replicas of one program as one vectorised simulation, each bit-identical to its solo run.

A sweep's runs are mostly small (6-400 agents), and a small run spends nearly all its
time in the fixed cost of a tick (a closure call per status, per aggregate, per draw),
not in its agents. A batch lays R runs of ONE compiled program (same params, different
seeds) side by side in one agent store, so every closure runs once per tick for all of
them. What keeps each replica exactly its solo run:

- rows: replica-major, replica r's agents contiguous (`bounds[r]:bounds[r+1]`) and in
  its solo run's row order, so `flatnonzero(status == code)` keeps each replica's order
  and every elementwise operation gives the solo bits;
- draws: the counter-based streams key a call by the run's seed; a batch keys each row
  by its own replica's (`ReplicaRandom`), the same integers as the solo draw;
- neighbours: one table per replica, built by the backend's own search on the replica's
  positions (so each owner sees its solo neighbours in its solo order, and sums round
  alike), laid end to end: pairs never cross a replica;
- placement: each replica placed by the solo code with its own random source;
- robot bodies, sensing models, messages and behaviour trees: their runtime works row
  by row or pair by pair (a tree's memory is agent columns); where it decides something
  for the whole run (whether anyone moves with noise) it asks `run_any`, answered per
  replica;
- objectives: toward a point or a region, per agent (regions are shapes, the same in
  every replica); toward another kind's agents, the nearest one searched among the
  replica's own agents (`replica_bounds`), as its solo run searches;
- `nn()`: one forward pass over every replica's rows, each row computed on its own
  (`runtime/nn.py`), so a row's output does not depend on how many rows share the pass;
- metrics: evaluated once for the batch, each swarm aggregate reducing every replica's
  values as its solo run reduces its own (`metric_rows`).

What cannot be made exact yet is refused before anything runs (`batch_refusal`), naming
the construct and its line: the caller then runs those programs solo.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from swarmdsl.errors import NotPerReplica, SwarmOptionError, SwarmRuntimeError
from swarmdsl.runtime import backends
from swarmdsl.runtime.agents import AgentStore
from swarmdsl.runtime.batch_fields import join_environments, view_environment
from swarmdsl.runtime.batch_random import BatchRandom
from swarmdsl.runtime.messaging import Messenger
from swarmdsl.runtime.metrics import SWARM_MEASURES, evaluate, swarm_frame
from swarmdsl.runtime.protocols import hooks
from swarmdsl.runtime.randomness import RandomSource
from swarmdsl.runtime.simulation import MAX_SEED, Simulation
from swarmdsl.runtime.spatial import PairTable, build_pairs, build_replica_pairs
from swarmdsl.runtime.world import World

# ---- what is batched ----

# Actions a batch runs exactly: messages, beliefs, LEDs, map notes, path memories and
# label sets are agent columns; deposits go to each replica's grid (`batch_fields.py`).
BATCHED_ACTIONS = frozenset({"broadcast", "believe", "led", "note",
                             "remember", "retrace", "clear", "learn", "deposit"})
# Calls a batch runs exactly besides the built-in functions and draws (`ops/functions.py`):
# the aggregates (`compiler/builtins.AGGREGATES`), neighbours, and `previous`
# (properties: their monitors read each replica's view).
CORE_CALLS = frozenset({"count", "sum", "mean", "min", "max", "nearest", "any", "all",
                        "neighbors", "previous", "heard", "trilaterate",
                        "move_to", "wait",   # behaviour trees' long actions
                        "recall", "age", "known", "best",   # internal maps
                        "len", "choose", "at_edge",   # path memories, directions
                        "target", "toward", "approach", "arrived",   # objectives
                        # one forward pass for the batch: each row on its own, the
                        # same bits for any row count (`runtime/nn.py`)
                        "nn",
                        # fields, read on each replica's grid (`batch_fields.py`)
                        "sample", "gradient", "ahead", "cone", "follow",
                        # regions: shapes, the same in every replica
                        "circle", "rect", "polygon", "inside", "touching",
                        "distance_to", "centre", "center", "touched",
                        "knows", "unknown",   # food labels: agent columns
                        # metrics of the swarm's geometry, measured per replica
                        *SWARM_MEASURES})
# The runtime plug-ins a batch runs per replica, by the module whose hook adds them:
# robot profiles' sensing models, bodies (speed limits, motion noise, odometry, LEDs)
# and messages. Each works row by row or pair by pair, with draws by rows.
BATCHED_EXTENSIONS = frozenset({"swarmdsl.compiler.lang_sensing",
                                "swarmdsl.compiler.lang_beliefs",
                                "swarmdsl.compiler.lang_messaging",
                                "swarmdsl.compiler.tree_codegen",   # trees' columns
                                "swarmdsl.compiler.lang_maps",   # maps' columns
                                "swarmdsl.compiler.lang_nn",   # models, read-only
                                # the environment: fields (one grid per replica),
                                # regions, path memories, label sets, direction choice
                                "swarmdsl.compiler.lang_fields"})


def _walk(node):
    """`node` and every AST node under it (the runtime knows the AST only as nodes with
    `children()`, a `span` and a class name)."""
    stack = [node]
    while stack:
        n = stack.pop()
        yield n
        stack.extend(n.children())


def batch_refusal(program) -> str | None:
    """Why `program` cannot run as replicas bit-identical to its solo runs, in words a
    user reads in `-v` (e.g. "fields are not batched yet (`field pheromone`, line 12)");
    None when it can."""
    from swarmdsl.ops.functions import FUNCTIONS

    calls = CORE_CALLS | BATCHED_ACTIONS | set(FUNCTIONS) | {   # a tree's actions are
        # calls; leaves that tick a named tree
        n.name for n in _walk(program.info.tree) if type(n).__name__ == "TreeDecl"}
    for node in sorted(_walk(program.info.tree), key=_where):
        name = type(node).__name__
        why = _refused_node(node, name)
        if why is None and name == "Call" and node.name not in calls:
            why = f"`{node.name}()` is not batched yet"
        if name == "ActionStmt" and node.name not in BATCHED_ACTIONS:
            why = f"the action `{node.name}` is not batched yet"
        if why is not None:
            return f"{why} ({_construct(node)}, line {node.span.line})"
    for make in program.extensions:   # a plug-in no declaration above accounts for
        if getattr(make, "__module__", None) not in BATCHED_EXTENSIONS:
            return (f"a runtime extension of this program ({make.__module__}) is not "
                    "batched yet")
    return None


def _refused_node(node, name: str) -> str | None:
    """Why a declaration's run-time state is not laid out per replica yet, or None."""
    if name == "FieldDecl":
        for opt in node.options:   # a twin sampled anew every tick, drawing per node:
            if opt.name == "twin" and _reads_tick(opt) and _draws(opt):   # each run's
                return "a physical twin that draws at every tick is not batched yet"
    return None


def _reads_tick(node) -> bool:
    return any(type(n).__name__ == "Name" and n.id == "tick" for n in _walk(node))


def _draws(node) -> bool:
    from swarmdsl.ops.functions import FUNCTIONS

    return any(type(n).__name__ == "Call" and getattr(FUNCTIONS.get(n.name), "random", False)
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
    if name == "ActionStmt":
        return f"`{node.name}(...)`"
    if name == "Call":
        return f"`{node.name}(...)`"
    return "a behaviour tree" if name.startswith("Tree") else "a field reading"


# ---- faults ----

class ReplicaFault(SwarmRuntimeError):
    """A runtime fault of one replica of a batch: `replica`, its `seed`, and `error`, the
    fault its solo run raises at that tick. The batch is then unusable."""

    def __init__(self, replica: int, error: SwarmRuntimeError, seed: int | None = None):
        who = f"replica {replica}" + ("" if seed is None else f" (seed {seed})")
        super().__init__(f"{who}: {error.message}", error.span, error.hint)
        self.replica = replica
        self.seed = seed
        self.error = error


# ---- the batch ----

class BatchedSimulation(Simulation):
    """R replicas of `program` with `seeds`, stepped together. `replica(r)` is replica r
    as a solo `Simulation` would be at the same tick; `metric_rows()` every replica's
    metrics."""

    def __init__(self, program, seeds: Sequence[int], backend: str | None = None,
                 work: float | None = None):
        from swarmdsl.runtime.arguments import check_program, real, whole

        check_program(program, "BatchedSimulation")
        try:
            seeds = [whole("seed", s, 0, MAX_SEED) for s in seeds]
        except TypeError:
            raise SwarmOptionError(f"seeds must be a list of whole numbers, got "
                                   f"{type(seeds).__name__}") from None
        if not seeds:
            raise SwarmOptionError("a batch needs at least one seed")
        if work is not None:
            work = real("work", work, 0.0, float("inf"))
        why = batch_refusal(program)
        if why is not None:
            raise SwarmOptionError(f"this program cannot run as a batch: {why}")
        self.program = program
        self.layout = None
        self.backend = backends.make(backend, work, program)
        self.backend.prepare(program)
        self.seeds = seeds
        self.replicas = len(seeds)
        self.seed = seeds[0]
        w = program.world
        self.world = World(w.width, w.height, w.grid, w.edges, w.edge_weight, w.edge_range)
        self.tick = 0
        self.pairs = None
        self.environment = self.sensing = self.maps = None
        self.record_columns = {}
        stores, made_by_replica = [], []
        try:
            with np.errstate(all="ignore"):
                for r, seed in enumerate(seeds):   # each replica placed by the solo code
                    self.agents = AgentStore(program.var_specs)
                    self.rng = self._solo_random(seed)
                    # its plug-ins made on its own store (a tree's columns); they keep no
                    # state of a replica's own, so the first's serve the whole batch
                    made = [make(self) for make in program.extensions]
                    if r == 0:
                        self.extensions = made
                    made_by_replica.append(made)
                    try:
                        for kind in program.kinds:
                            self._place(kind)
                        for hook in hooks(made, "after_placement"):
                            hook(self)
                    except SwarmRuntimeError as exc:
                        raise ReplicaFault(r, exc, seed) from exc
                    stores.append(self.agents)
        except MemoryError:
            total = sum(k.count for k in program.kinds) * len(seeds)
            raise SwarmRuntimeError(f"not enough memory to place {total:,} agents") from None
        sizes = np.array([s.n for s in stores], np.int64)
        self.bounds = np.zeros(len(seeds) + 1, np.int64)
        np.cumsum(sizes, out=self.bounds[1:])
        self.agents = _joined(program.var_specs, stores)
        join_environments(self, made_by_replica)   # fields: one grid per replica
        self.replica_of_row = np.repeat(np.arange(len(seeds)), sizes)
        self.rng = BatchRandom(seeds, self.replica_of_row, self.backend.random_units_rows)
        # how many threads the batch's kernels use, and why (the backend's own)
        self.threads, self.threads_why = self.backend.batch_threads(int(self.bounds[-1]))

    def _solo_random(self, seed: int) -> RandomSource:
        rng = RandomSource(seed)
        rng.compiled_units = self.backend.random_units
        return rng

    # ---- ticks ----
    def step(self) -> None:
        before = dict(self.agents.cols)   # the tick's start, to find a fault's replica
        try:
            with self.backend.threads_limited(self.threads):
                super().step()
        except ReplicaFault:
            raise
        except SwarmRuntimeError as exc:
            raise self._fault(before, exc) from exc

    def _fault(self, before: dict, exc: SwarmRuntimeError) -> ReplicaFault:
        """The replica that faulted: each replica's tick rerun alone from the same
        start, the first that faults (with its own solo message)."""
        for r in range(self.replicas):
            solo = self._view(r, before, copy=True, backend=backends.make(self.backend.name))
            solo.rng = self._solo_random(solo.seed)   # this tick's draws not yet made
            try:
                solo.step()
            except SwarmRuntimeError as err:
                return ReplicaFault(r, err, self.seeds[r])
            except Exception:   # noqa: BLE001 - the batch's error is reported below
                continue
        return ReplicaFault(0, SwarmRuntimeError(
            f"the batch failed where no replica fails alone: {exc.message}", exc.span),
            self.seeds[0])

    def _build_pairs(self, pos, radius: float):
        """One table per replica by the backend's search (the solo run's pairs in its
        order), laid end to end with rows shifted to the batch's."""
        box, b = self.world.box, self.bounds
        table = self.backend.build_pairs(pos, radius, box, b)
        if table is not None:
            return table
        tables = [self.backend.pairs_table(pos[b[r]:b[r + 1]], radius, box)
                  for r in range(self.replicas)]
        return _joined_pairs(radius, tables, b)

    def reference_pairs(self, radius: float) -> PairTable:
        pos, box, b = self.agents.cols["pos"], self.world.box, self.bounds
        table = build_replica_pairs(pos, b, radius, box)
        if table is not None:
            return table
        return _joined_pairs(radius, [build_pairs(pos[b[r]:b[r + 1]], radius, box)
                                      for r in range(self.replicas)], b)

    def replicas_of(self, rows) -> np.ndarray:
        return self.replica_of_row[rows]

    def replica_bounds(self) -> np.ndarray:
        return self.bounds

    def run_any(self, mask: np.ndarray) -> np.ndarray:
        rep = self.replica_of_row
        return (np.bincount(rep[mask], minlength=self.replicas) > 0)[rep]

    # ---- views ----
    def replica(self, r: int) -> Simulation:
        """Replica r as a solo `Simulation` at the current tick (its columns are views
        of the batch's: read-only, valid until the next `step()`)."""
        r = int(r)
        if not 0 <= r < self.replicas:
            raise SwarmOptionError(f"replica must be 0 to {self.replicas - 1}, got {r}")
        return self._view(r, self.agents.cols, copy=False, backend=self.backend)

    def _view(self, r: int, cols: dict, copy: bool, backend) -> Simulation:
        lo, hi = int(self.bounds[r]), int(self.bounds[r + 1])
        sim = Simulation.__new__(Simulation)
        sim.program, sim.layout, sim.backend = self.program, None, backend
        sim.seed = self.seeds[r]
        sim.rng = self._solo_random(sim.seed)
        sim.rng.tick, sim.rng._calls = self.rng.tick, self.rng.calls_of(r)
        sim.world, sim.tick, sim.pairs = self.world, self.tick, None
        sim.environment = sim.sensing = sim.maps = None
        sim.record_columns = dict(self.record_columns)   # read from the view it is given
        store = AgentStore.__new__(AgentStore)
        store.var_specs, store.extra_specs = self.agents.var_specs, {}
        def part():
            return {k: (v[lo:hi].copy() if copy else v[lo:hi]) for k, v in cols.items()}
        store.cols = part()
        store.declared = {k: v[lo:hi] for k, v in self.agents.declared.items()}
        sim.agents = store
        with np.errstate(all="ignore"):
            sim.extensions = [make(sim) for make in self.program.extensions]
        # made on the view they may have added their columns afresh (a tree's): the
        # replica's own values again
        store.cols = part()
        store.extra_specs = dict(self.agents.extra_specs)
        view_environment(sim, self, r, copy)   # the replica's own field grids
        for mine, theirs in zip(self.extensions, sim.extensions, strict=True):
            if isinstance(mine, Messenger):   # this tick's deliveries, for its links
                theirs.table = _table_part(mine.table, lo, hi)
        return sim

    def metric_rows(self) -> np.ndarray:
        """(replicas, k) float64: every replica's metrics at the current tick, bit for
        bit what `MetricLog.sample` computes on its solo run. Each metric is evaluated
        once for the whole batch, its swarm aggregates reducing each replica's values
        as the solo run reduces its own (`segments`); a metric that cannot be (a swarm
        aggregate inside another, or with an `else`) replica by replica."""
        metrics = self.program.metrics
        out = np.empty((self.replicas, len(metrics)))
        frame = swarm_frame(self, self._segments)
        for j, m in enumerate(metrics):
            got = None
            try:
                with np.errstate(all="ignore"):
                    got = np.asarray(m.value(frame), dtype=float)
            except NotPerReplica:
                got = None
            except Exception:   # noqa: BLE001 - a fault is found, and named, per replica
                got = None
            if got is not None and got.shape == ():   # no aggregate: the same for all
                got = np.full(self.replicas, float(got))
            if got is not None and got.shape == (self.replicas,):
                out[:, j] = got
                continue
            for r in range(self.replicas):
                try:
                    out[r, j] = evaluate([m], self.replica(r))[0]
                except SwarmRuntimeError as exc:
                    raise ReplicaFault(r, exc, self.seeds[r]) from exc
        return out

    def _segments(self, rows: np.ndarray) -> np.ndarray:
        """(R+1,) where each replica's rows start in the sorted batch rows `rows`."""
        return np.searchsorted(rows, self.bounds)

    def status_counts(self) -> dict[str, int]:   # the whole batch's
        return super().status_counts()


def _joined(var_specs, stores: list[AgentStore]) -> AgentStore:
    """One store of every replica's agents, replica-major."""
    out = AgentStore(var_specs)
    for name, (tail, dtype, fill) in stores[0].extra_specs.items():
        out.add_column(name, tail, dtype, fill)
    for name in out.cols:
        out.cols[name] = np.concatenate([s.cols[name] for s in stores])
    for name in out.declared:
        out.declared[name] = np.concatenate([s.declared[name] for s in stores])
    return out


def _table_part(table: PairTable, lo: int, hi: int) -> PairTable:
    """The pairs of owners lo:hi of a batch's table, as their replica's own table."""
    if table.offsets.size <= hi:   # not built for this store (before the first tick)
        return table
    p0, p1 = int(table.offsets[lo]), int(table.offsets[hi])
    return PairTable(table.radius, table.offsets[lo:hi + 1] - p0, table.j[p0:p1] - lo,
                     table.dist[p0:p1], table.delta[p0:p1])


def _joined_pairs(radius: float, tables: list[PairTable], bounds) -> PairTable:
    """The replicas' tables end to end: owners and neighbours shifted to batch rows."""
    sizes = np.array([t.j.size for t in tables], np.int64)
    first = np.zeros(len(tables), np.int64)
    np.cumsum(sizes[:-1], out=first[1:])
    offsets = np.empty(int(bounds[-1]) + 1, np.int64)
    for r, t in enumerate(tables):
        offsets[bounds[r]:bounds[r + 1]] = t.offsets[:-1] + first[r]
    offsets[-1] = int(sizes.sum())
    shift = np.repeat(bounds[:-1], sizes)
    j = np.concatenate([t.j for t in tables]) + shift
    i = np.concatenate([t.i for t in tables]) + shift
    dist = np.concatenate([t.dist for t in tables])
    delta = np.concatenate([t.delta for t in tables]).reshape(-1, 2)
    return PairTable(radius, offsets, j, dist, delta, i)
