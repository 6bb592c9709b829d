"""The progress estimate follows the recent rate (an injected clock: no timing), and
the end summary says where the run's time went."""

from __future__ import annotations

import io
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.runtime.progress import Progress, RecentRate


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _tick(rate: RecentRate, clock: Clock, tick: int, seconds: float, paused=0.0) -> int:
    clock.now += seconds
    rate.update(tick + 1, paused)
    return tick + 1


def test_the_rate_follows_a_fall():
    """1,000 ticks of 1 ms, then ticks of 10 ms: after 300 slow ones the rate is the slow
    one, where the average since the start (1,300 ticks in 4 s) says 325 ticks/s and the
    time left three times too short."""
    clock = Clock()
    rate, tick = RecentRate(0, clock), 0
    for _ in range(1000):
        tick = _tick(rate, clock, tick, 0.001)
    assert rate.ticks_per_second == pytest.approx(1000)
    for _ in range(300):
        tick = _tick(rate, clock, tick, 0.010)
    assert rate.ticks_per_second == pytest.approx(100, rel=0.02)
    assert rate.seconds_left(700) == pytest.approx(7.0, rel=0.02)


def test_the_rate_follows_ticks_that_keep_slowing():
    """Each tick a little longer than the one before (a flock tightening): the estimate
    stays within 10 % of the current tick's rate all along."""
    clock = Clock()
    rate, tick = RecentRate(0, clock), 0
    for i in range(3000):
        tick = _tick(rate, clock, tick, 0.01 * (1 + i / 300))
        if i > 200:         # past the first second, which the rate takes whole
            assert rate.ticks_per_second == pytest.approx(1 / (0.01 * (1 + i / 300)),
                                                          rel=0.10)


def test_a_slow_first_tick_and_compilation_are_forgotten():
    """A first tick that loaded numba (10 s) poisoned an average weighted towards recent
    ticks for a long time; a window drops it once it has passed. Compilation the
    backend reports (`paused`) is not counted as ticking at all."""
    clock = Clock()
    rate = RecentRate(0, clock)
    tick = _tick(rate, clock, 0, 10.0)
    for _ in range(2000):
        tick = _tick(rate, clock, tick, 0.001)
    assert rate.ticks_per_second == pytest.approx(1000, rel=0.01)
    clock2 = Clock()
    paused = RecentRate(0, clock2)
    tick = _tick(paused, clock2, 0, 30.001, paused=30.0)
    for _ in range(10):
        tick = _tick(paused, clock2, tick, 0.001, paused=30.0)
    assert paused.ticks_per_second == pytest.approx(1000)


def test_ticks_longer_than_the_window_give_the_last_ticks_rate():
    clock = Clock()
    rate, tick = RecentRate(0, clock), 0
    assert rate.ticks_per_second is None and rate.seconds_left(5) is None
    for seconds in (2.0, 5.0, 5.0):
        tick = _tick(rate, clock, tick, seconds)
    assert rate.ticks_per_second == pytest.approx(0.2)


@given(st.lists(st.floats(1e-5, 5.0), min_size=2, max_size=300))
@settings(max_examples=100, deadline=None)
def test_the_rate_is_one_the_recent_ticks_had(durations):
    """Whatever the ticks took, the rate lies between the slowest and the fastest tick's
    rate since the window began (it is a ratio of their sums)."""
    clock = Clock()
    rate, tick = RecentRate(0, clock), 0
    for seconds in durations:
        tick = _tick(rate, clock, tick, seconds)
    got = rate.ticks_per_second
    assert 1 / max(durations) * 0.999 <= got <= 1 / min(durations) * 1.001


class Lines(io.StringIO):
    def isatty(self) -> bool:
        return False


def test_progress_lines_give_the_tick_the_recent_rate_and_the_time_left():
    clock, out = Clock(), Lines()
    progress = Progress(200, 0, clock, out)
    for tick in range(1, 201):
        clock.now += 0.01 if tick <= 100 else 0.1
        progress.update(tick)
    lines = out.getvalue().splitlines()
    assert len(lines) == 10
    assert lines[0] == "tick 20/200 (10%), 100 ticks/s, 2 s left at this rate"
    assert lines[-2] == "tick 180/200 (90%), 10 ticks/s, 2 s left at this rate"
    assert lines[-1] == "tick 200/200 (100%), 10 ticks/s"
    progress.close()


def test_the_summary_splits_the_time_into_simulating_and_recording(backend, tmp_path, capsys):
    """It said `in 2.44 s (650 ticks/s)`: the time included recording, the rate did not."""
    from swarmdsl.cli import main

    program = tmp_path / "p.swarm"
    program.write_text("world { size 50 x 50 }\nagent a { count 200; var s = 0\n"
                       "  status m { s = count(neighbors(5)); velocity = (1, 0) } }\n")
    assert main(["run", str(program), "--headless", "--steps", "40",
                 "--out", str(tmp_path / "out")]) == 0
    line = capsys.readouterr().out
    got = re.search(r"ran 40 ticks of 200 agents in ([\d.]+) s: "
                    r"(?:[\d.]+ s compiling kernels, )?([\d.]+) s simulating "
                    r"\(([\d,.]+) ticks/s\), ([\d.]+) s recording", line)
    assert got, line
    total, simulating, rate, recording = (float(g.replace(",", "")) for g in got.groups())
    # the shown seconds are rounded to 0.01 s; the rate is of the unrounded ones
    assert 40 / (simulating + 0.005) - 1 <= rate <= 40 / max(simulating - 0.005, 1e-9) + 1
    assert simulating + recording <= total + 0.01
    assert recording > 0


class Terminal(Lines):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_a_bar_with_the_tick_count_and_rate():
    clock, out = Clock(), Terminal()
    progress = Progress(200, 0, clock, out)
    for tick in range(1, 201):
        clock.now += 0.05
        progress.update(tick)
    progress.close()
    assert "tick 200/200" in out.getvalue() and "20 ticks/s" in out.getvalue()


def test_slow_rates_keep_two_digits():
    from swarmdsl.runtime.progress import rate_number

    assert [rate_number(x) for x in (1.4, 0.078, 9.96, 12.4, 1234.5)] == [
        "1.4", "0.078", "10", "12", "1,234"]
