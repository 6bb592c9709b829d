"""The tiered start: a run ticks on the numpy reference at once while another process
compiles its numba kernels, and takes numba from the next tick once they are on disk.

A first numba run of a program waits seconds for numba to compile its kernels (boids at
10^4 agents: 10 s of an 18 s run). Both backends give the same bits
(docs/backends.md#the-two-backends-agree), so a run may as well start on numpy and change
backend between two ticks. `TieredBackend` is the numpy backend until then: when the run
starts it lowers the program for numba (planning imports no numba) and starts
`python -m swarmdsl.runtime.compiled.warmup`, which compiles the same program text with
the same params and steps a copy of its swarm for a few ticks on numba, which leaves
every kernel those ticks ran in the kernel cache on disk (`disk_cache.py`; the cell list,
motion and draws in numba's own). At the end of each tick's motion the backend asks
whether that process has finished; once it has, it makes a `NumbaBackend` (its kernels
load from disk in a fraction of a second) and puts it in the simulation's place, with
what the numpy phase built that it needs: the draws' compiled loop, the fields'
compiled loops (each field takes its compiled class on its next call), the motion
report. The pair table is built afresh every tick, so nothing of it carries over. From
the next tick on the run is a numba run; the one line of `-v` says when it changed.

A compile that fails, or a process that is killed, leaves the run on numpy: it says so
on stderr once, and `-v` says why. A run that ends first leaves the compile running for
later runs, in this process and, once it exits, on its own (`_at_exit`). One compile
runs per program text and process at a time: a run made again from the same text (the
studio after an edit of a param, a sweep worker's next run) waits for the same one.
"""

from __future__ import annotations

import atexit
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import types

from swarmdsl.runtime.compiled.warmup import READY, SHARED
from swarmdsl.runtime.numpy_backend import NumpyBackend

# A fused part's `-v` line (`fused.part_line`): "LINE:COL label: compiled ...".
_PART_LINE = re.compile(r"^(\d+:\d+ .*?): compiled.*$")
# What a field's compiled class overrides (`compiled/fields.py`'s `CompiledField`): a
# field of a tiered run calls these on numpy until the run switches, then takes that
# class (tests/test_tiered.py checks the list against it).
FIELD_METHODS = ("_starts", "sample", "gradient", "_splat", "_spread", "_diffuse")


class Compile:
    """One background compile: the warm-up process (`warmup.py`) for a program text and
    its params, and what became of it."""

    def __init__(self, request: dict, argv: list[str] | None = None):
        self.started = time.perf_counter()
        self.finished_at: float | None = None
        self.shared_at: float | None = None   # when it was seen to say `SHARED`
        self.reason = ""            # why it failed, when it did
        self._log = tempfile.TemporaryFile()
        argv = argv or [sys.executable, "-m", "swarmdsl.runtime.compiled.warmup"]
        self._proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=self._log,
                                      stderr=subprocess.STDOUT)
        try:
            self._proc.stdin.write(json.dumps(request).encode())
            self._proc.stdin.close()
        except OSError:             # it died already: poll() says how
            pass
        self.state = "running"

    def poll(self) -> str:
        """"running", "shared" (numba's shared kernels are on disk, the program's are
        compiling), "done" or "failed" (`reason` says why)."""
        if self.state not in ("running", "shared"):
            return self.state
        code = self._proc.poll()
        if code is None:
            said = self._said()
            if SHARED in said and self.shared_at is None:
                self.shared_at = time.perf_counter()
            if READY in said:        # the per-tick kernels are on disk: the run may
                self.finished_at = time.perf_counter()  # switch while this process
                self.state = "done"                     # compiles the whole-tick one
                self._log.close()
            elif SHARED in said:
                self.state = "shared"
            return self.state
        self.finished_at = time.perf_counter()
        if code == 0:
            self.state = "done"
        else:
            self.state = "failed"
            self.reason = (f"killed by signal {-code}" if code < 0
                           else self._last_line() or f"exit status {code}")
        self._log.close()
        return self.state

    @property
    def seconds(self) -> float:
        """How long it ran (so far)."""
        return (self.finished_at or time.perf_counter()) - self.started

    def alive(self) -> bool:
        """Whether the process is still compiling (after `READY`: the whole ticks)."""
        return self._proc.poll() is None

    def _said(self) -> set[str]:
        """Which of the warm-up's words (`SHARED`, `READY`) it has written, each on its
        own line (read without moving the file's offset, which the process writing it
        shares)."""
        try:
            text = os.pread(self._log.fileno(), 1 << 16, 0)
        except (OSError, ValueError):
            return set()
        return {w for w in (SHARED, READY) if f"{w}\n".encode() in text}

    def _last_line(self) -> str:
        self._log.seek(0)
        lines = [ln.strip() for ln in self._log.read().decode(errors="replace").splitlines()
                 if ln.strip()]
        return lines[-1][:200] if lines else ""

    def leave(self) -> None:
        """Let the process go on after this one exits (its own output file stays open
        in it)."""
        if not self._log.closed:
            self._log.close()

    def stop(self) -> None:
        """End the process if it is still compiling (a run ended, the process exits):
        before `READY` the compile failed; after, only the whole-tick kernel is lost."""
        if self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()
            if self.state == "running":
                self.state, self.reason = "failed", "stopped: the run ended first"
        if not self._log.closed:
            self._log.close()


# The compile in flight or finished for each program text (a later run of the same text
# takes it over).
_COMPILES: dict[str, Compile] = {}


def _stop_all() -> None:
    for c in _COMPILES.values():
        c.stop()


def _at_exit() -> None:
    """The process ends. A compile still running goes on in its own process until its
    kernels are on disk, so that later runs load them, as the backend line promised
    ("kept for later runs"): a run shorter than its compile would otherwise never get
    them. `SWARMDSL_COMPILE_AFTER_EXIT=0` stops it instead. It shares the run's process
    group, so Ctrl-C in a terminal stops it with the run."""
    if os.environ.get("SWARMDSL_COMPILE_AFTER_EXIT", "1").strip().lower() in (
            "0", "no", "off"):
        _stop_all()
        return
    for c in _COMPILES.values():
        c.leave()


atexit.register(_at_exit)


def request(program) -> dict:
    """What the warm-up process needs to compile `program` again: its text, file, folder
    and every param's value as `--set` writes it."""
    from swarmdsl.runtime.arguments import param_text

    return {"source": program.source, "filename": program.filename,
            "program_dir": str(program.program_dir),
            "params": {k: param_text(v) for k, v in program.params.items()}}


def _key(program) -> str:
    """Which compile a program can take over: one of the same text (its params are
    values in the kernels' tables, not part of their code)."""
    return json.dumps([program.filename, program.source])


def compile_for(program, argv=None) -> Compile:
    """The background compile of `program`: the one in flight (or done) for its text,
    else a new one; a compile of another text still running is stopped (one at a time:
    an edited program's kernels are the ones wanted now)."""
    key = _key(program)
    got = _COMPILES.get(key)
    if got is not None and got.poll() != "failed":
        return got
    for other in list(_COMPILES):
        if _COMPILES[other].alive():    # compiling another text, or its whole ticks
            _COMPILES.pop(other).stop()
    got = _COMPILES[key] = Compile(request(program), argv)
    return got


def compiled_in_process(program) -> bool:
    """Whether this process has a finished background compile of `program`."""
    got = _COMPILES.get(_key(program))
    return got is not None and got.poll() == "done"


class TieredBackend(NumpyBackend):
    """The numpy backend until another process has compiled the run's numba kernels,
    then a `NumbaBackend` in its place (`move`)."""

    name = "tiered"

    def __init__(self, argv: list[str] | None = None, compile_=None):
        super().__init__()
        self._argv = argv               # the warm-up's command (tests stand in for it)
        self.compile: Compile | None = compile_
        self.switched_at: int | None = None   # the first tick on numba
        self.failed = ""                # why the run stayed on numpy
        self.numba = None               # the NumbaBackend, once switched
        self._fields = types.SimpleNamespace(compiled=False)   # what its fields ask

    def prepare(self, program) -> None:
        """Lower `program` for numba (its lowered closures run the reference while this
        backend's `fused` is False) and start compiling its kernels elsewhere."""
        from swarmdsl.runtime.compiled.lowering import NUMBA

        program.lower(NUMBA)
        if self.compile is None:
            try:
                self.compile = compile_for(program, self._argv)
            except OSError as exc:      # no process could start: numpy throughout
                self.failed = f"the compile could not start: {exc}"
                self._say()
        self._program = program

    def field_type(self, reference: type) -> type:
        """numpy's `Field` until the switch, then each field takes the compiled class."""
        return type("TieredField", (reference,), {
            name: _field_method(name, reference, self._fields) for name in FIELD_METHODS})

    def move(self, sim):
        """numpy's motion; after it, once numba's shared kernels are on disk, they take
        over the simulation from the next tick (`SharedFirst`), or numba whole once the
        program's own kernels are there too."""
        c = self.compile
        if c is None or sim.backend is not self:
            return None
        state = c.poll()
        if state in ("shared", "done"):
            self._switch(sim, state)
        elif state == "failed":
            self.failed = f"the compile in another process failed ({c.reason})"
            self.compile = None
            self._say()
        return None

    def _switch(self, sim, state: str) -> None:
        from swarmdsl.runtime import backends

        t0 = time.perf_counter()
        if state == "shared":
            numba = _shared_first(backends.plugin("numba").factory)(self.compile, sim.tick)
        else:
            numba = backends.make("numba")
        numba.load_seconds = time.perf_counter() - t0
        numba.choice = self.choice
        numba.fields_compiled = self.fields_compiled
        self.switched_at = sim.tick + 1
        last = sim.tick
        if state == "done":
            numba.why = (f"ticks 0-{last} on numpy while its kernels compiled in another "
                         f"process ({self.compile.seconds:.1f} s), numba from tick "
                         f"{last + 1}" if last >= 0 else "")
        self.numba = numba
        self._fields.compiled = True
        sim.backend = numba
        sim.rng.compiled_units = numba.random_units

    def finished(self, program, ticks: int) -> None:
        """The run ended on numpy. A compile still running goes on (a later run of the
        same text in this process takes it over) until the process exits."""
        if self.compile is not None and self.compile.poll() == "running":
            self.failed = (f"the run ended before its kernels compiled "
                           f"({self.compile.seconds:.1f} s so far)")

    def _say(self) -> None:
        print(f"backend: numpy from here on: {self.failed}", file=sys.stderr)

    def summary(self, program) -> list[str]:
        """`run -v` for a run that never switched: numpy, and why."""
        why = self.failed
        if not why and self.compile is not None:
            why = f"its kernels were still compiling in another process " \
                  f"({self.compile.seconds:.1f} s)"
        return [f"backend: numpy ({why}; every tick on numpy)"]


class SharedFirst:
    """(Mixed into the numba backend's class: `_shared_first`, so that this module
    need not import the backend's package, which imports it.)

    The numba backend while only its shared kernels are on disk: the cell list, the
    motion, the draws, the fields' loops and the portable math's (numba's own
    `cache=True` kernels, the same for every program, which the warm-up compiles or
    loads first and then says `SHARED`), with the reference closures for the program's
    aggregates and statements (`fused` is False) until their kernels are on disk too,
    when the warm-up says `READY`; from the next tick the backend is numba whole.

    Why a stage between: numpy spends most of a big run's tick building the pair table
    (boids at 10^4 agents, its flock gathering: 75 of 111 ms a tick), which the shared
    cell list builds in a few milliseconds, and the program's own kernels take seconds
    more to compile than the shared ones take to load. Both stages give the reference's
    bits, so the run's result does not depend on when either switch came."""

    def __init__(self, compile_: Compile, numpy_until: int):
        super().__init__()
        self.fused = False
        self.compile: Compile | None = compile_
        self.numpy_until = numpy_until      # the last tick on numpy (-1: none)
        self.fused_at: int | None = None    # the first tick with the program's kernels
        self.failed = ""

    def move(self, sim):
        """The compiled motion; after it, once the program's kernels are on disk, they
        run from the next tick."""
        got = super().move(sim)
        if self.fused:
            return got
        c = self.compile
        if c is not None:
            state = c.poll()
            if state == "done":
                self.fused, self.fused_at = True, sim.tick + 1
                # as a fresh numba backend: the sums search the cells themselves next
                # tick, with the kernel the warm-up compiled (the reference read the
                # pairs until now; summing those would compile another loop here)
                self._filled = False
            elif state == "failed":
                self.failed = f"the compile in another process failed ({c.reason})"
                self.compile = None
                print(f"backend: numba's shared kernels from here on, the program's "
                      f"parts on the reference closures: {self.failed}", file=sys.stderr)
        self.why = self._stages()
        return got

    def _stages(self) -> str:
        """What `-v` says of the run's ticks: numpy, the shared kernels, numba."""
        numpy = (f"ticks 0-{self.numpy_until} on numpy, "
                 if self.numpy_until >= 0 else "")
        start = self.numpy_until + 1
        if self.fused_at is not None:
            return (f"{numpy}ticks {start}-{self.fused_at - 1} on numba's shared kernels "
                    f"while its kernels compiled in another process "
                    f"({self.compile.seconds:.1f} s), numba from tick {self.fused_at}")
        why = self.failed or (f"its kernels were still compiling in another process "
                              f"({self.compile.seconds:.1f} s)" if self.compile else "")
        return (f"{numpy}numba's shared kernels from tick {start} (the cell list, motion, "
                f"draws and fields), the program's aggregates and statements on the "
                f"reference closures: {why}")

    def summary(self, program) -> list[str]:
        """`run -v`: a run that ended before the program's kernels took over ran its
        aggregates and statements on the reference closures only."""
        lines = super().summary(program)
        if self.fused:
            return lines
        return [_PART_LINE.sub(r"\1: the reference closures (its kernels were not on disk "
                               r"yet)", line) for line in lines]

    def advance(self, sim, ticks: int, watch=None) -> int:
        """Whole ticks need the program's kernels: none before they are on disk."""
        return super().advance(sim, ticks, watch) if self.fused else -1

    def whole_ticks_ready(self, sim, left: float = 0.0, watch=None) -> bool:
        return self.fused and super().whole_ticks_ready(sim, left, watch)

    def finished(self, program, ticks: int) -> None:
        """Marked compiled on this machine only once the program's kernels ran."""
        if self.fused:
            super().finished(program, ticks)


_STAGED: dict = {}    # the numba backend's class -> it with `SharedFirst` mixed in


def _shared_first(numba) -> type:
    if not isinstance(numba, type):     # a factory function: the class it makes
        numba = type(numba())
    got = _STAGED.get(numba)
    if got is None:
        got = _STAGED[numba] = type("SharedFirst", (SharedFirst, numba), {})
    return got


def _field_method(name: str, reference: type, switch):
    """Field method `name`: the reference's until the run switched to numba
    (`switch.compiled`), whose compiled class the field then takes for good."""

    def method(self, *args, **kw):
        if switch.compiled:
            from swarmdsl.runtime.compiled.fields import CompiledField

            self.__class__ = CompiledField
            return getattr(CompiledField, name)(self, *args, **kw)
        return getattr(reference, name)(self, *args, **kw)

    method.__name__ = name
    return method


def environment_ready() -> bool:
    """Whether a background compile can hand kernels over: the kernel cache is on."""
    from swarmdsl.runtime.compiled import disk_cache

    return disk_cache.enabled() and os.environ.get("SWARMDSL_TIERED", "1") != "0"
