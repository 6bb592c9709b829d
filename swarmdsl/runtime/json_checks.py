"""Small checks for values read from JSON or handed in through the API (a layout, a
saved example), shared so that one rule is written once and worded the same wherever it
is broken: an option error naming the entry, never a traceback."""

from __future__ import annotations

import json
import math
import numbers
from typing import NoReturn

import numpy as np

from swarmdsl.errors import SwarmOptionError

MAX_WHOLE = 2**63 - 1       # what an int64 column (ids, indexes, seeds) holds


class Refuse:
    """Raises option errors prefixed by where the value came from (`--example FILE`, or
    nothing for a value handed to the API), with a hint once one is known."""

    def __init__(self, where: str | None = None, hint: str | None = None):
        self.where = where
        self.hint = hint

    def __call__(self, message: str) -> NoReturn:
        text = f"{self.where}: {message}" if self.where else message
        raise SwarmOptionError(text, hint=self.hint)


def shown(value) -> str:
    """A value as JSON spells it, cut short (numpy values too: the API hands those in)."""
    text = json.dumps(value, default=lambda v: v.tolist() if hasattr(v, "tolist") else repr(v))
    return text if len(text) <= 40 else text[:37] + "..."


def is_bool(value) -> bool:
    return isinstance(value, bool | np.bool_)


def finite(value) -> bool:
    """A bool, or a number a float holds (a JSON integer can be any length)."""
    try:
        return is_bool(value) or math.isfinite(float(value))
    except OverflowError:
        return False


def number(value) -> bool:
    """A finite number (true and false are not numbers here)."""
    return isinstance(value, numbers.Real) and not is_bool(value) and finite(value)


def whole(refuse: Refuse, value, what: str, lo: int, hi: int) -> int:
    if is_bool(value) or not isinstance(value, numbers.Integral) or not lo <= value <= hi:
        refuse(f"{what}: {shown(value)} is not a whole number from {lo:,} to {hi:,}")
    return int(value)


def known_keys(refuse: Refuse, obj: dict, known, prefix: str, has: str) -> None:
    for key in obj:
        if key not in known:
            refuse(f"{prefix}unknown entry \"{key}\" ({has} {', '.join(known)})")
