"""The benchmark models and their implementations, one table: `CASES` and `IMPLEMENTATIONS`.

A case is a `.swarm` program that scales with N, the params that size it (at the model's
own density, or at a chosen mean number of neighbours: `Case.params_at`), the params
that switch its noise off, and its statistics. An implementation is anything with
`step()` and `state()` (a dict of `(N, ...)` arrays ordered by agent id) built from the
swarmdsl run's initial state, so every implementation starts from the same agents.

Adding a runtime backend as one more column is one line in `SWARMDSL_BACKENDS`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "programs"
MODELS = Path(__file__).resolve().parent / "models"

# Column name -> the `backend` a Simulation gets (None: the runtime's default). A backend
# the runtime does not have yet is reported as skipped, not as an error.
SWARMDSL_BACKENDS: dict[str, str | None] = {
    "swarmdsl": None,               # the default: numba when installed (docs/backends.md)
    "swarmdsl-numpy": "numpy",      # the reference closures
}


@dataclass
class Case:
    name: str
    program: Path
    params: object                     # n -> {param: value}, at the model's own density
    radius: object                     # params -> neighbour radius for the statistics
    resize: object                     # (params, area) -> params with a world of that area
    wrap: bool
    quiet: dict = field(default_factory=dict)   # params that switch the noise off
    references: dict = field(default_factory=dict)   # column -> (module, factory name)
    extra_columns: tuple = ()          # per-agent variables references need, by name
    mesa_max: int = 0                  # run Mesa's boid flockers up to this N

    def params_at(self, n: int, neighbours: float | None = None) -> dict:
        """The params at size n: the model's own density, or (given `neighbours`) a world
        on which a uniform layout has that mean number of other agents within the radius,
        so that models with different densities can be timed at one stated density."""
        own = self.params(n)
        if neighbours is None:
            return own
        return self.resize(own, world_area(n, self.radius(own), neighbours))


def world_area(n: int, radius: float, neighbours: float) -> float:
    """The area on which n uniformly placed agents have, on average, `neighbours` others
    within `radius` of each (edge effects aside): n * pi * r^2 / K."""
    return n * math.pi * radius ** 2 / neighbours


def uniform_neighbours(case: Case, params: dict) -> float:
    """The mean number of other agents within the case's radius for a uniform layout on
    the world `params` describe (edge effects aside): the density a run is set up at."""
    width = params.get("width", params.get("size"))
    height = params.get("height", params.get("size"))
    return params["n"] * math.pi * case.radius(params) ** 2 / (width * height)


def _boids_params(n: int) -> dict:
    side = round(600 * math.sqrt(n / 100))  # the program's density: 100 on 600 x 600
    return {"n": n, "width": side, "height": side}


def _boids_resize(params: dict, area: float) -> dict:
    """Width and height scaled alike (the aspect kept), whole units like the default's;
    the radius, edge push and grid spacing are lengths of their own."""
    scale = math.sqrt(area / (params["width"] * params["height"]))
    return {**params, "width": round(params["width"] * scale),
            "height": round(params["height"] * scale)}


def _vicsek_params(n: int) -> dict:
    return {"n": n, "size": round(math.sqrt(n / 4), 6)}  # density 4, the paper's figures


def _swarmalator_params(n: int) -> dict:
    return {"n": n, "size": round(math.sqrt(n * math.pi * 4 / 10), 6)}  # ~10 within r = 2


def _square_resize(params: dict, area: float) -> dict:
    """A square world of that area (Vicsek, swarmalators: nothing else follows its size)."""
    return {**params, "size": round(math.sqrt(area), 6)}


def _chemotaxis_params(n: int) -> dict:
    return {"n": n, "size": 2 * math.ceil(math.sqrt(n))}  # 1 cell per 4 grid nodes


def _chemotaxis_resize(params: dict, area: float) -> dict:
    """A square world of that area whose grid keeps the default's nodes per side (1 cell
    per 4 grid nodes: the same field work per agent), so the spacing follows the size; a
    wrapped grid needs the size to be a whole number of spacings, which this is."""
    size = round(math.sqrt(area), 6)
    nodes = round(params["size"] / params.get("spacing", 1))
    return {**params, "size": size, "spacing": size / nodes}


CASES: dict[str, Case] = {
    "boids": Case(
        "boids", PROGRAMS / "boids.swarm", _boids_params, lambda p: 80.0, _boids_resize,
        wrap=False,
        quiet={"wander": 0},
        references={"numpy": ("benchmarks.reference_boids", "ReferenceBoids.from_state"),
                    "numba": ("benchmarks.numba_refs", "NumbaBoids.from_state")},
        mesa_max=1000),
    "vicsek": Case(
        "vicsek", PROGRAMS / "vicsek.swarm", _vicsek_params, lambda p: 1.0, _square_resize,
        wrap=True,
        quiet={"eta": 0},
        references={"numpy": ("benchmarks.reference_vicsek", "ReferenceVicsek.from_state"),
                    "numba": ("benchmarks.numba_refs", "NumbaVicsek.from_state")}),
    "swarmalators": Case(
        "swarmalators", MODELS / "swarmalators.swarm", _swarmalator_params,
        lambda p: 2.0, _square_resize, wrap=True, quiet={"noise": 0},
        extra_columns=("phase",),
        references={
            "numpy": ("benchmarks.reference_swarmalators", "ReferenceSwarmalators"),
            "numba": ("benchmarks.numba_refs", "NumbaSwarmalators")}),
    "chemotaxis": Case(
        "chemotaxis", MODELS / "chemotaxis.swarm", _chemotaxis_params, lambda p: 2.0,
        _chemotaxis_resize, wrap=True, quiet={"turn": 0},
        references={"numpy": ("benchmarks.reference_chemotaxis", "ReferenceChemotaxis"),
                    "numba": ("benchmarks.numba_refs", "NumbaChemotaxis")}),
}


def make_simulation(program, seed: int, backend: str | None):
    """A Simulation on `backend` (None: the default); raises LookupError if there is none."""
    import inspect

    from swarmdsl.runtime.simulation import Simulation

    if backend is None:
        return Simulation(program, seed)
    if "backend" not in inspect.signature(Simulation).parameters:
        raise LookupError(f"this swarmdsl has no `{backend}` backend")
    return Simulation(program, seed, backend=backend)


class SwarmdslRun:
    """The compiled program, ticked by `Simulation.step()` (what `run` times)."""

    def __init__(self, case: Case, n: int, seed: int, backend=None, overrides=None,
                 neighbours: float | None = None):
        from swarmdsl import load_program

        self.params = {**case.params_at(n, neighbours), **(overrides or {})}
        program = load_program(case.program, {k: str(v) for k, v in self.params.items()})
        self.sim = make_simulation(program, seed, backend)
        self.extra = case.extra_columns

    def step(self) -> None:
        self.sim.step()

    def state(self) -> dict:
        cols = self.sim.agents.cols
        order = np.argsort(cols["id"])
        out = {"pos": cols["pos"][order], "vel": cols["vel"][order]}
        for name in self.extra:
            out[name] = cols[name][order]
        return out


def reference(case: Case, column: str, start: dict, params: dict, seed: int):
    """Build the `column` reference of `case` from a start state; ImportError if absent."""
    import importlib

    module_name, factory = case.references[column]
    obj = importlib.import_module(module_name)
    for part in factory.split("."):
        obj = getattr(obj, part)
    return obj(start, params, seed)


# ---- statistics: computed the same way from every implementation's state ----

def neighbour_pairs(pos: np.ndarray, radius: float, box: float | None):
    from scipy.spatial import cKDTree

    if box is not None:
        pts = np.mod(pos, box)
        pts[pts >= box] = 0.0
        return cKDTree(pts, boxsize=box).query_pairs(radius, output_type="ndarray")
    return cKDTree(pos).query_pairs(radius, output_type="ndarray")


def statistics(case: Case, params: dict, state: dict) -> dict[str, float]:
    """Polarisation (|mean unit velocity|) and mean neighbours within the model's radius."""
    pos, vel = state["pos"], state["vel"]
    speed = np.linalg.norm(vel, axis=1)
    moving = speed > 0
    unit = vel[moving] / speed[moving, None]
    pol = float(np.linalg.norm(unit.mean(axis=0))) if unit.size else 0.0
    box = float(params.get("size", params.get("width", 0))) if case.wrap else None
    pairs = neighbour_pairs(pos, case.radius(params), box)
    return {"polarisation": pol, "neighbours": 2 * len(pairs) / max(len(pos), 1)}
