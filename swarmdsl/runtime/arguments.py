"""The arguments of `Run` checked before anything is built, as the CLI checks its options.

The Python API is used from notebooks and sweeps with values from anywhere; a bad one
gets a `SwarmOptionError` naming it, not a numpy or file-system exception from deep
inside the run.
"""

from __future__ import annotations

import os
from pathlib import Path

from swarmdsl.errors import SwarmOptionError
from swarmdsl.limits import upper

VIDEO_SUFFIXES = (".gif", ".mp4")


def param_text(v) -> str:
    """A param value as `--set` writes it: booleans as true/false, numpy scalars as the
    numbers they hold (`repr(np.float64(2.0))` is "np.float64(2.0)"), text as it is."""
    import numbers

    import numpy as np

    if isinstance(v, bool | np.bool_):
        return "true" if v else "false"
    if isinstance(v, numbers.Integral):
        return str(int(v))
    if isinstance(v, numbers.Real):
        return repr(float(v))
    return str(v)


def whole(name: str, value, lo: int, hi: int) -> int:
    """`value` as an int in [lo, hi] (numpy integers welcome), or a SwarmOptionError."""
    import numbers

    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise SwarmOptionError(f"{name} must be a whole number, got {type(value).__name__}")
    if not lo <= int(value) <= hi:
        raise SwarmOptionError(f"{name} must be from {lo:,} to {hi:,}, got {int(value):,}")
    return int(value)


def real(name: str, value, lo: float, hi: float) -> float:
    """`value` as a float in [lo, hi] (numpy numbers welcome; NaN is outside), or a
    SwarmOptionError."""
    import numbers

    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise SwarmOptionError(f"{name} must be a number, got {type(value).__name__}")
    if not lo <= float(value) <= hi:
        raise SwarmOptionError(f"{name} must be from {lo:g} to {hi:g}, got {float(value):g}")
    return float(value)


def text(name: str, value) -> str:
    """`value` itself when it is a str, else a SwarmOptionError naming it."""
    if not isinstance(value, str):
        raise SwarmOptionError(f"{name} must be text, got {type(value).__name__}")
    return value


def required_path(name: str, value, needs: str) -> Path:
    """`value` as a Path; None is refused saying what the call `needs`."""
    if value is None:
        raise SwarmOptionError(f"{name} is None: {needs}")
    return path_or_none(name, value)


def path_or_none(name: str, value) -> Path | None:
    if value is None:
        return None
    if not isinstance(value, str | os.PathLike):
        raise SwarmOptionError(f"{name} must be a path, got {type(value).__name__}")
    text = os.fspath(value)
    if isinstance(text, bytes) or "\0" in text or not text.strip():
        raise SwarmOptionError(f"{name} must be a non-empty path without NUL characters")
    return Path(text)


class Forkable:
    """For an object holding a compiled program (a Simulation, a Run): pickling it is
    refused saying what to send instead, and `copy.copy` or `copy.deepcopy` forks it.

    Its closures cannot be pickled, and pickle's own AttributeError ("Can't pickle local
    object 'CodeGen.status_body.<locals>.run'") does not say what to send to a worker.
    A copy copies every attribute and shares the program's functions (they hold no
    state); a shallow copy would share, and change, the agents' state."""

    def __reduce__(self):
        raise SwarmOptionError(f"a {type(self).__name__} cannot be pickled (it holds "
                               "compiled code); send the program's path and overrides to "
                               "the process and build it there with "
                               "swarmdsl.load_program(path, overrides)")

    def __deepcopy__(self, memo):
        import copy

        clone = object.__new__(type(self))
        memo[id(self)] = clone
        for name, value in self.__dict__.items():
            setattr(clone, name, copy.deepcopy(value, memo))
        return clone

    def __copy__(self):
        return self.__deepcopy__({})


def check_program(program, who: str) -> None:
    """`program` is a compiled Program, or an option error saying how to get one."""
    from swarmdsl.runtime.protocols import RunnableProgram

    if not isinstance(program, RunnableProgram):
        raise SwarmOptionError(f"{who} needs a compiled program: "
                               f"{who}(swarmdsl.load_program(path), ...), got "
                               f"{type(program).__name__}")


def check_run_arguments(program, seed, steps, every, out, record, video_px):
    """Validate `Run(...)`'s arguments; returns (seed, steps, every, out, record, px)."""
    check_program(program, "Run")
    seed = whole("seed", seed, 0, 2**63 - 1)
    if steps is None:       # the program's own length, as `swarmdsl run` takes it
        steps = program.world.steps
    steps = whole("steps", steps, 0, upper("steps"))
    every = whole("every", every, 1, 2**62)
    video_px = whole("video_px", video_px, 16, 8192)
    from swarmdsl.runtime.outputs import check_file, check_folder

    out = path_or_none("out", out)
    if out is not None:
        check_folder(out, "out")
    record = path_or_none("record", record)
    if record is not None and record.suffix.lower() not in VIDEO_SUFFIXES:
        raise SwarmOptionError(f"record {record}: the file must end in .gif or .mp4")
    if record is not None:
        check_file(record, "record", example="run.mp4")
    return seed, steps, every, out, record, video_px
