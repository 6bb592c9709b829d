"""What `check --target kilobot` and the export say besides refusing: located warnings
of what runs differently on robots (the arena's walls, message values that may
saturate), and each refusal once, with their count."""

from __future__ import annotations

import re

import pytest

from swarmdsl.cli import main


def _check(tmp_path, capsys, text: str) -> tuple[int, str]:
    path = tmp_path / "p.swarm"
    path.write_text(text)
    code = main(["check", "--target", "kilobot", str(path)])
    captured = capsys.readouterr()
    return code, captured.err + captured.out


SENDER = """world {{ size 200 x 200; steps {steps} }}
agent bot {{
  robot kilobot
  count 2
  place (50 + 40 * index, 100)
  var n = 0
  message v num
  status s {{
    n = min(n + 1, 100)
    broadcast(v, {value})
  }}
}}
"""


@pytest.mark.parametrize(("steps", "value", "warned"), [
    (1000, "tick * 100", "from 0 to 100000"),
    (100, "tick * 100", None),                      # at most 10000
    (1000, "clamp(tick * 100, 0, 30000)", None),
    (1000, "n * 300", None),                         # n stays within 0..100
    (1000, "n * 400", "from 0 to 40000"),
    (1000, "count(heard()) + min(heard() : msg.v else 0)", "from -32768 to 32775"),
])
def test_a_value_that_may_not_fit_a_message_is_warned_at_its_broadcast(
        tmp_path, capsys, steps, value, warned):
    """A message number is a 16-bit whole number: a value the exporter cannot bound
    within it (from `tick`, counters, received values...) is warned about, located at
    the broadcast, with the range it may take; the robot then sends it saturated."""
    code, err = _check(tmp_path, capsys, SENDER.format(steps=steps, value=value))
    assert code == 0
    found = re.search(r"p\.swarm:10:18: warning: `v` is sent as whole numbers from -32768 "
                      r"to 32767; the values sent may be ([^,(]*)", err)
    if warned is None:
        assert "is sent as" not in err
    else:
        assert found and found[1].strip() == warned, err


WALKER = """world { size 300 x 200; steps 100 }
agent bot {
  robot kilobot
  count 2
  place (50 + 40 * index, 100)
  velocity (1, 0)
  status s { velocity = rotate(velocity, 0.1) }
}
"""


def test_a_walled_world_whose_robots_move_is_warned_of_the_arena_real_robots_meet(
        tmp_path, capsys):
    code, err = _check(tmp_path, capsys, WALKER)
    assert code == 0
    assert re.search(r"p\.swarm:1:1: warning: the world's walls \(300 x 200\) are an arena "
                     r"on Kilobots", err)
    assert "build the arena's walls 333 x 233 mm" in err
    still = WALKER.replace("  velocity (1, 0)\n", "").replace(
        "velocity = rotate(velocity, 0.1)", "led(red)")
    assert "arena" not in _check(tmp_path, capsys, still)[1]    # robots that never move


def test_a_wrap_world_is_refused_at_its_edges_option(tmp_path, capsys):
    code, err = _check(tmp_path, capsys, WALKER.replace("steps 100 }", "steps 100; edges wrap }"))
    assert code == 2
    assert err.startswith(f"{tmp_path / 'p.swarm'}:1:36: error: a wrap-around world "
                          "(`edges wrap`) cannot run on a Kilobot (target kilobot)")
    assert err.rstrip().endswith("1 error: what a Kilobot cannot run (target kilobot)")


def test_each_refusal_is_shown_once_with_the_count(tmp_path, capsys):
    """A neighbour set's `let` is inlined in each aggregate over it: its refusal came
    once per aggregate. Now once, and the count of refusals closes the report."""
    text = """world { size 200 x 200; steps 10 }
agent bot {
  robot kilobot
  count 2
  place (50 + 40 * index, 100)
  var a = 0
  message v num
  status s {
    let near = neighbors(40)
    a = count(near) + sum(near : dist) + max(near : dist else 0) + min(near : dist else 0)
    a = normal(0, 1)
    broadcast(v, 1)
  }
}
"""
    code, err = _check(tmp_path, capsys, text)
    assert code == 2
    errors = [x for x in err.splitlines() if ": error: " in x]
    assert len(errors) == len(set(errors)) == 2
    assert "9:16: error: `neighbors()`" in errors[0]
    assert "11:9: error: the function `normal`" in errors[1]
    assert err.rstrip().endswith("2 errors: what a Kilobot cannot run (target kilobot)")


MOVER = """world {{ size 300 x 200; steps 100 }}
param rate = 0.0227
agent bot {{
  robot kilobot
  count 1
  place (50, 100)
  status s {{ {motion} }}
}}
"""


@pytest.mark.parametrize(("motion", "warned"), [
    ("forward(0.7)", None), ("forward(0.72); stop()", None), ("turn_left(rate)", None),
    ("forward(1)", "`forward` moves a Kilobot at its calibrated 7 mm/s (0.7 a tick in "
                   "swarmdsl's units), not 1 a tick"),
    ("turn_right(tick / 100)", "`turn_right` moves a Kilobot at its calibrated 13 "
                               "degrees/s (0.0227 a tick in swarmdsl's units), not a size "
                               "computed as it runs"),
])
def test_a_motion_size_that_is_not_the_robots_is_warned(tmp_path, capsys, motion, warned):
    """A Kilobot goes and turns at its calibration: a program asking for another speed
    or turn rate runs otherwise on the robot than in swarmdsl, and is told so where."""
    code, err = _check(tmp_path, capsys, MOVER.format(motion=motion))
    assert code == 0
    if warned is None:
        assert "calibrated" not in err
    else:
        col = MOVER.format(motion=motion).splitlines()[6].index("(") + 2   # the argument
        assert f"p.swarm:7:{col}: warning: {warned} (target kilobot)" in err, err
