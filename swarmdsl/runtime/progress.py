"""A run's progress: tick count, the recent tick rate and the time left at that rate.

The rate of a swarm run is not constant: flocks tighten, so each agent has more
neighbours and ticks get slower (boids at 5,000 agents: the bar said 1:21 left at 10 %
and the run took 6.5 more minutes). The average since the start lags such a fall by the
whole run, so the rate here is that of the recent past only: the ticks of the last
eighth of the run's time (at least 1 s, at most 30 s). A window forgets a slow first
tick (numba loading or compiling kernels) completely once it has passed, where an
average weighted towards recent ticks still carried it; kernel compilation the backend
reports is not ticking and is left out of the time.
"""

from __future__ import annotations

import math
import sys
import time
from collections import deque
from collections.abc import Callable

WINDOW_SHARE, WINDOW_MIN, WINDOW_MAX = 1 / 8, 1.0, 30.0
REDRAW = 0.1        # seconds between two updates of the bar
SAMPLES = 128       # (time, tick) points kept per window: the window's start to 1/128


class RecentRate:
    """Ticks per second over the last window of ticking time (`clock`: seconds,
    injectable for tests). `update` is O(1) per tick; the rate is worked out on demand."""

    def __init__(self, tick: int = 0, clock: Callable[[], float] = time.perf_counter):
        self.clock = clock
        self.start = clock()
        self.paused = 0.0           # seconds not spent ticking (compilation) so far
        self.latest = (0.0, tick)   # (ticking seconds, tick) at the last update
        self.previous: tuple[float, int] | None = None
        self.samples: deque = deque([self.latest], maxlen=4 * SAMPLES)

    def update(self, tick: int, paused: float = 0.0) -> None:
        """`tick` reached; `paused`: the total seconds so far that were not ticking."""
        self.paused = max(paused, self.paused)
        if tick <= self.latest[1]:
            return
        now = max(self.clock() - self.start - self.paused, self.latest[0])
        self.previous, self.latest = self.latest, (now, tick)
        if now - self.samples[-1][0] >= window(now) / SAMPLES:
            self.samples.append(self.latest)

    @property
    def ticks_per_second(self) -> float | None:
        """The rate over the window: from its oldest point to the latest tick (over the
        last tick alone when that tick is longer than the window); None before a tick."""
        if self.previous is None:
            return None
        now, tick = self.latest
        since = now - window(now)
        first = next((s for s in self.samples if s[0] >= since and s[1] < tick),
                     self.previous)
        if first[0] > self.previous[0]:     # a thinned-out point later than the last tick
            first = self.previous
        seconds = now - first[0]
        return math.inf if seconds <= 0 else (tick - first[1]) / seconds

    def seconds_left(self, ticks_left: int) -> float | None:
        rate = self.ticks_per_second
        return None if rate is None else (0.0 if rate == math.inf else ticks_left / rate)


def window(elapsed: float) -> float:
    """The recent past, in seconds of ticking, for a run `elapsed` seconds old."""
    return min(max(elapsed * WINDOW_SHARE, WINDOW_MIN), WINDOW_MAX)


def clock_text(seconds: float) -> str:
    """12 s, 6:30, 1:02:03."""
    seconds = round(seconds)
    if seconds < 60:
        return f"{seconds} s"
    minutes, secs = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes}:{secs:02d}"
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}"


def rate_number(per_second: float) -> str:
    """1,234 or 0.78: whole above 10, two significant digits below (it said `1 ticks/s`
    for a run at 1.4)."""
    return f"{per_second:,.0f}" if per_second >= 10 else f"{per_second:.2g}"


def rate_text(rate: RecentRate, tick: int, total: int) -> str:
    """`120 ticks/s, 6:30 left at this rate` (a rate that falls further makes it longer),
    or "" before the first tick."""
    per_second = rate.ticks_per_second
    if per_second is None:
        return ""
    speed = rate_number(per_second)
    if tick >= total:
        return f"{speed} ticks/s"
    return f"{speed} ticks/s, {clock_text(rate.seconds_left(total - tick))} left at this rate"


class Progress:
    """The tick count, recent rate and time left: a rich bar on a terminal, a plain line
    on stderr every 10 % otherwise (runs of 100 ticks or more)."""

    def __init__(self, total: int, first: int = 0,
                 clock: Callable[[], float] = time.perf_counter, stream=None):
        self.enabled = total > 0
        self.total = max(total, 1)
        self.first = first      # a resumed run starts at its checkpoint's tick
        self.stream = sys.stderr if stream is None else stream
        self.rate = RecentRate(first, clock)
        self.bar = None
        self.shown_at = -math.inf
        self.next_line = 0.1
        while self.next_line <= first / self.total:
            self.next_line += 0.1
        if self.enabled and self.stream.isatty():
            from rich.console import Console
            from rich.progress import BarColumn, TaskProgressColumn, TextColumn
            from rich.progress import Progress as Bar

            self.bar = Bar(TextColumn("tick {task.completed:,.0f}/{task.total:,.0f}"),
                           BarColumn(), TaskProgressColumn(),
                           TextColumn("{task.fields[rate]}"),
                           console=Console(file=self.stream), transient=True)
            self.task = self.bar.add_task("ticks", total=self.total, completed=first,
                                          rate="")
            self.bar.start()

    def update(self, tick: int, paused: float = 0.0) -> None:
        """`tick` reached; `paused`: seconds so far spent not ticking (compiling)."""
        self.rate.update(tick, paused)
        if self.bar is not None:
            now = self.rate.clock()
            if now - self.shown_at >= REDRAW or tick >= self.total:   # rich draws 10/s
                self.shown_at = now
                self.bar.update(self.task, completed=tick,
                                rate=rate_text(self.rate, tick, self.total))
            return
        frac = tick / self.total
        if frac >= self.next_line and self.total >= 100 and self.enabled:
            print(f"tick {tick:,}/{self.total:,} ({frac:.0%}), "
                  f"{rate_text(self.rate, tick, self.total)}", file=self.stream)
            while self.next_line <= frac:
                self.next_line += 0.1

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
