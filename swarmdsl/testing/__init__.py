"""Property-based testing of swarm programs: strategies, checked runs, the
counterexample search behind `swarmdsl test`, and a state machine for robustness tests.
"""

from swarmdsl.testing.machine import SwarmMachine
from swarmdsl.testing.monitor import Monitor, PropertyViolation, Violation, enable_checks
from swarmdsl.testing.runner import RunResult, load, run_program, state_arrays
from swarmdsl.testing.search import Counterexample, Example, SearchReport, search
from swarmdsl.testing.strategies import (
    MoveAgents,
    ParamAxis,
    RemoveAgents,
    SetVariable,
    param_axes,
    params,
    perturbations,
    placements,
    seeds,
)

__all__ = [
    "Counterexample", "Example", "Monitor", "MoveAgents", "ParamAxis", "PropertyViolation",
    "RemoveAgents", "RunResult", "SearchReport", "SetVariable", "SwarmMachine",
    "Violation", "enable_checks", "load", "param_axes", "params", "perturbations",
    "placements", "run_program", "search", "seeds", "state_arrays",
]
