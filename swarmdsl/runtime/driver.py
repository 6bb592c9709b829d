"""The one tick loop: a simulation stepped between stop checks, timed, observed at its
recorded ticks, its fault caught at the tick it happened, and closed however it ends.

Every caller that advances a simulation steps it through a `Driver`: `Run` (and the
viewer's window, through `Run.step`), `Batch`'s batches, `swarmdsl test`'s checked
runs, `SwarmMachine`, the studio's session and `Simulation.run`. What each of them
does with a tick is an observer plugged in (`runtime/observers.py`: the recorder and
metric log, the property monitor, the video, the studio's plot stream), not a loop of
its own; so a stop, a fault or a new kind of tick boundary is handled once, here, and
every caller stops, faults and closes the same way (`tests/test_driver.py`).

A tick, `step()`:

1. `stopping.check()` (a stop that was lost on its way is honoured where a tick
   starts), unless the driver was made with `stops=False` (the studio's stepping
   thread, where the page, not a process signal, pauses the run; `Simulation.run`,
   where a notebook's Ctrl-C interrupts as Python's own does);
2. inside `stopping.uncut()` (a stop signal waits for the tick to end):
   the `between_ticks` callbacks, each `fn(driver)`, the place where work that must
   happen at a tick boundary goes (the tiered start's switch of a run's backend: a
   callback builds the new simulation, carries the state over with
   `checkpoint.carry(driver.sim, new)` and calls `driver.switch(new)`); then
   `sim.step()`, timed into `tick_seconds` without the backend's one-off kernel
   compilation; then, at a recorded tick (`due`), every observer's `tick(subject)`;
   then the `after_tick` callbacks, both timed into `observe_seconds` (a callback
   that needs only the ticks of its own grid, `Scheduled`, such as a checkpoint every
   K ticks, lets whole ticks run up to the next of them; any other sees every tick);
3. the `checks`, each `fn(driver)`, which may raise to stop the run after its tick is
   recorded (`run --check`'s property violation). A check reads what the tick's
   observers and extensions found, so it sees every tick, or the end of a run of
   whole ticks whose watching the backend did for them (a `Watch` covering every
   extension that watches ticks: `run --check`'s, which checks after every tick).

`attempt(body)` runs `body` and turns what stops it into an outcome ("completed",
"interrupted", "fault", or an error's own `outcome` such as "violation"), keeping the
fault (a `SwarmError` with the program's text; any other exception as an internal
error naming the tick, `swarmdsl.internal`) and `fault_tick`: the tick being computed
when `sim.step()` raised it (`fault_in_tick`), else the current tick.
`close(outcome)` records the stop tick of a run stopped between ticks (a whole tick, on
the `every` grid or not) and closes every observer with the outcome, with stop signals
held (`stopping.deferred`). `drive(body)` is the three together: start, attempt,
close, whatever happens.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarmdsl import stopping
from swarmdsl.errors import SwarmError

CHUNK_SECONDS = 0.05     # the longest a run of unobserved ticks should take
MAX_CHUNK = 1024         # ... and the most ticks in one


@dataclass
class Watch:
    """What observers need of the ticks they see, computed inside the backend's
    compiled call of whole ticks instead (an observer's `watch(subject)` offers one,
    None when it must see each tick itself): the `properties` (qualified names)
    checked at those ticks, the `premises` whose held agent-ticks are counted, the
    program's `metrics` sampled. The backend stops the call after the first tick
    where a property fails (`failed`: the observers then see that tick as usual) and
    fills in the results of the other ticks, which each observer takes in its
    `watched(subject, watch)`: agent-ticks checked and premise held, by property;
    the metric samples.

    An extension that only watches ticks (`run --check`'s checks, which stop the run
    at a violation) offers one the same way, `watch(sim)` and `watched(sim, watch)`,
    and is then in `covers`: the backend runs whole ticks past it only when the
    watch covers it. Its properties are checked at `each_tick`, not only the ticks
    the observers see; `observed` says whether the observers' watches are in it too
    (else the call ends at the next tick they see, which they see as usual)."""

    properties: tuple[str, ...] = ()
    premises: tuple[str, ...] = ()
    metrics: bool = False       # the program's metrics sampled at the ticks observed
    every: int = 1              # the ticks observed: on this grid ...
    last: int | None = None     # ... and this one (the run's end)
    agent_ticks: dict = field(default_factory=dict)
    premise_ticks: dict = field(default_factory=dict)
    failed: bool = False
    samples: tuple | None = None    # the metrics: (ticks (k,) int64, values (k, m))
    each_tick: bool = False     # the properties checked at every tick, not on `every`
    covers: tuple = ()          # the extensions whose watching it does
    observed: bool = True       # the observers' watches are in it

    @staticmethod
    def union(watches) -> Watch:
        props, premises = {}, {}
        for w in watches:
            props.update(dict.fromkeys(w.properties))
            premises.update(dict.fromkeys(w.premises))
        return Watch(tuple(props), tuple(premises), any(w.metrics for w in watches),
                     each_tick=any(w.each_tick for w in watches))


class Scheduled:
    """An `after_tick` callback that needs only the ticks on its grid (`every()` K:
    multiples of K, and the run's last), so whole ticks may run up to the next of them
    (a checkpoint every K ticks); `every()` 0 or None: it needs none."""

    def __init__(self, callback: Callable[[Driver], None], every: Callable[[], int | None]):
        self.callback, self.every = callback, every

    def __call__(self, driver: Driver) -> None:
        self.callback(driver)


class Driver:
    """Steps `sim` up to tick `steps` (None: no end), calling its observers with
    `subject` (default the driver; a `Run` hands itself, so observers read
    `run.sim`, `run.every`...) at every `every`-th tick and at `steps` (`every` None:
    only when `observe()` is called, as the studio samples once per frame)."""

    def __init__(self, sim, steps: int | None = None, *, every: int | None = 1,
                 subject: Any = None, stops: bool = True):
        self.sim = sim
        self.steps = steps
        self.every = every
        self.subject = self if subject is None else subject
        self.stops = stops
        self.observers: list = []          # `observers.Observer`s, in call order
        self.between_ticks: list[Callable[[Driver], None]] = []
        self.after_tick: list[Callable[[Driver], None]] = []
        self.checks: list[Callable[[Driver], None]] = []
        self.tick_seconds = 0.0             # in `sim.step()`, kernel compiling excluded
        self.observe_seconds = 0.0          # in observers, `after_tick` and closing
        self.observed_tick = -1             # the last tick the observers saw
        self.halted = False                 # `halt()`: `run` ends after this tick
        self.outcome: str | None = None
        self.fault: SwarmError | None = None    # with the program's text attached
        self.error: BaseException | None = None     # what `attempt` caught, as raised
        self.fault_tick: int | None = None
        self.fault_in_tick = False          # raised by `sim.step()`, not an observer
        self.stop_signal = "SIGINT"         # what interrupted the run, when one did
        self.stop_exit_code = 130
        self.stopped_between_ticks = False  # a stop signal: the run is at a whole tick
        self._ticking = False
        self._timed_from = sim.tick         # the tick `tick_seconds` counts from
        self._pace = _Pace()
        # Seconds of like work the caller expects after this run (a hunt's many short
        # runs of one program): counted with the run's own when deciding whether its
        # whole-tick kernel is worth compiling in another process (`whole_ticks_ready`).
        self.more_seconds = 0.0

    # ---- where the run is ----
    @property
    def program(self):
        return self.sim.program

    @property
    def tick(self) -> int:
        return self.sim.tick

    @property
    def done(self) -> bool:
        return self.steps is not None and self.sim.tick >= self.steps

    def due(self, tick: int) -> bool:
        """Whether observers see `tick`: on the `every` grid, or the last tick."""
        if self.every is None:
            return False
        return tick % self.every == 0 or tick == self.steps

    def snapshot(self):
        return self.sim.snapshot()

    # ---- the loop ----
    def start(self, observe: bool = True) -> None:
        """Tell the observers the run begins, then (with `observe`) show them the
        current tick; a stop signal waits until they have (nothing half-opened)."""
        with stopping.uncut():
            for observer in self.observers:
                observer.start(self.subject)
            if observe:
                self.observe()

    def step(self, ticks: int = 1, watch: Watch | None = None, whole: bool = False) -> None:
        """One tick, between stop checks (see the module's docstring); or `ticks` ticks
        no observer, callback or check needs to see apart (`_unobserved`), handed to
        the simulation at once (`Simulation.advance`: a backend may run them in one
        compiled call, with the same bits as stepping); or, with a `watch`, ticks
        whose observing the backend computes (`Watch`: checks, metrics), handed to it
        with the watch: the observers take its results (`watched`) and see only a
        tick where a check failed (or the one tick stepped, if the backend ran none
        whole)."""
        if self.done:
            return
        if self.stops:
            stopping.check()
        with stopping.uncut():
            for hook in self.between_ticks:
                hook(self)
            sim = self.sim
            compiling = sim.backend.compile_seconds
            t0, before = time.perf_counter(), sim.tick
            self._ticking = True
            covered = False     # the watch did the observers' watching of the call
            if watch is not None:
                with np.errstate(all="ignore"):
                    done = sim.backend.advance(sim, ticks, watch)
                if done <= 0:
                    sim.step()
                else:
                    covered = watch.observed and not watch.failed
            elif ticks > 1 or whole:
                sim.advance(ticks)
            else:
                sim.step()
            self._ticking = False
            seconds = (time.perf_counter() - t0
                       - (sim.backend.compile_seconds - compiling))
            self.tick_seconds += seconds
            self._pace.add((ticks > 1 or whole) if watch is None else done > 0, seconds,
                           sim.tick - before)
            t0 = time.perf_counter()
            if watch is not None and done > 0:
                for ext in watch.covers:
                    ext.watched(sim, watch)
                for observer in self.observers if watch.observed else ():
                    observer.watched(self.subject, watch)
                if covered and self.due(sim.tick):    # seen, as far as a stop goes
                    self.observed_tick = sim.tick
            if self.due(sim.tick) and not covered:
                self._observe()
            for hook in self.after_tick:
                hook(self)
            self.observe_seconds += time.perf_counter() - t0
        for check in self.checks:
            check(self)

    def run(self, ticks: int | None = None, progress=None,
            step: Callable[[], None] | None = None) -> None:
        """Step until `steps` (or `ticks` more ticks, or a `halt()`); `progress`, a
        `runtime.progress.Progress`, is updated after every tick and closed; `step`,
        the caller's own step around `self.step` (`Run.step`, which a script may
        wrap)."""
        end = None if ticks is None else self.sim.tick + ticks
        whole = step is None        # a caller's own step sees every tick
        step = self.step if step is None else step
        try:
            while not (self.done or self.halted or (end is not None and self.sim.tick >= end)):
                k, watch = self._unobserved(end) if whole else (0, None)
                if k > 0 or watch is not None:
                    self.step(max(k, 1), watch, whole=k > 0)
                else:
                    step()
                if progress is not None:
                    progress.update(self.sim.tick, self.sim.backend.compile_seconds)
        finally:
            if progress is not None:
                progress.close()

    def _unobserved(self, end: int | None) -> tuple[int, Watch | None]:
        """How many ticks can run whole from here before anything needs the state
        between them: up to the next tick the observers see, the run's end or `end`
        or the next tick a `Scheduled` callback needs (one, when the next is seen); 0
        (step one tick) while a check (unwatched) or another after-tick callback
        watches each tick, or the backend cannot run ticks whole without compiling
        first (`whole_ticks_ready`).
        When every observer offers a `Watch` the backend can compute (checks, metrics
        in its call), the ticks they see do not cut the chunk, and the watch goes with
        it; so does the watch of the extensions that watch ticks (`Watch.covers`).
        Capped so a chunk lasts about `CHUNK_SECONDS`: stop signals and progress wait
        for it."""
        sim = self.sim
        ready = getattr(sim.backend, "whole_ticks_ready", None)
        grids = [hook.every() if isinstance(hook, Scheduled) else -1
                 for hook in self.after_tick]
        if ready is None or -1 in grids:
            return 0, None      # a callback that sees every tick
        tick = sim.tick
        if not self._pace.whole_may_pay():
            return 0, None
        per_tick = self._pace.per_tick()
        cap = min(MAX_CHUNK, int(CHUNK_SECONDS / max(per_tick, 1e-6)))
        if cap <= 1:    # ticks this long gain nothing whole: not even compile it
            return 0, None
        left = per_tick * (self.steps - tick) if self.steps is not None else float("inf")
        left += self.more_seconds
        last = [t for t in (self.steps, end) if t is not None]
        watch = self._watch()
        if watch is not None and not ready(sim, left, watch):
            watch = None    # what it asks is not compiled: up to the next observed tick
        if watch is None and self.checks:
            return 0, None  # a check sees each tick the backend did not watch for it
        if self.every is not None and (watch is None or not watch.observed):
            last.append((tick // self.every + 1) * self.every)
        last += [(tick // k + 1) * k for k in grids if k]
        k = min(min(last, default=tick + MAX_CHUNK) - tick, cap)
        # Even one tick goes whole, observed or not: a small swarm's tick costs less
        # as one call of the kernel, its state packed and unpacked, than stepped in
        # Python (boids at 100 agents recorded every tick: ~3,700 ticks/s against
        # ~1,350); where it does not, the pace steps again.
        if watch is None and not ready(sim, left):
            return 0, None
        return max(k, 1), watch

    def _watch(self) -> Watch | None:
        """The union of the watches of the extensions that watch ticks (None when one
        must see the next tick itself) and of the observers' watches, when each
        observer offers one (else `observed` is false: the chunk ends at the next
        tick they see); None when there is nothing to watch. The ticks observers see
        are the run's `every` grid and its end."""
        if self.every is None:
            return None
        got, covers = [], []
        for ext in getattr(self.sim, "extensions", ()):
            offer = getattr(ext, "watch", None)
            if offer is None:
                continue
            w = offer(self.sim)
            if w is None:
                return None
            got.append(w)
            covers.append(ext)
        observed = bool(self.observers)
        seen = []
        for observer in self.observers:
            offer = getattr(observer, "watch", None)
            w = offer(self.subject) if offer is not None else None
            if w is None:
                observed = False
                break
            seen.append(w)
        if observed:
            got += seen
        if not got:
            return None
        watch = Watch.union(got)
        watch.every, watch.last = self.every, self.steps
        watch.covers, watch.observed = tuple(covers), observed
        return watch

    def halt(self) -> None:
        """End `run` after the current tick (an observer that has seen enough)."""
        self.halted = True

    def observe(self) -> None:
        """Show every observer the current tick now (timed as observing)."""
        t0 = time.perf_counter()
        self._observe()
        self.observe_seconds += time.perf_counter() - t0

    def _observe(self) -> None:
        self.observed_tick = self.sim.tick
        for observer in self.observers:
            observer.tick(self.subject)

    def switch(self, sim) -> None:
        """Go on with `sim` in place of the current simulation, between ticks: it must
        be at the same tick (its state carried over: `checkpoint.carry`). The studio's
        mid-run param change and the tiered start's backend switch both land here."""
        if sim.tick != self.sim.tick:
            raise ValueError(f"switch at tick {self.sim.tick} to a simulation at tick "
                             f"{sim.tick}")
        self.sim = sim
        self._pace = _Pace()    # another backend: its pace is its own

    # ---- how it ends ----
    def attempt(self, body: Callable[[], Any]) -> str:
        """Run `body`; the outcome of what ended it, its fault kept (never raised)."""
        from swarmdsl.internal import internal_error

        self.outcome, self.fault, self.error, self.fault_tick = "completed", None, None, None
        self.fault_in_tick = False
        self._ticking = False
        try:
            body()
        except KeyboardInterrupt as stop:
            self.outcome, self.error = "interrupted", stop
            if isinstance(stop, stopping.Stopped):  # raised between ticks (`uncut`)
                self.stop_signal, self.stop_exit_code = stop.name, stop.exit_code
                self.stopped_between_ticks = True
        except SwarmError as err:
            self._faulted(err, err.with_source(self.program.source))
            self.outcome = getattr(err, "outcome", "fault")
        except Exception as exc:    # a bug in swarmdsl: a fault the user can report
            self._faulted(exc, internal_error(exc, self.sim.tick))
            self.outcome = "fault"
        return self.outcome

    def _faulted(self, error: BaseException, fault: SwarmError) -> None:
        self.error, self.fault, self.fault_in_tick = error, fault, self._ticking
        self.fault_tick = self.sim.tick + 1 if self._ticking else self.sim.tick
        self._ticking = False

    def close(self, outcome: str) -> None:
        """Record the stop tick of a run stopped between ticks, then close every
        observer with `outcome`; stop signals only noted meanwhile."""
        t0 = time.perf_counter()
        try:
            with stopping.deferred():
                if self.stopped_between_ticks and self.observed_tick != self.sim.tick:
                    self._observe()
                for observer in self.observers:
                    observer.close(self.subject, outcome)
        finally:
            self.observe_seconds += time.perf_counter() - t0

    def drive(self, body: Callable[[], Any] | None = None, *,
              observe_start: bool = True) -> str:
        """Start, run `body` (default: `run()` to the end) and close, in every case;
        returns the outcome."""
        outcome = "fault"
        try:
            outcome = self.attempt(lambda: (self.start(observe_start),
                                            (body or self.run)()))
        finally:
            self.close(outcome)
        return outcome


class Callback:
    """A function of the simulation called at each tick the driver observes, as an
    observer (`Simulation.run`'s `on_tick`)."""

    def __init__(self, fn: Callable[[Any], None]):
        self.fn = fn

    def start(self, subject) -> None:
        """Nothing opens."""

    def tick(self, subject) -> None:
        self.fn(getattr(subject, "sim", subject))

    def close(self, subject, outcome: str) -> None:
        """Nothing to close."""


class _Pace:
    """Seconds a tick took, stepped one by one and run whole (`Simulation.advance`).

    Whole ticks pay for small swarms, whose ticks are mostly Python's fixed cost; a
    large swarm's per-tick kernels split their loops over threads, and the whole-tick
    kernel (one serial loop) is slower there: Vicsek at 10^6 agents took 3.6 s a tick
    whole against 0.6 s stepped. The numba backend refuses whole ticks above
    `compiled.WHOLE_TICKS_MAX` agents outright; below, where machines and programs
    differ, a run hands ticks whole only once a tick stepped one by one has been timed
    (which also sizes the chunk), and stops once whole ticks have proved slower."""

    def __init__(self):
        self.seconds = {False: 0.0, True: 0.0}
        self.ticks = {False: 0, True: 0}

    def add(self, whole: bool, seconds: float, ticks: int) -> None:
        self.seconds[whole] += seconds
        self.ticks[whole] += ticks

    def _rate(self, whole: bool) -> float | None:
        n = self.ticks[whole]
        return self.seconds[whole] / n if n else None

    def whole_may_pay(self) -> bool:
        one, whole = self._rate(False), self._rate(True)
        return one is not None and (whole is None or whole <= one)

    def per_tick(self) -> float:
        whole = self._rate(True)
        return whole if whole is not None else self._rate(False)
