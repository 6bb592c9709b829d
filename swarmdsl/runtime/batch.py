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
- metrics: evaluated per replica on a solo view (`replica(r)`).

What cannot be made exact yet is refused before anything runs (`batch_refusal`), naming
the construct and its line: the caller then runs those programs solo.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from swarmdsl.errors import SwarmError, SwarmOptionError, SwarmRuntimeError
from swarmdsl.runtime.agents import AgentStore
from swarmdsl.runtime.compiled import make_backend
from swarmdsl.runtime.metrics import evaluate
from swarmdsl.runtime.randomness import (_C_CALL, _C_TICK, _MASK, AgentRandom, RandomSource,
                                         _mix, _mix_int, pair_ids, stream_key)
from swarmdsl.runtime.simulation import MAX_SEED, Simulation
from swarmdsl.runtime.spatial import PairTable
from swarmdsl.runtime.world import World

# ---- what is batched ----

# Declarations and statements whose runtime state is not laid out per replica yet.
_REFUSED_NODES = {
    "FieldDecl": "fields are not batched yet",
    "RegionDecl": "regions are not batched yet",
    "RobotDecl": "robot profiles (sensing, messaging, beliefs) are not batched yet",
    "ObjectiveDecl": "objectives are not batched yet",
    "TreeDecl": "behaviour trees are not batched yet",
    "TreeStmt": "behaviour trees are not batched yet",
    "TreeResult": "behaviour trees are not batched yet",
    "FieldAt": "field readings are not batched yet",
    "ActionStmt": "actions (deposit, messages, memories, maps) are not batched yet",
}
# Calls a batch runs exactly besides the built-in functions and draws (`ops/functions.py`):
# the aggregates (`compiler/builtins.AGGREGATES`), neighbours, and `previous`
# (properties: their monitors read each replica's view).
CORE_CALLS = frozenset({"count", "sum", "mean", "min", "max", "nearest", "any", "all",
                        "neighbors", "previous"})


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

    calls = CORE_CALLS | set(FUNCTIONS)
    for node in sorted(_walk(program.info.tree), key=_where):
        name = type(node).__name__
        why = _REFUSED_NODES.get(name)
        if why is None and name == "Call" and node.name not in calls:
            why = f"`{node.name}()` is not batched yet"
        if why is not None:
            return f"{why} ({_construct(node)}, line {node.span.line})"
    if program.extensions:   # a plug-in no declaration above accounts for
        return "a runtime extension of this program is not batched yet"
    return None


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


# ---- draws ----

class ReplicaRandom(AgentRandom):
    """`AgentRandom` over rows of several replicas: each agent's draws use its own
    replica's call key (`replica`: its index per agent), bit for bit the solo draw."""

    def __init__(self, source: BatchRandom, ids: np.ndarray, stream: str,
                 replica: np.ndarray):
        super().__init__(source, ids, stream)
        self.replica = replica

    def at(self, site: str) -> ReplicaRandom:
        return ReplicaRandom(self.source, self.ids, f"{self.stream}@{site}", self.replica)

    def pairs(self, seg, j, id_col) -> ReplicaRandom:
        return ReplicaRandom(self.source, pair_ids(np.take(self.ids, seg), np.take(id_col, j)),
                             f"{self.stream}/pairs", np.take(self.replica, seg))

    def subset(self, rows) -> ReplicaRandom:
        return ReplicaRandom(self.source, self.ids[rows], self.stream, self.replica[rows])

    def _unit(self, shape, open_low: bool = False) -> np.ndarray:
        lanes = int(np.prod(shape[1:], dtype=np.int64))
        base = np.take(self.source.call_key(self.stream), self.replica)
        compiled = self.source.compiled_rows
        if compiled is not None:
            return compiled(self.ids, base, lanes, open_low).reshape(shape)
        bits = self._bits(base, lanes)   # ids * C + base: elementwise, the solo bits
        u = (bits >> np.uint64(11)).astype(np.float64)
        if open_low:
            u += 1.0
        return (u * 2.0 ** -53).reshape(shape)

    def rejection(self, accept, low, high, batch: int = 8, rounds: int = 1000):
        raise SwarmRuntimeError("internal: rejection draws are not batched")


class BatchRandom(RandomSource):
    """The random source of a batch: one key per replica's seed, one call counter per
    stream (a stream is a call site of a status, drawn at most once a tick by a frame,
    so every replica's counter is the same)."""

    def __init__(self, seeds: Sequence[int], replica_of_row: np.ndarray, compiled_rows=None):
        super().__init__(seeds[0])
        self.seeds = list(seeds)
        self.keys = np.array([_mix_int(s ^ 0x5EED5EED5EED5EED) for s in self.seeds],
                             dtype=np.uint64)
        self.replica_of_row = replica_of_row
        self.compiled_rows = compiled_rows

    def call_key(self, stream: str) -> np.ndarray:
        """(R,) uint64: the key of the next call on `stream` in every replica."""
        count = self._calls.get(stream, 0)
        self._calls[stream] = count + 1
        tick = (self.tick & _MASK) * _C_TICK
        salt = (_mix_int(tick ^ stream_key(stream)) ^ (count * _C_CALL)) & _MASK
        return _mix(self.keys ^ np.uint64(salt))

    def rows(self, id_col, idx, stream: str) -> ReplicaRandom:
        return ReplicaRandom(self, np.take(id_col, idx), stream,
                             np.take(self.replica_of_row, idx))

    def agents(self, ids, stream: str):
        raise SwarmRuntimeError("internal: a batch draws by rows (`rows`), not by ids")


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
        self.backend = make_backend(backend, work, program)
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
        self.extensions = []
        stores = []
        try:
            with np.errstate(all="ignore"):
                for r, seed in enumerate(seeds):   # each replica placed by the solo code
                    self.agents = AgentStore(program.var_specs)
                    self.rng = self._solo_random(seed)
                    try:
                        for kind in program.kinds:
                            self._place(kind)
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
        self.rng = BatchRandom(seeds, np.repeat(np.arange(len(seeds)), sizes),
                               self.backend.random_units_rows)

    def _solo_random(self, seed: int) -> RandomSource:
        rng = RandomSource(seed)
        rng.compiled_units = self.backend.random_units
        return rng

    # ---- ticks ----
    def step(self) -> None:
        before = dict(self.agents.cols)   # the tick's start, to find a fault's replica
        try:
            super().step()
        except ReplicaFault:
            raise
        except SwarmRuntimeError as exc:
            raise self._fault(before, exc) from exc

    def _fault(self, before: dict, exc: SwarmRuntimeError) -> ReplicaFault:
        """The replica that faulted: each replica's tick rerun alone from the same
        start, the first that faults (with its own solo message)."""
        for r in range(self.replicas):
            solo = self._view(r, before, copy=True, backend=make_backend(self.backend.name))
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
        table = self.backend.replica_pairs(pos, b, radius, box)
        if table is not None:
            return table
        tables = [self.backend.pairs_table(pos[b[r]:b[r + 1]], radius, box)
                  for r in range(self.replicas)]
        return _joined_pairs(radius, tables, b)

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
        sim.rng.tick, sim.rng._calls = self.rng.tick, dict(self.rng._calls)
        sim.world, sim.tick, sim.pairs = self.world, self.tick, None
        sim.environment = sim.sensing = sim.maps = None
        sim.record_columns, sim.extensions = {}, []
        store = AgentStore.__new__(AgentStore)
        store.var_specs, store.extra_specs = self.agents.var_specs, {}
        store.cols = {k: (v[lo:hi].copy() if copy else v[lo:hi]) for k, v in cols.items()}
        store.declared = {k: v[lo:hi] for k, v in self.agents.declared.items()}
        sim.agents = store
        return sim

    def metric_rows(self) -> np.ndarray:
        """(replicas, k) float64: every replica's metrics at the current tick, bit for
        bit what `MetricLog.sample` computes on its solo run."""
        metrics = self.program.metrics
        out = np.empty((self.replicas, len(metrics)))
        for r in range(self.replicas):
            try:
                out[r] = evaluate(metrics, self.replica(r))
            except SwarmError as exc:
                if isinstance(exc, SwarmRuntimeError):
                    raise ReplicaFault(r, exc, self.seeds[r]) from exc
                raise
        return out

    def status_counts(self) -> dict[str, int]:   # the whole batch's
        return super().status_counts()


def _joined(var_specs, stores: list[AgentStore]) -> AgentStore:
    """One store of every replica's agents, replica-major."""
    out = AgentStore(var_specs)
    for name in out.cols:
        out.cols[name] = np.concatenate([s.cols[name] for s in stores])
    for name in out.declared:
        out.declared[name] = np.concatenate([s.declared[name] for s in stores])
    return out


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
