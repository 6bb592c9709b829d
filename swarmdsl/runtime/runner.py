"""One run of a program: the tick loop with recording, progress and its observers (the
video and the viewer's window among them, plugged in by viz: `runtime/observers.py`).

Whatever stops the run (the last tick, Ctrl-C, SIGTERM or SIGHUP, a runtime fault, the
window closing, an internal error), the outputs are closed and hold every tick recorded
so far; closing is never cut by a second stop signal (see `swarmdsl.stopping`). An
exception that is not a `SwarmError` is a bug in swarmdsl: the run ends as a fault
naming it and the tick (`swarmdsl.internal`, exit 3), not with a traceback.
"""

from __future__ import annotations

from pathlib import Path

from swarmdsl import stopping
from swarmdsl.errors import SwarmError, SwarmOptionError
from swarmdsl.runtime import observers
from swarmdsl.runtime.arguments import Forkable
from swarmdsl.runtime.driver import Driver, Scheduled, Watch
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
        # the tick loop (`runtime/driver.py`); its observers are handed this Run
        self.driver = Driver(Simulation(program, seed, layout, backend, work), steps,
                             every=every, subject=self)
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
        self.windowed = False           # executed in the viewer's window
        self._checkpoints = Scheduled(self._checkpoint, lambda: self.checkpoint_every)
        self.driver.after_tick.append(self._checkpoints)
        self.driver.checks.append(self._stop_if_violated)

    # ---- what the driver keeps ----
    @property
    def sim(self) -> Simulation:
        return self.driver.sim

    @property
    def fault(self) -> SwarmError | None:
        return self.driver.fault

    @property
    def stop_signal(self) -> str:
        """What interrupted the run, when one did ("SIGINT", "SIGTERM", ...)."""
        return self.driver.stop_signal

    @property
    def stop_exit_code(self) -> int:
        return self.driver.stop_exit_code

    @property
    def tick_seconds(self) -> float:
        return self.driver.tick_seconds

    @property
    def record_seconds(self) -> float:
        """Writing outputs: rows, metrics, frames, checkpoints, closing."""
        return self.driver.observe_seconds

    @property
    def observed_tick(self) -> int:
        """The last tick sent to the outputs."""
        return self.driver.observed_tick

    # ---- driver protocol used by the viewer ----
    @property
    def tick(self) -> int:
        return self.sim.tick

    @property
    def done(self) -> bool:
        return self.driver.done

    def snapshot(self):
        return self.sim.snapshot()

    def step(self) -> None:
        if self.executed != "running":   # outside execute() the outputs are not open
            raise SwarmOptionError("Run.step() drives the viewer inside execute(): call "
                                   "run.execute(headless=False) to watch a Run, or step a "
                                   "Simulation(program, seed) by hand")
        # A stop signal takes effect between ticks: a tick cut halfway would leave rows
        # recorded without their field frames or metrics, or a state no tick ever had.
        self.driver.step()

    def _stop_if_violated(self, driver=None) -> None:
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

    def _checkpoint(self, driver) -> None:
        """After each tick: OUT/checkpoint every `checkpoint_every` ticks and at the end."""
        tick = self.sim.tick
        if self.checkpoint_every and self.recorder is not None and (
                tick % self.checkpoint_every == 0 or tick == self.steps):
            from swarmdsl.runtime.resume import save_run

            save_run(self)

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
        self.driver.observers = [_Outputs(), *self.observers]
        self._window_reason = None
        outcome = "fault"
        try:
            outcome = self.driver.attempt(lambda: self._body(headless, fps))
            if outcome == "completed" and self._window_reason not in (None, "done"):
                outcome = "quit"
        finally:
            self.executed = outcome
            self.close(outcome)
        return outcome

    def _body(self, headless: bool, fps: int) -> None:
        with stopping.uncut():      # the old run's files go, the new run's first tick
            if self.recorder is not None:   # is written, or neither
                self.recorder.begin(resumed=self.resumed_at is not None)
            if self.record_path is not None:
                self._video = observers.video(self.video_file, self.fps, self.video_px)
                self.observers.append(self._video)
                self.driver.observers.append(self._video)
            # a resumed run's checkpoint tick is observed already
            self.driver.start(observe=self.resumed_at is None)
            if self.resumed_at is not None:
                self.driver.observed_tick = self.sim.tick
            else:
                self._stop_if_violated()
        self.windowed = not headless
        if headless:
            self._loop()
        else:
            self._window_reason = observers.window(self, fps,
                                                   Path(self.program.filename).name)
            self.driver.stopped_between_ticks = True

    def _check_checkpoint_every(self) -> None:
        """`run.checkpoint_every` is set by hand: "10" once failed at tick 1 as an
        internal error, and K with no `out` wrote no checkpoint without a word."""
        from swarmdsl.runtime.arguments import whole

        self.checkpoint_every = whole("checkpoint_every", self.checkpoint_every, 0, 2**62)
        if self.checkpoint_every and self.recorder is None:
            raise SwarmOptionError("checkpoint_every needs a Run with out=DIR (checkpoints "
                                   "go in DIR/checkpoint)")

    def attach(self, observer: observers.Observer) -> None:
        """Have `observer` watch this run's recorded ticks (before `execute`)."""
        if self.executed is not None:
            raise SwarmOptionError("attach observers before run.execute()")
        self.observers.append(observer)

    def _loop(self) -> None:
        from swarmdsl.runtime.progress import Progress

        # `Run.step` as written only steps the driver, which then may hand the ticks no
        # output needs to the simulation at once; a `step` a script or test put in its
        # place sees every tick
        own = "step" in vars(self) or type(self).step is not _PLAIN_STEP
        # what watches each tick only when there is something to watch for, so the
        # driver may run the ticks between records at once
        if not self.checkpoint_every and self._checkpoints in self.driver.after_tick:
            self.driver.after_tick.remove(self._checkpoints)
        if not any(hasattr(ext, "violation") for ext in self.sim.extensions) \
                and self._stop_if_violated in self.driver.checks:
            self.driver.checks.remove(self._stop_if_violated)
        self.driver.run(progress=Progress(self.steps if self.show_progress else 0,
                                          self.sim.tick), step=self.step if own else None)

    def close(self, outcome: str = "completed") -> None:
        """Close every output (a stop tick recorded first), stop signals held."""
        self.driver.close(outcome)
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


class _Outputs:
    """A Run's metric log and recorder as the first of its observers: the rows and
    samples of each recorded tick, and what its end writes (a checkpoint at a stop
    signal, run.json's timing, outcome and fault)."""

    def start(self, run: Run) -> None:
        """The recorder began already: before the video opened (`Run._body`)."""

    def tick(self, run: Run) -> None:
        run.metrics.sample(run.sim)
        if run.recorder is not None:
            run.recorder.sim = run.sim      # the driver's, also after a `switch`
            run.recorder.record()

    def watch(self, run: Run):
        """A run that records no agent rows (metrics only: a sweep's solo run, `run`
        without `--out`) lets the backend sample its metrics inside a call of whole
        ticks (`driver.Watch`); None when rows are recorded."""
        if run.recorder is not None:
            return None
        return Watch(metrics=bool(run.metrics))

    def watched(self, run: Run, watch) -> None:
        """The metric samples of the ticks the backend ran whole."""
        if watch.samples is not None:
            ticks, rows = watch.samples
            for tick, row in zip(ticks.tolist(), rows, strict=True):
                run.metrics.add_row(tick, row)

    def close(self, run: Run, outcome: str) -> None:
        recorder, driver = run.recorder, run.driver
        if (outcome == "interrupted" and driver.stopped_between_ticks
                and run.checkpoint_every and recorder is not None):
            from swarmdsl.runtime.resume import save_at_stop

            save_at_stop(run)      # a preempted job resumes at its stop tick
        if recorder is not None:
            if run.metrics:    # its samples are flushed with the recorder's rows
                recorder.extra_json["metrics"] = run.metrics.summary()
            # a resumed run: the whole run's time when its checkpoint kept the time
            # before it (older ones did not: then this process's ticks only)
            recorder.wall_seconds = run.tick_seconds_before + run.tick_seconds
            recorder.ticks_timed = None if run.timed_before else run.ticks_run
            if outcome == "interrupted":
                recorder.extra_json["signal"] = run.stop_signal
            if outcome == "fault" and run.fault is not None:
                recorder.extra_json["error"] = str(run.fault)
            recorder.extra_json["backend"] = run.sim.backend.name
            recorder.extra_json["compile_seconds"] = round(
                run.sim.backend.compile_seconds, 6)
            recorder.sim = run.sim
            recorder.close(run.sim.tick, outcome)
        run.sim.backend.finished(run.program, run.sim.tick)


_PLAIN_STEP = Run.step
