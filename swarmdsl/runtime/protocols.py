"""What the runtime asks of the program it runs, of its backend and of its extensions.

The runtime imports neither the compiler nor a backend's code to run a program: a
`Simulation` takes any object that is a `RunnableProgram` (the compiler's `Program` is
one), reaches its backend only through `Backend` (the plug-ins of
`runtime/backends.py`: numpy's `runtime/numpy_backend/`, numba's `runtime/compiled/`)
and its plug-ins (fields, messaging, sensing, ...) only through
the hooks of `Extension`. These protocols are the whole contract: a method the runtime
calls that is not declared here is a bug.
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Any, Protocol, runtime_checkable

# The runtime's own classes by name, for reading: this module imports none of them, so
# everything in the runtime may import it.
Simulation = AgentFrame = NeighborSet = PairTable = View = Any


@runtime_checkable
class RunnableProgram(Protocol):
    """A compiled program: per kind its status closures and initialisers
    (`compiler/program.py`'s `CompiledKind`), the agent columns its variables take,
    and the plug-in factories `extensions` (each `make(sim) -> Extension`)."""

    source: str
    filename: str
    kinds: list
    status_display: list[str]
    status_name_ids: Any             # (statuses,) int32 name ids
    var_specs: dict
    var_types: dict
    pair_radius: float
    extensions: list

    @property
    def world(self) -> Any: ...

    @property
    def params(self) -> dict: ...

    @property
    def metrics(self) -> list: ...

    @property
    def sha256(self) -> str: ...

    def lower(self, lowering) -> None:
        """Compile the closures again with a backend's lowering, unless compiled with one
        (`compiler/lowering.py`)."""

    def batch_refusal(self) -> str | None:
        """Why its replicas cannot run as one batch (`runtime/batch.py`), each
        bit-identical to its solo run, naming the construct and its line; None when
        they can. The program answers from its constructs' declarations."""


class Backend(Protocol):
    """A run's array backend, made by the registry (`runtime/backends.py`) from the
    plug-in that registered `name`. `fused`: its compiled paths run (the lowered
    closures ask it); `random_units`: its counter-based draws, None for the reference's
    (`random_units_rows`: the same with a call key per agent, for batches of replicas);
    `why` and `choice`: why the default chose it, when it did."""

    name: str
    why: str
    choice: Any
    fused: bool
    random_units: Any
    random_units_rows: Any
    compile_seconds: float
    fields_compiled: bool | None

    def prepare(self, program: RunnableProgram) -> None:
        """Before the run starts: lower `program` for this backend, if it lowers."""

    def build_pairs(self, pos, radius: float, box, bounds=None) -> PairTable | None:
        """The tick's neighbour pairs within `radius`; with `bounds`, every replica's of
        a batch in one call, or None when they are searched replica by replica."""

    def pairs_table(self, pos, radius: float, box) -> PairTable:
        """The row-order pairs of `pos`, keeping no state between calls."""

    def replica_pairs(self, pos, bounds, radius: float, box) -> PairTable | None:
        """Every replica's row-order pairs in one call; None: `pairs_table` each."""

    def neighbors_within(self, frame: AgentFrame, table: PairTable, limit,
                         view: View | None = None) -> NeighborSet | None:
        """`frame`'s pairs of `table` within each agent's `limit` and, given a `view`
        (`sensing.View`), in its field of view, as this backend's own table narrows
        itself; None: the frame selects the rows (and the sensing model filters them)."""

    def field_type(self, reference: type) -> type:
        """The class that keeps a grid field on this backend (`reference`: numpy's)."""

    def move(self, sim: Simulation) -> tuple | None:
        """The tick's motion done compiled, (pos, vel, heading); None: the reference's."""

    def note(self, part, compiled: bool) -> None:
        """A lowered part ran, compiled or not (what `summary` reports)."""

    def finished(self, program: RunnableProgram, ticks: int) -> None:
        """A run of `program` ended after `ticks` ticks."""

    def batch_threads(self, agents: int) -> tuple[int, str]:
        """The threads a batch of `agents` ticks on, and why."""

    def threads_limited(self, n: int) -> AbstractContextManager:
        """A block whose work uses at most `n` threads."""

    def summary(self, program: RunnableProgram) -> list[str]:
        """Lines for `swarmdsl run -v`."""


class Extension(Protocol):
    """A runtime plug-in, made per run by a factory of `program.extensions`.

    `state_dict` is required (a checkpoint refuses to save without it rather than
    resume differently); the runtime calls each other hook an extension defines, and
    skips those it does not: `load_state(sim, state)` (what `state_dict` gave),
    `after_placement(sim)`, `begin_tick(sim)`, `end_tick(sim)`,
    `place_in(sim, region, n, frame) -> (n, 2) positions`,
    `place_uniform(sim, kind, frame) -> positions or None` (`place uniform` outside
    what it keeps agents out of; None: the plain draw),
    `motion(sim, step) -> step` (the displacement agents really make this tick),
    `decorate_snapshot(sim, snap)`, `field_values(sim) -> {name: array}`,
    `field_node_values(sim)` and `refined_nodes(sim)` (a refined grid's every node),
    `grid_nodes(sim) -> (x, y)`, `regions_json(sim) -> list`.

    An extension that serves the closures takes its slot on the Simulation in its
    constructor: `sim.environment` (fields, regions, obstacles, memories),
    `sim.sensing` (a robot profile's sensing model), `sim.maps` (internal maps); each
    is None in a run without it.
    """

    def state_dict(self, sim: Simulation) -> dict:
        """What it keeps between ticks: NumPy arrays and JSON values only (`{}` when
        every bit of its state is in agent columns)."""


OPTIONAL_HOOKS = ("load_state", "after_placement", "begin_tick", "end_tick", "place_in",
                  "place_uniform", "motion", "decorate_snapshot", "field_values",
                  "field_node_values", "grid_nodes", "refined_nodes", "regions_json")


def hooks(extensions, name: str) -> list:
    """The bound hook `name` of each extension that defines it, in order."""
    assert name in OPTIONAL_HOOKS, name
    return [h for h in (getattr(ext, name, None) for ext in extensions) if h is not None]

