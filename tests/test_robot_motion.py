"""Robot-relative motion (`compiler/lang_motion.py`): `stop()`, `forward(SPEED)`,
`turn_left(RATE)`, `turn_right(RATE)` on every backend, so a robot can stop and go
again, and turns as a Kilobot pivots about a leg."""

from __future__ import annotations

import numpy as np
import pytest

from swarmdsl.cli import main
from swarmdsl.compiler import compile_source
from swarmdsl.runtime.simulation import Simulation

STOP_AND_GO = """
world { size 400 x 400; steps 100 }
agent bot {
  robot generic
  count 2
  place (100, 100 + 100 * index)
  velocity if index == 0 then (0.6, 0.8) else (-1, 0)
  status go {
    when tick == 5 -> wait { stop() }
  }
  status wait {
    when tick == 15 -> again { forward(2) }
  }
  status again { }
}
"""


def test_a_stopped_robot_goes_again_along_the_heading_it_kept(backend):
    """Stopped at tick 5, still for ten ticks, then `forward(2)`: each robot moves on in
    the direction it had (the zero velocity rotated stays zero; `forward` does not)."""
    sim = Simulation(compile_source(STOP_AND_GO, "go.swarm"), seed=0, backend=backend)
    sim.run(6)
    stopped = sim.agents.cols["pos"].copy()
    sim.run(9)
    assert np.array_equal(sim.agents.cols["pos"], stopped)
    sim.run(10)
    moved = sim.agents.cols["pos"] - stopped
    direction = np.array([[0.6, 0.8], [-1.0, 0.0]])
    assert np.allclose(moved, direction * 2 * 10)


PIVOT = """
world {{ size 400 x 400; steps 100 }}
robot still {{ like kilobot; heading_noise 0; speed_noise 0 }}
agent bot {{
  robot still
  count 1
  place (200, 200)
  velocity (0.7, 0)
  status s {{ {action} }}
}}
"""


@pytest.mark.parametrize(("action", "sign"), [("turn_left(0.0227)", 1),
                                              ("turn_right(0.0227)", -1)])
def test_a_turn_pivots_about_a_leg_half_a_body_away(backend, action, sign):
    """Turning 13 degrees a second (0.0227 rad a tick, Kilombo's Kilobot) for 10 s:
    the heading turns 2.27 rad that way and the centre goes round a circle of half a
    body (16.5 mm): it stays within a body of where it started."""
    sim = Simulation(compile_source(PIVOT.format(action=action), "p.swarm"), seed=0,
                     backend=backend)
    start = sim.agents.cols["pos"][0].copy()
    track = []
    for _ in range(100):
        sim.run(1)
        track.append(sim.agents.cols["pos"][0].copy())
    assert sim.agents.cols["heading"][0] == pytest.approx(sign * 100 * 0.0227)
    track = np.array(track)
    assert np.hypot(*(track - start).T).max() <= 33.0 + 1e-9
    steps = np.hypot(*np.diff(track, axis=0).T)
    assert steps == pytest.approx(16.5 * 0.0227)        # the centre's pace on its circle


def test_motion_actions_are_checked(tmp_path, capsys):
    path = tmp_path / "bad.swarm"
    path.write_text("agent a { count 1; status s { forward(); turn_left((1, 2)) } }\n")
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:1:31: error: `forward` takes 1 argument: `forward(SPEED)`" in err
    assert f"{path}:1:52: error: the argument of `turn_left` must be a number, got a vector" \
        in err
