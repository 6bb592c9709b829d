"""One run of a program: the tick loop with recording, progress and its observers (the
video and the viewer's window among them, plugged in by viz: `runtime/observers.py`).

Whatever stops the run (the last tick, Ctrl-C, SIGTERM or SIGHUP, a runtime fault, the
window closing, an internal error), the outputs are closed and hold every tick recorded
so far; closing is never cut by a second stop signal (see `swarmdsl.stopping`). An
exception that is not a `SwarmError` is a bug in swarmdsl: the run ends as a fault
naming it and the tick (`swarmdsl.internal`, exit 3), not with a traceback.
"""

from __future__ import annotations

import time
from pathlib import Path

from swarmdsl import stopping
from swarmdsl.errors import SwarmError, SwarmOptionError
from swarmdsl.internal import internal_error
from swarmdsl.runtime import observers
from swarmdsl.runtime.arguments import Forkable
from swarmdsl.runtime.metrics import MetricLog
from swarmdsl.runtime.simulation import Simulation


class Run(Forkable):
    show_progress = True      # a sweep's worker runs many runs quietly
    checkpoint_every = 0      # save OUT/checkpoint every K ticks and at the end (0: never)
    resumed_at: int | None = None
    tick_seconds_before: float = 0.0    # ticking time of a resumed run before this process
    timed_before: bool = False          # ... known from its checkpoint
    executed: str | None = None     # the outcome, once `execute` has been called

    def resume(self, folder: Path) -> int:
        """Continue from the checkpoint in `folder` (a run's --out); returns its tick.

        Refuses, before any file is touched, what `run --resume` refuses: another seed,
        fewer steps than the checkpoint's tick, another `out`, a Run already executed.
        """
        from swarmdsl.runtime.arguments import required_path
        from swarmdsl.runtime.resume import check_resume, resume_run

        folder = required_path("folder", folder, "resume needs the run's out folder")
        check_resume(self, folder)
        self.resumed_at = resume_run(self, folder)
        return self.resumed_at

    def __init__(self, program, *, seed: int = 0, steps: int | None = None,
                 out: Path | None = None, every: int = 1, record: Path | None = None,
                 video_px: int = 640,
                 layout=None, backend: str | None = None, tree_leaf: bool = False,
                 tree_memory: bool = False):
        from swarmdsl.runtime.arguments import check_run_arguments

        seed, steps, every, out, record, video_px = check_run_arguments(
            program, seed, steps, every, out, record, video_px)
        self.program = program
        self.steps = steps
        self.every = every
        self.tree_leaf = bool(tree_leaf)       # a checkpoint names the columns it records
        self.tree_memory = bool(tree_memory)
        work = steps * sum(k.count for k in program.kinds)   # guides the default backend
        self.sim = Simulation(program, seed, layout, backend, work)
        if tree_leaf:   # before the recorder, which takes the column from the sim
            from swarmdsl.runtime.trees import record_active_leaf

            record_active_leaf(self.sim)
        if tree_memory:
            from swarmdsl.runtime.trees import record_tree_memory

            record_tree_memory(self.sim)
        self.metrics = MetricLog(program)
        # `out` and `record` as given, for the summary; the files go where they named
        # when the Run was made (and were checked), also after a notebook's `%cd`
        self.out, self.record_path = out, record
        self.video_file = None if record is None else record.absolute()
        self.recorder = None
        if out is not None:
            from swarmdsl.runtime.record import Recorder

            self.recorder = Recorder(out.absolute(), self.sim, self.every, self.metrics)
        self.video_px = video_px
        self.observers: list[observers.Observer] = []   # besides recorder and metrics
        self._video = None              # the `record` video's observer, once it starts
        self.video_complete = False     # the video was finished and moved into place
        self.video_error: str | None = None     # why it was not
        self.fault: SwarmError | None = None
        self.stop_signal = "SIGINT"     # what interrupted the run, when one did
        self.stop_exit_code = 130
        self.tick_seconds = 0.0
        self.record_seconds = 0.0       # writing outputs: rows, metrics, frames, checkpoints
        self.windowed = False           # executed in the viewer's window
        self.observed_tick = -1         # the last tick sent to the outputs
        self.stopped_between_ticks = False  # a stop signal or the window: a whole tick

    # ---- driver protocol used by the viewer ----
    @property
    def tick(self) -> int:
        return self.sim.tick

    @property
    def done(self) -> bool:
        return self.sim.tick >= self.steps

    def snapshot(self):
        return self.sim.snapshot()

    def step(self) -> None:
        if self.executed != "running":   # outside execute() the outputs are not open
            raise SwarmOptionError("Run.step() drives the viewer inside execute(): call "
                                   "run.execute(headless=False) to watch a Run, or step a "
                                   "Simulation(program, seed) by hand")
        if self.done:
            return
        # A stop signal takes effect between ticks: a tick cut halfway would leave rows
        # recorded without their field frames or metrics, or a state no tick ever had.
        stopping.check()
        with stopping.uncut():
            compiling = self.sim.backend.compile_seconds
            t0 = time.perf_counter()
            self.sim.step()
            # ticks only: numba's one-off kernel compilation is reported on its own
            self.tick_seconds += (time.perf_counter() - t0
                                  - (self.sim.backend.compile_seconds - compiling))
            self._observe()
        self._stop_if_violated()

    def _stop_if_violated(self) -> None:
        """Raise a property violation found this tick (`run --check`), after the tick
        is recorded, so the outputs end at the violating state."""
        for ext in self.sim.extensions:
            found = getattr(ext, "violation", lambda sim: None)(self.sim)
            if found is not None:
                if self.recorder is not None:
                    if not self.recorder.ticks or self.recorder.ticks[-1] != self.sim.tick:
                        self.recorder.record()
                    self.recorder.extra_json["violation"] = found.details
                raise found

    def _observe(self) -> None:
        tick = self.sim.tick
        t0 = time.perf_counter()
        if tick % self.every == 0 or tick == self.steps:
            self._record_tick()
        if self.checkpoint_every and self.recorder is not None and (
                tick % self.checkpoint_every == 0 or tick == self.steps):
            from swarmdsl.runtime.resume import save_run

            save_run(self)
        self.record_seconds += time.perf_counter() - t0

    # ---- the loop ----
    def execute(self, headless: bool = True, fps: int = 30) -> str:
        """Run to the end; returns "completed", "quit", "interrupted" or "fault".

        A Run executes once: its outputs are closed when it ends, so a second call is
        an option error (it used to clear the finished run's files and write nothing).
        In a script or notebook a Ctrl-C is handled as the command handles it
        (`stopping.plain_ctrl_c`): one landing while the files close lets them close.
        """
        if self.executed is not None:
            raise SwarmOptionError(f"this Run has already run ({self.executed}); build a "
                                   "new Run(program, ...) to run it again")
        self._check_checkpoint_every()
        with stopping.plain_ctrl_c():
            return self._execute(headless, fps)

    def _execute(self, headless: bool, fps: int) -> str:
        self.fps = fps          # the window's pace and the recorded video's frame rate
        self.executed = "running"
        outcome = "completed"
        try:
            with stopping.uncut():      # the old run's files go, the new run's first tick
                if self.recorder is not None:   # is written, or neither
                    self.recorder.begin(resumed=self.resumed_at is not None)
                self._start_observers()
                self._observe_start()
            self.windowed = not headless
            if headless:
                self._loop()
            else:
                reason = observers.window(self, fps, Path(self.program.filename).name)
                outcome = "completed" if reason == "done" else "quit"
                self.stopped_between_ticks = True
        except KeyboardInterrupt as stop:
            outcome = "interrupted"
            if isinstance(stop, stopping.Stopped):  # raised between ticks (`uncut`)
                self.stop_signal, self.stop_exit_code = stop.name, stop.exit_code
                self.stopped_between_ticks = True
        except SwarmError as err:
            self.fault = err.with_source(self.program.source)
            outcome = getattr(err, "outcome", "fault")
        except Exception as exc:    # a bug in swarmdsl: a fault the user can report
            self.fault = internal_error(exc, self.sim.tick)
            outcome = "fault"
        finally:
            self.executed = outcome
            with stopping.deferred():
                self.close(outcome)
        return outcome

    def _check_checkpoint_every(self) -> None:
        """`run.checkpoint_every` is set by hand: "10" once failed at tick 1 as an
        internal error, and K with no `out` wrote no checkpoint without a word."""
        from swarmdsl.runtime.arguments import whole

        self.checkpoint_every = whole("checkpoint_every", self.checkpoint_every, 0, 2**62)
        if self.checkpoint_every and self.recorder is None:
            raise SwarmOptionError("checkpoint_every needs a Run with out=DIR (checkpoints "
                                   "go in DIR/checkpoint)")

    def _observe_start(self) -> None:
        if self.resumed_at is not None:     # the checkpoint's tick is observed already
            self.observed_tick = self.sim.tick
            return
        t0 = time.perf_counter()
        self._record_tick()
        self.record_seconds += time.perf_counter() - t0
        self._stop_if_violated()

    def _record_tick(self) -> None:
        """The current tick into every output: metrics, agent rows, a video frame."""
        self.observed_tick = self.sim.tick
        self.metrics.sample(self.sim)
        if self.recorder is not None:
            self.recorder.record()
        for observer in self.observers:
            observer.tick(self)

    def attach(self, observer: observers.Observer) -> None:
        """Have `observer` watch this run's recorded ticks (before `execute`)."""
        if self.executed is not None:
            raise SwarmOptionError("attach observers before run.execute()")
        self.observers.append(observer)

    def _start_observers(self) -> None:
        if self.record_path is not None:
            self._video = observers.video(self.video_file, self.fps, self.video_px)
            self.observers.append(self._video)
        for observer in self.observers:
            observer.start(self)

    def _loop(self) -> None:
        from swarmdsl.runtime.progress import Progress

        progress = Progress(self.steps if self.show_progress else 0, self.sim.tick)
        try:
            while not self.done:
                self.step()
                progress.update(self.sim.tick, self.sim.backend.compile_seconds)
        finally:
            progress.close()

    def close(self, outcome: str = "completed") -> None:
        t0 = time.perf_counter()
        try:
            self._close(outcome)
        finally:
            self.record_seconds += time.perf_counter() - t0

    def _close(self, outcome: str) -> None:
        # A run stopped between ticks (a stop signal, the window closed) ends at a whole
        # tick: it is recorded as the last tick, on the `--every` grid or not.
        if self.stopped_between_ticks and self.observed_tick != self.sim.tick:
            self._record_tick()
        if (outcome == "interrupted" and self.stopped_between_ticks
                and self.checkpoint_every and self.recorder is not None):
            from swarmdsl.runtime.resume import save_at_stop

            save_at_stop(self)      # a preempted job resumes at its stop tick
        if self.recorder is not None:
            if self.metrics:    # its samples are flushed with the recorder's rows
                self.recorder.extra_json["metrics"] = self.metrics.summary()
            # a resumed run: the whole run's time when its checkpoint kept the time
            # before it (older ones did not: then this process's ticks only)
            self.recorder.wall_seconds = self.tick_seconds_before + self.tick_seconds
            self.recorder.ticks_timed = None if self.timed_before else self.ticks_run
            if outcome == "interrupted":
                self.recorder.extra_json["signal"] = self.stop_signal
            if outcome == "fault" and self.fault is not None:
                self.recorder.extra_json["error"] = str(self.fault)
            self.recorder.extra_json["backend"] = self.sim.backend.name
            self.recorder.extra_json["compile_seconds"] = round(
                self.sim.backend.compile_seconds, 6)
            self.recorder.close(self.sim.tick, outcome)
        self.sim.backend.finished(self.program, self.sim.tick)
        for observer in self.observers:
            observer.close(self, outcome)
        if self._video is not None:
            self.video_complete, self.video_error = self._video.complete, self._video.error

    @property
    def ticks_run(self) -> int:
        """The ticks this process ran (a resumed run starts at its checkpoint's)."""
        return self.sim.tick - (self.resumed_at or 0)

    def summary(self, outcome: str, elapsed: float) -> str:
        counts = ", ".join(f"{k} {v}" for k, v in self.sim.status_counts().items())
        what = {"completed": "ran", "quit": "stopped (window closed) after",
                "interrupted": "interrupted after" if self.stop_signal == "SIGINT"
                else f"interrupted by {self.stop_signal} after",
                "fault": "stopped by a fault after",
                "violation": "stopped by a property violation after"}[outcome]
        t, n = self.ticks_run, self.sim.agents.n
        resumed = (f" (resumed at tick {self.resumed_at}, now at {self.sim.tick})"
                   if self.resumed_at is not None else "")
        line = (f"{Path(self.program.filename).name}: {what} {t} tick{'s' * (t != 1)}"
                f"{resumed} of {n} agent{'s' * (n != 1)} in {elapsed:.2f} s"
                f"{self.time_parts(elapsed)}; {counts}")
        if self.recorder is not None:
            kept = len(self.recorder.ticks)
            line += f"; wrote {kept} recorded tick{'s' * (kept != 1)} to {self.out}"
        if self.record_path is not None:
            line += (f"; video {self.record_path}" if self.video_complete
                     else f"; no video written to {self.record_path}")
        return line

    def time_parts(self, elapsed: float) -> str:
        """Where the run's `elapsed` seconds went: `: 1.90 s simulating (158 ticks/s),
        0.50 s recording`. The rate is the simulation's alone; it used to stand beside a
        time that included recording and compiling, and the two did not agree."""
        parts = []
        compiling = self.sim.backend.compile_seconds
        if compiling >= 0.005:
            parts.append(f"{compiling:.2f} s compiling kernels")
        if self.ticks_run > 0:
            # no rate when no tick ran (a fault while placing or at tick 0): it read "inf"
            from swarmdsl.runtime.progress import rate_number

            rate = (f" ({rate_number(self.ticks_run / self.tick_seconds)} ticks/s)"
                    if self.tick_seconds > 0 else "")
            parts.append(f"{self.tick_seconds:.2f} s simulating{rate}")
        if self.recorder is not None or self.record_path is not None or self.metrics:
            parts.append(f"{self.record_seconds:.2f} s recording")
        other = elapsed - compiling - self.tick_seconds - self.record_seconds
        if parts and other >= max(0.05, 0.1 * elapsed):
            parts.append(f"{other:.2f} s {'in the window' if self.windowed else 'other'}")
        return ": " + ", ".join(parts) if parts else ""
