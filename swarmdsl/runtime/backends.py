"""The backend registry: which array backends a run can take, and the one it gets.

A backend is a plug-in package that registers itself here when it is imported
(`register`): the numpy reference (`runtime/numpy_backend/`) and the numba backend
(`runtime/compiled/`). The runtime never imports a backend package: `PLUGINS` names
each known backend's package as data, and `make` imports the package by that name the
first time a run asks for the backend. So `Simulation(..., backend="numba")` works
from anywhere, while the import graph keeps the runtime below the compiler and the
backends that plan from it (`tests/test_imports.py` checks the table against the
packages and the names they register).

Which backend runs is decided from above: the API, the CLI, a sweep, the studio and
the tester pass a name (or None: `$SWARMDSL_BACKEND`, else the default's choice).
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from dataclasses import dataclass

from swarmdsl.errors import SwarmOptionError
from swarmdsl.runtime.protocols import Backend

# Each known backend's name -> the package that registers it, in the order messages
# list them. A third-party backend may call `register` itself, before asking for it.
PLUGINS = {"numba": "swarmdsl.runtime.compiled", "numpy": "swarmdsl.runtime.numpy_backend"}
ENV = "SWARMDSL_BACKEND"


@dataclass(frozen=True)
class Plugin:
    """A registered backend.

    `factory()` makes a fresh backend for one run; `installed()` says whether the
    libraries it needs are importable, `missing` what to do when not; `chooser(program,
    work)`, if given, is how this backend proposes itself as the default (a choice with
    `name` and `why`, `compiled/choice.py`); `lowering()`, if given, the compiler
    lowering a run on this backend takes, so a command that names the backend up front
    may compile the program for it once; `notes()`, lines a sweep's plan prints about it;
    `tiered()`, a factory of a backend that starts a solo run on the reference at once
    and becomes this one between two ticks (the default makes it when its chooser's
    choice says `tiered`); `hidden`: a name no user chooses (not in `names()`), made by
    name only to continue a run that had it.
    """

    name: str
    factory: Callable[[], Backend]
    installed: Callable[[], bool] = lambda: True
    missing: str = ""
    chooser: Callable | None = None
    lowering: Callable | None = None
    notes: Callable[[], list[str]] | None = None
    tiered: Callable[[], Backend] | None = None
    hidden: bool = False


_REGISTERED: dict[str, Plugin] = {}


def register(name: str, factory: Callable[[], Backend], **hooks) -> None:
    """Make backend `name` available (`hooks`: the optional fields of `Plugin`)."""
    _REGISTERED[name] = Plugin(name, factory, **hooks)


def names() -> tuple[str, ...]:
    """Every backend a run may name: the known ones, then any registered since (not
    the hidden ones)."""
    return tuple(PLUGINS) + tuple(n for n, p in _REGISTERED.items()
                                  if n not in PLUGINS and not p.hidden)


def plugin(name: str) -> Plugin | None:
    """The registered backend `name`, importing its package on first request; None
    for a name no package registers."""
    if not isinstance(name, str):
        return None
    if name not in _REGISTERED and name in PLUGINS:
        importlib.import_module(PLUGINS[name])
    return _REGISTERED.get(name)


def installed(name: str) -> bool:
    """Whether backend `name` exists and its libraries are importable here."""
    got = plugin(name)
    return got is not None and got.installed()


def _choices() -> str:
    return " or ".join(names())


def environment_backend() -> str:
    """`$SWARMDSL_BACKEND` ("" when unset). A name that is not a backend is refused
    naming the variable, which a command checks before anything runs: refused only as
    each run starts, a sweep failed every run and `swarmdsl test` reported it as a
    counterexample."""
    name = os.environ.get(ENV, "").strip()
    if not name:
        return ""
    got = plugin(name)
    if got is None:
        raise SwarmOptionError(f"${ENV}={name}: not a backend; set it to {_choices()}, "
                               "or unset it")
    if not got.installed():
        raise SwarmOptionError(f"${ENV}={name}: {got.missing}")
    return name


def default_choice(work: float | None = None, program=None, tiered: bool = False):
    """The default's choice for `work` agent-steps of `program`: the first backend in
    `PLUGINS` order that proposes itself (its `chooser`); None: the reference. `tiered`:
    the run can change backend between ticks (a solo `Simulation`)."""
    for name in names():
        got = plugin(name)
        if got is not None and got.chooser is not None:
            return got.chooser(program, work, tiered=tiered)
    return None


def default_backend(work: float | None = None, program=None) -> str:
    """`$SWARMDSL_BACKEND` if set, else the default's choice (numba when it is installed
    and saves more time over the run's `work`, agents x ticks, than compiling `program`'s
    kernels costs, `compiled/choice.py`), else numpy."""
    if name := environment_backend():
        return name
    choice = default_choice(work, program)
    return "numpy" if choice is None else choice.name


def make(name: str | None = None, work: float | None = None, program=None,
         tiered: bool = False) -> Backend:
    """A fresh backend called `name` (None: `$SWARMDSL_BACKEND`, else the default's choice
    for `work` agent-steps of `program`), or a SwarmOptionError naming the choices.
    `tiered`: the caller's run can change backend between ticks, so the default may
    start it on the reference and switch (`Plugin.tiered`)."""
    choice = None
    if name is None:
        name = environment_backend()
        if not name:
            choice = default_choice(work, program, tiered)
            name = "numpy" if choice is None else choice.name
    got = plugin(name)
    if got is None:
        raise SwarmOptionError(f"unknown backend `{name}`: choose {_choices()}")
    if not got.installed():
        raise SwarmOptionError(f"the {name} backend {got.missing}")
    tier = choice is not None and getattr(choice, "tiered", False) and got.tiered
    backend = got.tiered() if tier else got.factory()
    if choice is not None:
        backend.choice, backend.why = choice, choice.why
    return backend


def lowering(name: str | None):
    """The compiler lowering backend `name` runs with, for a command that compiles for
    a backend it names up front; None: the backend lowers when the run starts (or
    runs the reference closures as they are)."""
    got = None if name is None else plugin(name)
    return None if got is None or got.lowering is None else got.lowering()


def notes() -> list[str]:
    """Lines about every installed backend for a sweep's plan (e.g. its threads)."""
    out: list[str] = []
    for name in names():
        got = plugin(name)
        if got is not None and got.notes is not None and got.installed():
            out += got.notes()
    return out
