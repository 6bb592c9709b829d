"""Sensing models: range, field of view, noise, dropout and resolution per robot profile."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.compiler import compile_source
from swarmdsl.ops import portable
from swarmdsl.runtime.sensing import in_view
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"

CONE = """param half = 1
param n = 30
robot eye { fov cone half }
world { size 200 x 200; grid 10 }
agent a {
  robot eye
  count n
  place uniform
  velocity random_direction() * 2
  sense 80
  var seen = 0
  var widest = 1
  status s {
    let near = neighbors()
    seen = count(near)
    widest = min(near : dot(normalize(other.pos - pos), unit(heading)) else 1)
    velocity = (0, 0)
  }
}
"""


def _expected_counts(pos, heading, half, reach):
    delta = pos[None, :, :] - pos[:, None, :]                        # (N, N, 2)
    dist = portable.hypot_array(delta[..., 0], delta[..., 1])    # the language's own
    off = np.abs((portable.atan2_array(delta[..., 1], delta[..., 0]) - heading[:, None] + np.pi)
                 % (2 * np.pi) - np.pi)
    seen = (dist <= reach) & (off <= half) & ~np.eye(len(pos), dtype=bool)
    return seen.sum(axis=1)


@settings(max_examples=15)
@given(half=st.floats(0.1, math.pi), seed=st.integers(0, 10_000))
def test_a_cone_limited_agent_never_senses_outside_its_cone(backend, half, seed):
    sim = Simulation(compile_source(CONE, "cone.swarm", {"half": repr(half)}), seed)
    sim.step()                      # tick 0 sets headings from the initial velocities
    pos, heading = sim.agents.cols["pos"].copy(), sim.agents.cols["heading"].copy()
    sim.step()                      # tick 1 senses from exactly that state
    assert (sim.agents.cols["widest"] >= math.cos(half) - 1e-9).all()
    want = _expected_counts(pos, heading, half, 80.0)
    np.testing.assert_array_equal(sim.agents.cols["seen"], want)


@settings(max_examples=60)
@given(x=st.floats(-50, 50), y=st.floats(-50, 50), h=st.floats(-4, 4),
       wedge=st.floats(0, math.pi / 2), reach=st.floats(0, 40))
def test_front_view_is_half_circle_plus_side_wedges(x, y, h, wedge, reach):
    off = np.array([[x, y]])
    got = bool(in_view(off, np.array([h]), 2, wedge, reach, 45.0)[0])
    d = portable.hypot(x, y)                # the language's functions, not the C library's
    a = abs((portable.atan2(y, x) - h + math.pi) % (2 * math.pi) - math.pi)
    front = a <= math.pi / 2
    side = a <= math.pi / 2 + wedge and d <= reach
    assert got == (d <= 45 and (front or side or d == 0))


NOISY = """robot eye {{ {opts} }}
world {{ size 400 x 400; grid 10 }}
field level {{ twin 5 }}
agent a {{
  robot eye
  count 400
  place (5 + 20 * (index % 20), 5 + 20 * floor(index / 20))
  sense 12
  var reading = 0
  var gap = 0
  var heard = 0
  status s {{
    reading = sample(level)
    let near = neighbors()
    heard = count(near)
    gap = min(near : dist else -1)
  }}
}}
"""


def _run_noisy(run_src, opts, seed=3):
    return run_src(NOISY.format(opts=opts), steps=1, seed=seed).agents.cols


def test_field_noise_has_the_declared_spread_at_a_fixed_seed(run_src):
    cols = _run_noisy(run_src, "field_noise 2")
    assert cols["reading"].mean() == pytest.approx(5, abs=0.25)
    assert cols["reading"].std() == pytest.approx(2, rel=0.1)
    again = _run_noisy(run_src, "field_noise 2")
    np.testing.assert_array_equal(cols["reading"], again["reading"])


def test_neighbour_noise_spreads_the_sensed_distance(run_src):
    quiet = _run_noisy(run_src, "range 100")      # agents 20 apart, sense 12: nobody
    assert (quiet["heard"] == 0).all()
    cols = _run_noisy(run_src, "neighbor_noise 3", seed=5)
    assert (cols["heard"] == 0).all()            # noise never widens what is in range
    src = NOISY.format(opts="neighbor_noise 3").replace("sense 12", "sense 21")
    cols = run_src(src, steps=1, seed=5).agents.cols
    gaps = cols["gap"][cols["heard"] > 0]
    assert gaps.size > 300
    assert gaps.mean() < 20                       # the nearest of 2-4 noisy readings
    assert 0.5 < gaps.std() < 4


def test_dropout_loses_the_declared_share(run_src):
    src = NOISY.format(opts="neighbor_dropout 0.3; field_dropout 0.25").replace(
        "sense 12", "sense 21")
    cols = run_src(src, steps=1, seed=2).agents.cols
    full = run_src(NOISY.format(opts="").replace("sense 12", "sense 21"),
                   steps=1).agents.cols
    assert cols["heard"].sum() / full["heard"].sum() == pytest.approx(0.7, abs=0.05)
    assert (cols["reading"] == 0).mean() == pytest.approx(0.25, abs=0.05)
    assert set(np.unique(cols["reading"])) == {0.0, 5.0}


def test_resolution_rounds_readings(run_src):
    cols = _run_noisy(run_src, "field_noise 1; field_resolution 0.5")
    r = cols["reading"]
    np.testing.assert_allclose(r * 2, np.round(r * 2), atol=1e-12)
    assert np.unique(r).size > 5


def test_field_points_out_of_range_read_zero(run_src):
    src = """robot eye { range 30 }
world { size 200 x 200; grid 10 }
field level { twin 1 + pos.x }
agent a {
  robot eye
  count 1
  place (100, 100)
  var near = 0
  var far = 0
  status s { near = sample(level, pos + (20, 0)); far = sample(level, pos + (40, 0)) }
}
"""
    cols = run_src(src, steps=1).agents.cols
    assert cols["near"][0] == pytest.approx(121)
    assert cols["far"][0] == 0


@pytest.mark.parametrize("opts, message", [
    ("fov circle 1", "1:17: a field of view is `fov all`, `fov cone HALF_ANGLE` or "
     "`fov front WEDGE_ANGLE [WEDGE_REACH]` (angles in radians)"),
    ("fov cone 4", "1:22: a cone's half angle is in radians, above 0 and at most pi, got 4"),
    ("fov front 2", "1:23: a side wedge is at most pi/2 wide (it ends straight behind), "
     "got 2"),
    ("neighbor_dropout 1.5", "1:30: `neighbor_dropout` must be a number between 0 and 1, "
     "got 1.5"),
])
def test_sensing_option_mistakes_are_located_errors(assert_located_error, opts, message):
    assert_located_error("robot eye { " + opts + " }\nagent a { robot eye; status s { } }", message)


def _leader_alignment(sim) -> float:
    kinds = sim.agents.cols["kind"]
    lead = sim.program.kinds[int(kinds[0])].name == "leader"
    leader_row = 0 if lead else int(np.flatnonzero(kinds != kinds[-1])[0])
    heading = sim.agents.cols["heading"]
    followers = np.arange(len(kinds)) != leader_row
    return float(np.cos(heading[followers] - heading[leader_row]).mean())


@pytest.mark.parametrize("seed", [1, 2])
def test_followers_converge_on_the_leaders_heading(backend, seed):
    from swarmdsl.compiler import compile_file

    sim = Simulation(compile_file(PROGRAMS / "boids_leader.swarm"), seed)
    sim.step()
    assert _leader_alignment(sim) < 0.5           # scattered headings at the start
    sim.run(799)
    assert _leader_alignment(sim) > 0.9
