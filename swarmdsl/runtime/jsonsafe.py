"""Standard JSON for run outputs: Python's `json` writes NaN and Infinity, which other
readers (JavaScript, jq, pandas' strict modes) reject."""

from __future__ import annotations

import math

import numpy as np


def standard_json(value):
    """`value` with numpy scalars made plain and non-finite floats made `None` (null)."""
    if isinstance(value, dict):
        return {str(k): standard_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [standard_json(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
