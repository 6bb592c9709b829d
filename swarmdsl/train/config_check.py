"""A training configuration checked whole, before torch would fail on it somewhere deep.

Used by `TrainConfig.for_task` (the Python API) and by `swarmdsl train`; every refusal is
a `SwarmOptionError` naming the setting, never quoting a spec's text.
"""

from __future__ import annotations

import math

from swarmdsl.errors import SwarmOptionError, did_you_mean

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

RANGE_TEXT = {"val_fraction": "above 0 and below 1"}
"""Ranges whose bounds `:g` would round into values they exclude (1 - 1e-9 shows as 1,
so `'val_fraction' 1` was refused as outside "from 1e-09 to 1")."""

COORD_LIMIT = 1e9
"""Largest magnitude of a sampling coordinate: far beyond any world, and small enough
that the column means and spreads of the normalisation stay finite."""


def split_sizes(samples: int, val_fraction: float) -> tuple[int, int]:
    """(training rows, held-out rows): the held-out tail is at least 2 rows, so that the
    percentage error has a range to divide by."""
    n_val = max(2, int(round(samples * val_fraction)))
    return samples - n_val, n_val


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
            span = RANGE_TEXT.get(name, f"from {lo:g} to {hi:g}")
            raise SwarmOptionError(f"'{name}' must be {kind} {span}")
    n_train, n_val = split_sizes(config.samples, config.val_fraction)
    if n_train < 1:
        raise SwarmOptionError(f"'samples' {config.samples} with 'val_fraction' "
                               f"{config.val_fraction:g} leaves no rows to train on "
                               f"({n_val} are held out); raise 'samples' or lower "
                               "'val_fraction'")
    _check_task_settings(config)


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _check_task_settings(config) -> None:
    """The task's `sampling` and `rule_params`, checked before a sampler sees them.

    Without this, a wrong value surfaced as numpy's own words ("high - low < 0", a
    string quoted from the spec), or trained silently on nonsense: matrix2d positions
    beyond the ghost threshold are read by the rule as missing neighbours, and huge
    ranges overflow the normalisation after the whole training ran.
    """
    from swarmdsl.train import rules
    from swarmdsl.train.data import BLOCK_PATTERNS, TASKS

    task = TASKS[config.task]
    for key, known in (("sampling", task.sampling), ("rule_params", task.rule_params)):
        for sub, val in getattr(config, key).items():
            if sub not in known:
                raise SwarmOptionError(
                    f"unknown {key} key '{sub}' for task {task.name} "
                    f"(known: {', '.join(known) or 'none'})", hint=did_you_mean(sub, known))
            if sub == "pattern_weights":
                k = len(BLOCK_PATTERNS)
                if (not isinstance(val, list) or len(val) != k
                        or not all(_number(w) and w >= 0 for w in val) or sum(val) <= 0):
                    raise SwarmOptionError(f"'sampling.pattern_weights' must be {k} "
                                           "non-negative numbers, not all 0")
            elif not _number(val) or abs(val) > COORD_LIMIT:
                raise SwarmOptionError(f"'{key}.{sub}' must be a number from "
                                       f"{-COORD_LIMIT:g} to {COORD_LIMIT:g}")
    s = {**task.sampling, **config.sampling}
    if not s["low"] < s["high"]:
        raise SwarmOptionError("'sampling.low' must be below 'sampling.high'")
    if task.name != "matrix2d":
        return
    if not 0 <= s["spacing_low"] <= s["spacing_high"]:
        raise SwarmOptionError("'sampling.spacing_low' must be at least 0 and at most "
                               "'sampling.spacing_high'")
    if s["jitter"] < 0:
        raise SwarmOptionError("'sampling.jitter' must be at least 0")
    reach = s["high"] + s["spacing_high"] + s["jitter"]
    if reach >= rules.GHOST_THRESHOLD:
        raise SwarmOptionError(
            f"'sampling' reaches coordinates up to {reach:g}, but the rule reads any "
            f"coordinate from {rules.GHOST_THRESHOLD:g} on as a missing neighbour (ghost "
            f"{rules.GHOST:g}); keep 'high' + 'spacing_high' + 'jitter' below it")
    s0 = {**task.rule_params, **config.rule_params}["s0"]
    if s0 <= 0:
        raise SwarmOptionError("'rule_params.s0' (the rest spacing) must be above 0")
