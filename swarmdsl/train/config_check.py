"""A training configuration checked whole, before torch would fail on it somewhere deep.

Used by `TrainConfig.for_task` (the Python API) and by `swarmdsl train`; every refusal is
a `SwarmOptionError` naming the setting, never quoting a spec's text.
"""

from __future__ import annotations

import math

from swarmdsl.compiler.errors import SwarmOptionError

# name -> (lowest, highest, whole number?)
NUMBER_RANGES = {
    "epochs": (1, 1_000_000, True),
    "samples": (10, 50_000_000, True),
    "batch_size": (1, 50_000_000, True),
    "seed": (0, 2**63 - 1, True),
    "threads": (1, 1024, True),
    "lr": (1e-12, 1e3, False),
    "val_fraction": (1e-9, 1 - 1e-9, False),
    "input_clip": (1e-9, 1e15, False),
}


def check_config(config) -> None:
    """Raise SwarmOptionError for the first setting of `config` out of its range."""
    from swarmdsl.runtime.nn import ACTIVATIONS, MAX_HIDDEN_LAYERS, MAX_LAYER_WIDTH

    hidden = config.hidden
    if (not isinstance(hidden, list | tuple) or not hidden
            or len(hidden) > MAX_HIDDEN_LAYERS
            or not all(isinstance(h, int) and not isinstance(h, bool)
                       and 0 < h <= MAX_LAYER_WIDTH for h in hidden)):
        raise SwarmOptionError(f"'hidden' must list 1 to {MAX_HIDDEN_LAYERS} layer widths, "
                               f"each 1 to {MAX_LAYER_WIDTH}")
    if config.activation not in ACTIVATIONS:
        raise SwarmOptionError(f"'activation' must be one of {', '.join(ACTIVATIONS)}")
    if config.lr_schedule not in ("constant", "cosine"):
        raise SwarmOptionError("'lr_schedule' must be constant or cosine")
    if not isinstance(config.name, str) or not config.name.strip():
        raise SwarmOptionError("'name' must be a non-empty string")
    for key in ("sampling", "rule_params"):
        if not isinstance(getattr(config, key), dict):
            raise SwarmOptionError(f"'{key}' must be an object")
    for name, (lo, hi, whole) in NUMBER_RANGES.items():
        v = getattr(config, name)
        ok = (isinstance(v, int | float) and not isinstance(v, bool)
              and math.isfinite(v) and lo <= v <= hi and (not whole or float(v).is_integer()))
        if not ok:
            kind = "a whole number" if whole else "a number"
            raise SwarmOptionError(f"'{name}' must be {kind} from {lo:g} to {hi:g}")
