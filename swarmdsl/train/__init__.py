"""`swarmdsl train`: fit the small networks `nn(...)` calls, from hard-coded rules.

Importing this package does not import torch; `fit.train` does, when it runs. Its names
load on first use, so `swarmdsl.train.cli` (imported by every command for its subcommand)
does not pay for `fit` and the model runtime.
"""

from __future__ import annotations

import importlib

_HOMES = {"TASKS": "data", "Task": "data", "TrainConfig": "fit", "TrainResult": "fit",
          "percentage_error": "fit", "train": "fit"}

__all__ = ["TASKS", "Task", "TrainConfig", "TrainResult", "percentage_error", "train"]


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{home}"), name)
