"""Stop requests: SIGINT, SIGTERM and SIGHUP handled alike, and never while files close.

`timeout`, CI runners, Slurm and Dask stop a job with SIGTERM, a closed terminal sends
SIGHUP; all of them should stop a run the way Ctrl-C does: the tick loop ends, the
outputs are closed and say how the run ended. The handler raises `Stopped` (a
`KeyboardInterrupt`, so every `except KeyboardInterrupt` already in the code path treats
the three alike). Inside `deferred()` (while outputs are being closed) a signal is only
noted: a second Ctrl-C cannot tear a half-written file or print a traceback.

The command installs the handlers twice: `hold()` as soon as its module loads (a Ctrl-C
is only noted, so one while the command is still importing is no traceback), then
`install()` at the start of `main()`, which raises any noted signal in the command's
own `try`.
"""

from __future__ import annotations

import signal
from contextlib import contextmanager

SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                if hasattr(signal, name))


class Stopped(KeyboardInterrupt):
    """The process was asked to stop by `signum`; exits with 128 + signum."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


# "raised": the signal of the last `Stopped` raised (None: none since `install()`);
# "stopping": one was raised, and later signals are only noted
_state = {"depth": 0, "pending": [], "holding": False, "stopping": False, "raised": None}


def _handler(signum, frame) -> None:
    if _state["holding"] or _state["depth"] or _state["stopping"]:
        _state["pending"].append(signum)
        return
    _raise(signum)


def _raise(signum: int):
    _state["stopping"] = True      # later signals only noted: the stop is under way
    _state["raised"] = signum
    raise Stopped(signum)


def _set_all(signals=SIGNALS) -> dict:
    old = {}
    for sig in signals:
        try:
            old[sig] = signal.signal(sig, _handler)
        except (OSError, ValueError):  # not the main thread: leave signals alone
            return old
    return old


def hold() -> None:
    """Note a Ctrl-C without acting on it until `install()` (command start-up).

    SIGTERM and SIGHUP keep their default (end the process, silently) until then.
    """
    _state["holding"] = True
    _set_all((signal.SIGINT,))


def install() -> dict:
    """Make SIGINT, SIGTERM and SIGHUP raise `Stopped`; returns the previous handlers.

    A signal noted by `hold()` is raised now.
    """
    old = _set_all()
    _state.update(holding=False, stopping=False, raised=None)
    pending, _state["pending"] = _state["pending"], []
    if pending:
        _raise(pending[0])
    return old


def cause(exc: BaseException) -> KeyboardInterrupt | None:
    """The stop behind `exc`, if a stop signal interrupted what raised it. An import of a
    C extension turns the `Stopped` raised inside it into an ImportError, with the stop
    in its chain or, when the extension set a new error, nowhere (numpy's own import):
    then the stop raised since `install()` is the cause."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return Stopped(_state["raised"]) if _state["raised"] is not None else None


def installed() -> bool:
    """True when SIGTERM is handled here (inside the command's main())."""
    return signal.getsignal(signal.SIGTERM) is _handler


def restore(old: dict) -> None:
    """Put back the handlers `install()` replaced (the CLI called from Python)."""
    for sig, handler in old.items():
        try:
            signal.signal(sig, handler)
        except (OSError, ValueError, TypeError):  # pragma: no cover
            pass
    _state.update(holding=False, pending=[], stopping=False, raised=None)


def ignore() -> None:
    """The command is exiting: stop signals are ignored from now on.

    Python puts its default handlers back while it shuts down, and a Ctrl-C then would
    end the process by the signal instead of with the exit code it chose.
    """
    for sig in SIGNALS:
        try:
            signal.signal(sig, signal.SIG_IGN)
        except (OSError, ValueError):   # not the main thread
            return


@contextmanager
def deferred():
    """Stop signals arriving inside are noted, not raised: files close whole.

    A stop that arrives while a finished run closes its files does not turn the run
    into an interrupted one; the caller may look at `pending()` afterwards.
    """
    _state["depth"] += 1
    try:
        yield
    finally:
        _state["depth"] -= 1


@contextmanager
def uncut():
    """A step that must not be cut (one video frame, one Parquet part): a stop signal
    arriving inside is raised when the step is done."""
    before = len(_state["pending"])
    with deferred():
        yield
    if len(_state["pending"]) > before and not _state["depth"] and not _state["stopping"]:
        signum = _state["pending"][before]
        del _state["pending"][before:]
        _raise(signum)


@contextmanager
def plain_ctrl_c():
    """Inside, a Ctrl-C in a plain Python process (a script, a notebook: SIGINT still has
    Python's own handler) is handled as the command handles it: noted while outputs
    close, raised between ticks. Python's handler raises KeyboardInterrupt wherever the
    signal lands, also halfway through closing a run's files, which left run.json
    saying `running` and a traceback. A Ctrl-C noted while files closed and not acted
    on (the run had finished) is raised as a KeyboardInterrupt on the way out, once
    the files are whole: a script looping over runs stops, as Ctrl-C means. A no-op
    where a handler is already set (the command's `install()`, the user's own) or off
    the main thread; the previous handler is put back on the way out."""
    try:
        mine = signal.getsignal(signal.SIGINT) is signal.default_int_handler
        if mine:
            signal.signal(signal.SIGINT, _handler)
    except ValueError:          # not the main thread: leave signals alone
        mine = False
    if not mine:
        yield
        return
    _state.update(pending=[], stopping=False, raised=None)
    try:
        yield
        late = bool(_state["pending"]) and not _state["stopping"]
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _state.update(pending=[], stopping=False, raised=None)
    if late:
        raise KeyboardInterrupt


def check() -> None:
    """Raise a stop that was lost on its way (called where a tick starts).

    The handler raises `Stopped` wherever the signal lands, and some code on the way
    does not let it through: a C library clearing whatever error a callback raised, an
    extension's import turning it into an ImportError that an optional import catches.
    A signal noted inside `uncut()` is lost too when the step then fails with another
    error that something handles, or when it lands while a finished run closes and the
    command goes on to another run. Every place that takes a stop ends the tick loop,
    and nothing is noted between ticks, so a tick starting after either has lost it;
    later signals are only noted while a stop is under way, so without this a lost stop
    was never honoured (the run went on to its last tick and exited 0)."""
    if _state["depth"] or _state["holding"]:
        return
    if _state["stopping"]:
        if _state["raised"] is not None:
            raise Stopped(_state["raised"])
    elif _state["pending"]:
        signum = _state["pending"][0]
        del _state["pending"][:]
        _raise(signum)


def pending() -> list[int]:
    """Signals noted inside `deferred()` and not raised."""
    return list(_state["pending"])
