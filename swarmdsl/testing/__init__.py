"""Property-based testing of swarm programs: strategies, checked runs, the
counterexample search behind `swarmdsl test`, and a state machine for robustness tests.

Names load on first use (PEP 562), so the `swarmdsl` command starts without importing
hypothesis or the runtime.
"""

from __future__ import annotations

import importlib

_WHERE = {
    "SwarmMachine": "machine",
    "Monitor": "monitor", "PropertyViolation": "monitor", "Violation": "monitor",
    "enable_checks": "monitor",
    "RunResult": "runner", "load": "runner", "run_program": "runner",
    "state_arrays": "runner",
    "Counterexample": "counterexample", "SearchReport": "search", "search": "search",
    "Example": "example", "load_example": "example",
    "AgentSpec": "layout", "Layout": "layout",
    "example_strategy": "swarms",
    "MoveAgents": "strategies", "ParamAxis": "strategies", "RemoveAgents": "strategies",
    "SetVariable": "strategies", "param_axes": "strategies", "params": "strategies",
    "perturbations": "strategies", "placements": "strategies", "seeds": "strategies",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'swarmdsl.testing' has no attribute {name!r}")
    package = "swarmdsl.runtime" if module == "layout" else "swarmdsl.testing"
    value = getattr(importlib.import_module(f"{package}.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
