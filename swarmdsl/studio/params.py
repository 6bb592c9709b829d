"""The controls a program's `param` declarations give the studio: one slider (or switch)
per param, its range, and the `--set` line that reproduces what is shown.

A declared `in LO..HI` range is the slider's range. A param without one gets a range
around its value (0 to twice it, at least 0..1; whole numbers stay whole), which is only
the slider's reach: the number box beside it takes any value the checker accepts.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.runtime.arguments import param_text


@dataclass(frozen=True)
class ParamControl:
    """One param as the page draws it."""

    name: str
    type: str               # "bool", "int" or "float"
    value: object
    lo: float | None        # None for booleans
    hi: float | None
    step: float | None
    declared_range: bool    # the program declares `in LO..HI`
    overridden: bool        # the value shown is not the program's own

    def as_json(self) -> dict:
        return asdict(self)


def controls(program, overrides: dict[str, str]) -> list[ParamControl]:
    """Every param of `program` (compiled with `overrides`), in declaration order."""
    info = program.info
    out = []
    for name, decl in info.param_decls.items():
        value = info.params[name]
        over = name in overrides
        if isinstance(value, bool):
            out.append(ParamControl(name, "bool", value, None, None, None, False, over))
            continue
        whole = isinstance(value, int)
        lo = hi = None
        if decl.lo is not None:
            try:
                lo = const_value(decl.lo, info.params)
                hi = const_value(decl.hi, info.params)
            except (NotConstant, ArithmeticError, ValueError, TypeError):
                lo = hi = None
        declared = _finite(lo) and _finite(hi) and lo <= hi
        if declared:
            whole = whole and isinstance(lo, int) and isinstance(hi, int)
        else:
            lo, hi = _around(float(value), whole)
        # a small whole number (`gain = 2`) is a number a slider moves finely; counts
        # and sizes (`n = 100`) move by whole steps
        whole = whole and float(hi) - float(lo) >= 20
        step = 1 if whole else _step(float(lo), float(hi))
        out.append(ParamControl(name, "int" if whole else "float", value, lo, hi, step,
                                bool(declared), over))
    return out


def set_line(program_path: str, overrides: dict[str, str], seed: int) -> str:
    """The command that runs what the studio shows: `swarmdsl run FILE --set ...`."""
    parts = ["swarmdsl", "run", _shell_word(program_path)]
    for name, text in overrides.items():
        parts += ["--set", _shell_word(f"{name}={text}")]
    if seed:
        parts += ["--seed", str(seed)]
    return " ".join(parts)


def value_text(value) -> str:
    """A value from the page (a JSON number or boolean, or text) as `--set` writes it."""
    if isinstance(value, float) and value.is_integer() and abs(value) < 2**53:
        # the page's number boxes send 5 for 5.0; the checker decides int or float
        return param_text(int(value)) if not isinstance(value, bool) else param_text(value)
    return param_text(value)


def _finite(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _around(value: float, whole: bool) -> tuple[float, float]:
    if value >= 0:
        lo, hi = 0.0, max(2.0 * value, 1.0)
    else:
        lo, hi = 2.0 * value, max(-2.0 * value, 1.0)
    if whole:
        return int(math.floor(lo)), int(math.ceil(hi))
    return lo, hi


def _step(lo: float, hi: float) -> float:
    """A round step giving about 200 positions along the slider."""
    span = hi - lo
    if span <= 0:
        return 1.0
    return 10.0 ** math.floor(math.log10(span / 200.0))


def _shell_word(text: str) -> str:
    import shlex

    return shlex.quote(text)
