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
on stderr once, and `-v` says why. A run that ends first stops the compile. One compile
runs per program text and process at a time: a run made again from the same text (the
studio after an edit of a param, a sweep worker's next run) waits for the same one.
"""

from __future__ import annotations

import atexit
import json
import os
import subprocess
import sys
import tempfile
import time
import types

from swarmdsl.runtime.numpy_backend import NumpyBackend

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
        """"running", "done" or "failed" (`reason` says why)."""
        if self.state != "running":
            return self.state
        code = self._proc.poll()
        if code is None:
            if self._said_ready():   # the per-tick kernels are on disk: the run may
                self.finished_at = time.perf_counter()  # switch while this process
                self.state = "done"                     # compiles the whole-tick one
                self._log.close()
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

    def _said_ready(self) -> bool:
        """Whether the warm-up has written `READY` (read without moving the file's
        offset, which the process writing it shares)."""
        from swarmdsl.runtime.compiled.warmup import READY

        try:
            text = os.pread(self._log.fileno(), 1 << 16, 0)
        except (OSError, ValueError):
            return False
        return f"{READY}\n".encode() in text

    def _last_line(self) -> str:
        self._log.seek(0)
        lines = [ln.strip() for ln in self._log.read().decode(errors="replace").splitlines()
                 if ln.strip()]
        return lines[-1][:200] if lines else ""

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


atexit.register(_stop_all)


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
        """numpy's motion; after it, once the kernels are on disk, numba takes over the
        simulation from the next tick."""
        c = self.compile
        if c is None or sim.backend is not self:
            return None
        state = c.poll()
        if state == "done":
            self._switch(sim)
        elif state == "failed":
            self.failed = f"the compile in another process failed ({c.reason})"
            self.compile = None
            self._say()
        return None

    def _switch(self, sim) -> None:
        from swarmdsl.runtime import backends

        t0 = time.perf_counter()
        numba = backends.make("numba")
        numba.load_seconds = time.perf_counter() - t0
        numba.choice = self.choice
        numba.fields_compiled = self.fields_compiled
        self.switched_at = sim.tick + 1
        last = sim.tick
        numba.why = (f"ticks 0-{last} on numpy while its kernels compiled in another "
                     f"process ({self.compile.seconds:.1f} s), numba from tick {last + 1}"
                     if last >= 0 else "")
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
