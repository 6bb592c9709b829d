"""Where exported robots start: the experimenter's set-up of `swarmdsl run --seed S`
(positions, initial velocities) in Kilombo's frame.

Kilombo's y axis points down the screen and a robot's `direction` is its angle from +y
toward +x, so a left turn (kilolib's `kilo_turn_left`) is counter-clockwise as drawn.
The language's y axis points up with angles counter-clockwise from +x; mirroring y keeps
left turns left: (x, y) -> (x, -y), and a heading `a` becomes `a + pi/2`.
"""

from __future__ import annotations

import math


def start(program, seed: int = 0) -> list[tuple[tuple[float, float], float, bool, int]]:
    """Per agent, in id order: Kilombo position, Kilombo direction, whether it moves,
    its kind's index."""
    from swarmdsl.runtime.simulation import Simulation

    cols = Simulation(program, seed=seed, backend="numpy").agents.cols
    out = []
    for i in sorted(range(len(cols["id"])), key=lambda r: cols["id"][r]):
        (x, y), (vx, vy) = cols["pos"][i], cols["vel"][i]
        moving = bool(vx != 0 or vy != 0)
        angle = math.atan2(vy, vx) if moving else float(cols["heading"][i])
        out.append(((float(x), -float(y)), angle + math.pi / 2, moving,
                    int(cols["kind"][i])))
    return out


def beliefs_at_start(program, seed: int = 0) -> list[tuple[tuple[float, float] | None, float]]:
    """Per agent, in id order: its belief as it is put down (None when its kind has no
    `believe` option: not located) and its heading, in the language's frame, which is
    the believed frame's orientation (odometry adds world displacements to a belief)."""
    from swarmdsl.runtime.simulation import Simulation

    cols = Simulation(program, seed=seed, backend="numpy").agents.cols
    located = cols.get("located")
    out = []
    for i in sorted(range(len(cols["id"])), key=lambda r: cols["id"][r]):
        belief = None
        if located is not None and bool(located[i]):
            belief = (float(cols["believed"][i][0]), float(cols["believed"][i][1]))
        out.append((belief, float(cols["heading"][i])))
    return out
