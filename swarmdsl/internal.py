"""Internal errors: an exception that is not a `SwarmError` is a bug in swarmdsl.

The user sees one line naming the exception (and the tick, when a run was going), never
a traceback, and the command exits with `EXIT_CODE` (3), apart from a bad program or
option (2). With `SWARMDSL_DEBUG=1` in the environment the exception is raised as it
is, traceback and all, for whoever fixes it.
"""

from __future__ import annotations

import os

from swarmdsl.errors import SwarmRuntimeError

EXIT_CODE = 3
DEBUG_VARIABLE = "SWARMDSL_DEBUG"


class InternalError(SwarmRuntimeError):
    """A bug in swarmdsl as the error it reports: the exception's type and message (and
    the tick, when known) on one line; the original exception is its `__cause__`."""

    exit_code = EXIT_CODE


def debugging() -> bool:
    """True when `SWARMDSL_DEBUG` is set to anything but empty or `0`."""
    return os.environ.get(DEBUG_VARIABLE, "").strip() not in ("", "0")


def describe(exc: BaseException) -> str:
    """`Type: message` on one line (a message's line breaks become spaces)."""
    message = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {message}" if message else type(exc).__name__


def internal_error(exc: Exception, tick: int | None = None) -> InternalError:
    """An unexpected exception during a run (at `tick`) or a command, as the error it
    reports: `internal error at tick N: Type: message (please report this)`."""
    if tick is not None:
        text = f"internal error at tick {tick}: {describe(exc)} (please report this)"
    else:
        text = (f"internal error: {describe(exc)} (please report this; "
                f"{DEBUG_VARIABLE}=1 shows the traceback)")
    err = InternalError(text)
    err.__cause__ = exc
    return err


def raise_when_debugging(err: BaseException) -> None:
    """Under `SWARMDSL_DEBUG=1`, raise the exception behind an internal error as it is."""
    if isinstance(err, InternalError) and err.__cause__ is not None and debugging():
        exc = err.__cause__
        exc.__suppress_context__ = True     # its own traceback, not the report's
        raise exc
