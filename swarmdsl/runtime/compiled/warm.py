"""Which programs this machine has compiled: one marker file per program, so the default
backend can choose numba for shorter runs without importing numba to find out; and
whether numba's shared kernels are on disk, so the tiered start's warm-up knows it may
offer them first (`warmup.py`).

A first numba run of a program compiles its kernels (seconds, `choice.py`); once they
are on disk a later process loads them in about 0.1 s and importing numba costs about
0.3 s, so numba repays several times shorter runs (100 boids for 2,000 ticks: numba 3x
faster than numpy from there). Only numba can say what its disk cache holds,
and importing it to ask costs the 0.3 s a short run is trying to save, so a numba run
whose every kernel is kept on disk (`disk_cache.not_kept`) leaves a marker in
swarmdsl's cache folder, named by the program's text and swarmdsl's version. A stale
marker (numba's cache deleted, another numba) costs one run its compile time, never a
different result: both backends compute the same program.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from swarmdsl.version import __version__


def _marker(name: str) -> Path | None:
    """The marker file `name` in swarmdsl's cache folder (None: no folder, or kernels
    are not kept on disk)."""
    from swarmdsl.compiler.grammar_cache import cache_dir
    from swarmdsl.runtime.compiled import disk_cache

    folder = cache_dir()
    if folder is None or not disk_cache.enabled():
        return None
    return folder / "compiled" / name


def _program_marker(program) -> Path | None:
    return _marker(hashlib.sha256(f"{__version__}\0{program.source}".encode()).hexdigest()[:32])


def _shared_marker(threaded: bool) -> Path | None:
    return _marker(f"shared-{__version__}-{'threads' if threaded else 'serial'}")


def _mark(path: Path | None) -> None:
    """Leave marker `path` if every kernel this process built was kept on disk. An
    unwritable cache folder only means no marker."""
    from swarmdsl.runtime.compiled import disk_cache

    if path is None or disk_cache.not_kept:
        return
    try:
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        path.touch()
    except OSError:
        pass


def keeps_kernels() -> bool:
    """Whether a first numba run keeps its kernels on disk for later processes."""
    from swarmdsl.runtime.compiled import disk_cache

    return disk_cache.enabled()


def compiled_here(program) -> bool:
    """Whether a numba run of `program` has left all its kernels on this machine."""
    path = _program_marker(program)
    return path is not None and path.is_file()


def note_compiled(program) -> None:
    """Mark `program` compiled here: called after a numba run that kept every kernel it
    built on disk."""
    _mark(_program_marker(program))


def _whole_marker(program) -> Path | None:
    return _marker("whole-" + hashlib.sha256(
        f"{__version__}\0{program.source}".encode()).hexdigest()[:32])


def whole_here(program) -> bool:
    """Whether `program`'s whole-tick kernel (`tick_kernel.py`) is on disk here: a run
    of it took whole ticks from a kernel kept there. Its shape holds no numbers, so one
    kernel serves every param value; a stale marker costs a run its per-tick path,
    never a different result."""
    path = _whole_marker(program)
    return path is not None and path.is_file()


def note_whole(program) -> None:
    """Mark `program`'s whole-tick kernel kept on disk here (`tick_run.advance`, once
    its machine code is on disk)."""
    _mark(_whole_marker(program))


def shared_here(threaded: bool) -> bool:
    """Whether a warm-up (`warmup.py`) has kept numba's shared kernels on disk here, for
    runs of that many agents (`threaded`: split over threads). A stale marker costs one
    run's `SHARED` stage its compile time, never a different result."""
    path = _shared_marker(threaded)
    return path is not None and path.is_file()


def note_shared(threaded: bool) -> None:
    """Mark numba's shared kernels kept on disk here, for runs of that size: after a
    warm-up stepped a swarm with them, if every kernel it built was kept."""
    _mark(_shared_marker(threaded))
