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

What cannot be made exact yet is refused before anything runs (`batch_refusal`, which
the program answers from its constructs' rows), naming the construct and its line: the
caller then runs those programs solo.
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
from swarmdsl.runtime.metrics import evaluate, swarm_frame
from swarmdsl.runtime.protocols import hooks
from swarmdsl.runtime.randomness import RandomSource
from swarmdsl.runtime.simulation import MAX_SEED, Simulation
from swarmdsl.runtime.spatial import PairTable, build_pairs, build_replica_pairs
from swarmdsl.runtime.world import World

# ---- what is batched ----

def batch_refusal(program) -> str | None:
    """Why `program` cannot run as replicas bit-identical to its solo runs, in words a
    user reads in `-v` (e.g. "the action `forward` is not batched yet (`forward(...)`,
    line 12)"); None when it can.

    The program answers (`RunnableProgram.batch_refusal`): whether a construct can be
    laid out per replica is declared on its row (a function, an aggregate, an action,
    an extension's call, a tree node, a plug-in factory), and the rows are the
    compiler's, which the runtime does not import (`compiler/batching.py` reads them).
    This module only runs what the program says it may."""
    return program.batch_refusal()


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
