"""An exported program as kilolib runs it: per-robot random streams, the program's
clock, the motors' spin-ups and the messages handed to the transmit interrupt, run on
the host against a logging stand-in of kilolib's API (`-DKILOLIB_API`, the robot's
own build of the C)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from swarmdsl.cli import main

_CC = shutil.which("gcc") or shutil.which("cc")
pytestmark = pytest.mark.skipif(not _CC, reason="no C compiler for the host")

# kilolib's API, logging what the program asks of it. `kilo_start` calls setup() at
# kilo_ticks 0 (a robot's power-on) and loop() from kilo_ticks START (the Run
# command), once a kilo_tick, until the program has run TICKS ticks; after every
# program tick EACH runs. rand_hard() is a robot's entropy: HARD seeds it.
HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#define main kb_program_main
#include "PROGRAM.c"
#undef main
volatile uint32_t kilo_ticks = 0;
volatile uint16_t kilo_tx_period = 15;
uint16_t kilo_uid = UID;
uint8_t kilo_turn_left = 70, kilo_turn_right = 71;
uint8_t kilo_straight_left = 72, kilo_straight_right = 73;
message_rx_t kilo_message_rx;
message_tx_t kilo_message_tx;
message_tx_success_t kilo_message_tx_success;
uint16_t message_crc(const message_t *m)
{
    uint16_t c = 0xFFFF;
    for (int i = 0; i < 9; i++) c = (uint16_t)((c << 5) ^ (c >> 11) ^ m->data[i]);
    return (uint16_t)(c ^ m->type);
}
uint8_t estimate_distance(const distance_measurement_t *d) { return d->high_gain; }
void delay(uint16_t ms) { (void)ms; }
static uint32_t hard = HARD;   /* or the run's first argument */
uint8_t rand_hard(void) { hard = hard * 1103515245u + 12345u; return (hard >> 16) & 0xFF; }
uint8_t rand_soft(void) { return 0; }
void rand_seed(uint8_t s) { (void)s; }
void set_motors(uint8_t l, uint8_t r) { printf("motors %u %u\n", l, r); }
void spinup_motors(void) { printf("spinup\n"); }
void set_color(uint8_t c)   /* the transmit interrupt, arriving in the middle of loop() */
{
    (void)c;
    message_t *p = kilo_message_tx ? kilo_message_tx() : 0;
    if (p) printf("irq %d %d\n", (int)kb_unpack(&p->data[0]), (int)kb_unpack(&p->data[2]));
}
void kilo_init(void) {}
void kilo_start(void (*setup)(void), void (*loop)(void)) {
    setup();
    kilo_ticks = START;
    uint32_t seen = 0, calls = 0;
    while (mydata->tick < TICKS && calls++ < 100000) {
        loop();
        if (mydata->tick != seen) { seen = mydata->tick; EACH; }
        kilo_ticks++;
    }
    printf("ticks %u at %u\n", (unsigned)mydata->tick, (unsigned)kilo_ticks);
}
int main(int argc, char **argv)
{
    if (argc > 1) hard = (uint32_t)strtoul(argv[1], 0, 10);
    kb_program_main();
    return 0;
}
"""


def _run(tmp_path: Path, name: str, program: str, ticks: int, *, uid: int = 0,
         hard: int = 1, start: int = 0, each: str = "(void)0") -> list[str]:
    """Export `program`, build it with the harness and run it: its log's lines."""
    folder = tmp_path / name
    if not (folder / "c" / f"{name}.c").exists():
        folder.mkdir(exist_ok=True)
        (folder / f"{name}.swarm").write_text(program)
        assert main(["export", "kilobot", str(folder / f"{name}.swarm"), "-o",
                     str(folder / "c")]) == 0
    (folder / "c" / "harness.c").write_text(HARNESS.replace("PROGRAM", name))
    exe = folder / "c" / f"run_{uid}_{hard}_{start}"
    subprocess.run([_CC, "-std=gnu99", "-DKILOLIB_API", f"-DTICKS={ticks}", f"-DUID={uid}",
                    f"-DHARD={hard}u", f"-DSTART={start}", f"-DEACH={each}", "-o", str(exe),
                    str(folder / "c" / "harness.c"), "-lm"], check=True, capture_output=True)
    return subprocess.run([str(exe)], capture_output=True, text=True,
                          check=True).stdout.splitlines()


DRAWS = """
world { size 400 x 400; steps 100 }
agent bot {
  robot kilobot
  count 8
  place (50 + 40 * index, 200)
  var r = 0
  status draw { r = random() }
}
"""
_PRINT_R = 'printf("r %.9g\\n", (double)mydata->v0_r)'


def _draws(tmp_path, uid: int, hard: int, ticks: int = 40) -> list[float]:
    lines = _run(tmp_path, "draws", DRAWS, ticks, uid=uid, hard=hard, each=_PRINT_R)
    return [float(x.split()[1]) for x in lines if x.startswith("r ")]


def test_every_robot_draws_its_own_random_numbers(tmp_path):
    """Eight robots, each with its own id and hardware entropy, draw eight different
    streams (kilolib's rand_soft unseeded gave every robot the same one); the same
    entropy on two robots still gives two streams (the id is mixed in), and a robot
    seeded alike draws alike (the stream is a function of entropy and id only)."""
    streams = [_draws(tmp_path, uid, hard=1000 + 7 * uid) for uid in range(8)]
    assert all(len(s) == 40 for s in streams)
    assert len({s[0] for s in streams}) == 8
    assert len({tuple(s) for s in streams}) == 8
    same_entropy = [_draws(tmp_path, uid, hard=5) for uid in (0, 1)]
    assert same_entropy[0] != same_entropy[1]
    assert _draws(tmp_path, 3, hard=1021) == streams[3]


def test_a_robots_draws_are_uniform_with_fine_steps(tmp_path):
    """`random()` on the robot: 2,000 draws pass a Kolmogorov-Smirnov test against
    the uniform distribution (p > 0.001), and take far more than kilolib's 256 values."""
    draws = np.array(_draws(tmp_path, 5, hard=99, ticks=2000))
    assert draws.min() >= 0 and draws.max() < 1
    assert stats.kstest(draws, "uniform").pvalue > 0.001
    assert len(set(draws.tolist())) > 1900


CLOCK = """
world { size 100 x 100; steps 50 }
agent bot { robot kilobot; count 1; place (50, 50); var n = 0; status s { n += 1 } }
"""


@pytest.mark.parametrize("start", [0, 1860])
def test_program_time_starts_with_the_program_and_never_bursts(tmp_path, start):
    """setup() at power-on, Run pressed 60 s later (kilo_ticks 1860): the program's
    ticks follow the clock from Run on, one every 3 kilo_ticks (0.1 s), not 620 at
    once to catch up."""
    each = 'printf("t %u %u\\n", (unsigned)mydata->tick, (unsigned)kilo_ticks)'
    lines = _run(tmp_path, "clock", CLOCK, 20, start=start, each=each)
    at = [int(x.split()[2]) for x in lines if x.startswith("t ")]
    assert len(at) == 20
    assert at[0] == start + 3
    assert np.diff(at).tolist() == [3] * 19


WANDER = """
world {{ size 400 x 400; steps 200 }}
agent bot {{
  robot kilobot
  count 1
  place (200, 200)
  velocity (1, 0)
  status go {{ velocity = rotate(velocity, {turn}) }}
}}
"""


def _motor_log(lines: list[str]) -> list[tuple]:
    """The motor commands in order, each with whether a spin-up came right before."""
    out, spun = [], False
    for line in lines:
        if line == "spinup":
            spun = True
        elif line.startswith("motors "):
            left, right = (int(v) for v in line.split()[1:])
            out.append((left, right, spun))
            spun = False
    return out


def test_motors_spin_up_whenever_a_motor_starts_from_off(tmp_path):
    """kilolib's guidance: a motor starting from off is spun up first. Going straight,
    turning left, straight, right, left, right, straight (a turn's sign each tick):
    the start, every turn becoming straight and every turn to the other side get a
    spin-up; straight becoming a turn (a motor stopping) gets none."""
    turns = "if tick % 7 == 1 or tick % 7 == 4 then 0.1 else if tick % 7 == 3 or " \
            "tick % 7 == 5 then -0.1 else 0"
    lines = _run(tmp_path, "wander", WANDER.format(turn=turns), 14)
    log = _motor_log(lines)
    assert log[0] == (0, 0, False)                      # setup: at rest
    previous = (0, 0)
    kinds = set()
    for left, right, spun in log[1:]:
        starts = (left > 0 and previous[0] == 0) or (right > 0 and previous[1] == 0)
        assert spun == starts, (previous, (left, right))
        kinds.add((previous, (left, right)))
        previous = (left, right)
    straight, turn_left, turn_right = (72, 73), (70, 0), (0, 71)
    assert {((0, 0), straight), (turn_left, straight), (turn_right, straight),
            (turn_left, turn_right), (turn_right, turn_left), (straight, turn_left),
            (straight, turn_right)} <= kinds


TALK = """
world { size 100 x 100; steps 100 }
agent bot {
  robot kilobot
  count 1
  place (50, 50)
  message a num b num
  status s { broadcast(a, tick * 3); led(red); broadcast(b, -tick * 3) }
}
"""

# After each program tick: the message the transmit interrupt is handed, checked whole
# (its values from one tick, its CRC its own), and checked again after the next
# loop() ran: the buffer the interrupt holds is never written while loop() packs.
_HANDED = r"""do {
    static message_t held, *p = 0;
    if (p && memcmp(p, &held, sizeof held)) printf("torn\n");
    p = kilo_message_tx();
    if (!p) { printf("none\n"); break; }
    held = *p;
    printf("msg %d %d %d\n", (int)kb_unpack(&p->data[0]), (int)kb_unpack(&p->data[2]),
           p->crc == message_crc(p));
} while (0)"""


def test_the_transmit_interrupt_is_handed_a_complete_message(tmp_path):
    """The program sends `a` and `b = -a`, set one after the other; the transmit
    interrupt, arriving between the two (here: from `led`), is handed the last
    complete message (from the tick before, with its CRC), never `a` of this tick with
    `b` of the last; after each tick it gets that tick's message."""
    lines = _run(tmp_path, "talk", TALK, 30, each=_HANDED.replace("\n", " "))
    msgs = [tuple(int(v) for v in x.split()[1:]) for x in lines if x.startswith("msg ")]
    assert "torn" not in lines and "none" not in lines
    assert len(msgs) == 30
    for a, b, crc in msgs:
        assert a == -b and crc == 1
    assert [a for a, _b, _c in msgs] == [3 * t for t in range(30)]
    irqs = [tuple(int(v) for v in x.split()[1:]) for x in lines if x.startswith("irq ")]
    assert len(irqs) >= 29 and all(a == -b for a, b in irqs)


STOP_AND_GO = """
world { size 400 x 400; steps 100 }
agent bot {
  robot kilobot
  count 1
  place (200, 200)
  status go {
    forward(0.7)
    when tick == 3 -> halt { stop() }
  }
  status halt { when tick == 6 -> turn { turn_left(0.0227) } }
  status turn { turn_left(0.0227); when tick == 8 -> back { turn_right(0.0227) } }
  status back { turn_right(0.0227); when tick == 10 -> go { forward(0.7) } }
}
"""


def test_stop_and_go_commands_the_motors_as_a_kilobot_program_does(tmp_path):
    """`forward`, `stop`, `turn_left`, `turn_right` become kilolib's motor commands
    (the calibrated duty cycles; a start from rest and every motor starting spun up):
    a stopped robot starts again, as a BEECLUST-like program needs."""
    log = _motor_log(_run(tmp_path, "stopgo", STOP_AND_GO, 12))
    straight, left, right, rest = (72, 73), (70, 0), (0, 71), (0, 0)
    assert [((a, b), spun) for a, b, spun in log] == [
        (rest, False), (straight, True), (rest, False), (left, True), (right, True),
        (straight, True)]


@pytest.mark.skipif(not shutil.which("avr-gcc"), reason="avr-gcc is not installed")
def test_motion_commands_compile_warning_free_for_the_avr(tmp_path):
    from tests.test_export_kilobot import _avr_compile

    folder = tmp_path / "stopgo"
    folder.mkdir()
    (folder / "stopgo.swarm").write_text(STOP_AND_GO)
    assert main(["export", "kilobot", str(folder / "stopgo.swarm"), "-o", str(folder / "c")]) == 0
    _avr_compile(folder / "c" / "stopgo.c", folder / "stopgo.elf")


def test_the_kilombo_build_with_its_arena_compiles_warning_free(tmp_path):
    """The Kilombo build (the arena's obstacles callback included) under -Wall -Werror."""
    from tests import kilombo_build

    if kilombo_build.missing():
        pytest.skip(f"no Kilombo: {kilombo_build.missing()}")
    folder = tmp_path / "stopgo"
    folder.mkdir()
    (folder / "stopgo.swarm").write_text(STOP_AND_GO)
    assert main(["export", "kilobot", str(folder / "stopgo.swarm"), "-o", str(folder / "c")]) == 0
    assert "kb_arena" in (folder / "c" / "stopgo.c").read_text()
    prefix = kilombo_build.prefix()
    subprocess.run([_CC, "-std=gnu99", "-Wall", "-Werror", "-fcommon", f"-I{prefix}/include",
                    "stopgo.c", f"-L{prefix}/lib", "-lheadless", "-ljansson", "-lm", "-o",
                    "stopgo"], cwd=folder / "c", check=True, capture_output=True)


RANDOM_COMMANDS = """
world { size 2000 x 2000; steps 100 }
agent bot {
  robot kilobot
  count 1
  place (1000, 1000)
  var pick = 0
  status go {
    pick = floor(uniform(0, 4))
    when pick == 0 -> go { stop() }
    when pick == 1 -> go { forward(0.7) }
    when pick == 2 -> go { turn_left(0.0227) }
    turn_right(0.0227)
  }
}
"""


def test_any_sequence_of_motions_spins_up_exactly_when_a_motor_starts(tmp_path):
    """A robot drawing one of stop, forward, left and right each tick (its entropy
    drawn by hypothesis): in every sequence, spin-up comes before a motor command
    exactly when a motor goes from off to on."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    _run(tmp_path, "commands", RANDOM_COMMANDS, 60, hard=1)
    exe = tmp_path / "commands" / "c" / "run_0_1_0"

    @settings(max_examples=15, deadline=None)
    @given(entropy=st.integers(0, 2**32 - 1))
    def spins(entropy):
        lines = subprocess.run([str(exe), str(entropy)], capture_output=True, text=True,
                               check=True).stdout.splitlines()
        log = _motor_log(lines)
        assert len(log) > 10
        previous = (0, 0)
        for left, right, spun in log:
            assert spun == ((left > 0 and previous[0] == 0) or
                            (right > 0 and previous[1] == 0)), (previous, (left, right))
            previous = (left, right)
    spins()
