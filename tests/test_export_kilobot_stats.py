"""Programs that use chance and motion behave alike in swarmdsl and, exported, in
Kilombo: statistics over seeds from the same layouts, not bits (the two draw from
different generators, and Kilombo's robots bump into each other and hear each other
twice a second). Each comparison is a stated two-sample test; where the motion models
cannot agree, a stated tolerance and why (docs/kilobot.md, "Chance and motion").

In CI a few seeds each (cheap); `-m slow` runs 30 seeds a side, the figures of the
docs' table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from swarmdsl.compiler import compile_source
from swarmdsl.runtime.simulation import Simulation
from tests.test_export_kilobot import KILOMBO, _export, _kilombo_states, kilombo_build

pytestmark = pytest.mark.skipif(not KILOMBO, reason=f"no Kilombo: {kilombo_build.missing()}")

# Probabilistic leader election: an undecided robot hearing a claim follows (and
# passes the claim on); otherwise it claims leadership with chance `p` a tick.
LEADER = """
param p = {p}
world {{ size 300 x 200; steps {steps} }}
agent bot {{
  robot kilobot
  count 10
  place (60 + 40 * (index % 5), 80 + 40 * floor(index / 5))
  var won = -1
  message claim bool
  status undecided {{
    broadcast(claim, false)
    when any(heard() : msg.claim) -> follower
    when chance(p) -> leader {{ won = tick }}
  }}
  final status leader {{ broadcast(claim, true); led(red) }}
  final status follower {{ broadcast(claim, true); led(blue) }}
}}
"""

# A random walk of Kilobot motions: each tick, with chance 0.1, go straight, turn left
# or turn right from then on, at Kilombo's Kilobot's speed (7 mm/s) and turn rate
# (13 degrees/s). No motion noise: Kilombo's robots have none.
WALK = """
robot walker { like kilobot; heading_noise 0; speed_noise 0 }
param pace = 0.7
param rate = 0.0227
world { size 1000 x 1000; steps 300 }
agent bot {
  robot walker
  count 9
  place (350 + 150 * (index % 3), 350 + 150 * floor(index / 3))
  var mode = 0
  status walk {
    mode = if chance(0.1) then floor(uniform(0, 3)) - 1 else mode
    when mode > 0 -> walk { turn_left(rate) }
    when mode < 0 -> walk { turn_right(rate) }
    forward(pace)
  }
}
"""

# BEECLUST-like aggregation in a walled arena: walk until a robot is heard, rest
# `wait_ticks`, turn away a random while, walk off, walk again.
BEECLUST = """
robot bee {{ like kilobot; heading_noise 0; speed_noise 0 }}
param pace = 0.7
param rate = 0.0227
param wait_ticks = 150
world {{ size 400 x 400; steps {steps} }}
agent bot {{
  robot bee
  count 20
  place (40 + 80 * (index % 5), 40 + 80 * floor(index / 5))
  var wait = 0
  var turning = 0
  message here bool
  status walk {{
    broadcast(here, true)
    forward(pace)
    when count(heard()) > 0 -> rest {{ stop(); wait = wait_ticks }}
  }}
  status rest {{
    broadcast(here, true)
    wait -= 1
    when wait <= 0 -> leave {{ turning = floor(uniform(10, 140)) }}
  }}
  status leave {{
    broadcast(here, true)
    turn_left(rate)
    turning -= 1
    when turning <= 0 -> escape {{ forward(pace); wait = 40 }}
  }}
  status escape {{
    broadcast(here, true)
    forward(pace)
    wait -= 1
    when wait <= 0 -> walk
  }}
}}
"""


def _bots(state: dict) -> list[dict]:
    return sorted(state["bot_states"], key=lambda b: b["ID"])


def _pos(state: dict) -> np.ndarray:
    """Kilombo's positions in the language's frame (Kilombo's y points down)."""
    return np.array([(b["x_position"], -b["y_position"]) for b in _bots(state)])


class Kilombo:
    """One exported program, built once, run with Kilombo's seeds 1, 2, ..."""

    def __init__(self, tmp: Path, name: str, text: str):
        tmp.mkdir(parents=True, exist_ok=True)
        (tmp / f"{name}.swarm").write_text(text)
        assert _export(tmp / f"{name}.swarm", tmp / "c") == 0
        self.folder, self.name, self.work = tmp / "c", name, tmp / "run"

    def run(self, seed: int) -> list[dict]:
        return _kilombo_states(self.folder, self.name, self.work, seed=seed + 1)


def _leader_outcome(won: np.ndarray) -> tuple[float, int]:
    """The tick of the first claim (inf if none) and how many robots claimed."""
    won = np.asarray(won, dtype=float)
    claimed = won[won >= 0]
    return (claimed.min() if claimed.size else np.inf), int(claimed.size)


def _leaders(tmp_path, backend, seeds: int, p: float, steps: int):
    text = LEADER.format(p=p, steps=steps)
    program = compile_source(text, "leader.swarm")
    ours = []
    for seed in range(seeds):
        sim = Simulation(program, seed=seed, backend=backend)
        sim.run(steps)
        ours.append(_leader_outcome(sim.agents.cols["won"]))
    kilombo = Kilombo(tmp_path, "leader", text)
    theirs = [_leader_outcome([b["state"]["won"] for b in _bots(kilombo.run(s)[-1])])
              for s in range(seeds)]
    return np.array(ours), np.array(theirs)


def test_leader_election_draws_alike_in_swarmdsl_and_kilombo(tmp_path, backend):
    """Ten robots, each claiming with chance 0.003 a tick: in both, every run elects
    (one leader, or two whose claims crossed), the first claim's tick is drawn from the
    same distribution (Mann-Whitney, two-sided, p > 0.001 over 6 seeds a side). With
    every robot drawing the same numbers (kilolib's unseeded rand_soft) all ten
    claimed at once."""
    ours, theirs = _leaders(tmp_path, backend, 6, 0.003, 300)
    for first, claimed in (*ours, *theirs):
        assert np.isfinite(first) and 1 <= claimed <= 2
    assert stats.mannwhitneyu(ours[:, 0], theirs[:, 0]).pvalue > 0.001


def _walk(tmp_path, backend, seeds: int):
    program = compile_source(WALK, "walk.swarm")
    ours = []
    for seed in range(seeds):
        sim = Simulation(program, seed=seed, backend=backend)
        start, headings = sim.agents.cols["pos"].copy(), [sim.agents.cols["heading"].copy()]
        for _ in range(30):
            sim.run(10)
            headings.append(sim.agents.cols["heading"].copy())
        turned = np.unwrap(np.array(headings), axis=0)
        ours.append((np.hypot(*(sim.agents.cols["pos"] - start).T).mean(),
                     np.abs(turned[-1] - turned[0]).mean()))
    kilombo, theirs = Kilombo(tmp_path, "walk", WALK), []
    for seed in range(seeds):
        states = kilombo.run(seed)[:31]
        turned = np.unwrap(np.array([[b["direction"] for b in _bots(s)] for s in states]),
                           axis=0)
        theirs.append((np.hypot(*(_pos(states[-1]) - _pos(states[0])).T).mean(),
                       np.abs(turned[-1] - turned[0]).mean()))
    return np.array(ours), np.array(theirs)


def _assert_walks_agree(ours, theirs, alpha: float) -> None:
    """How far the robots turn is the same process in both (Mann-Whitney, p > alpha);
    how far they get is Kilombo's less by up to 15 %: its turning robot pivots about a
    leg, its centre moving 35 degrees off its heading, where swarmdsl's moves along
    its heading (which is its motion's direction), and Kilombo goes straight at 6.85
    mm/s, not 7."""
    assert stats.mannwhitneyu(ours[:, 1], theirs[:, 1]).pvalue > alpha
    assert 0.85 < theirs[:, 0].mean() / ours[:, 0].mean() < 1.0


def test_a_random_walks_turns_and_spread_agree_within_the_motion_models(tmp_path, backend):
    ours, theirs = _walk(tmp_path, backend, 6)
    _assert_walks_agree(ours, theirs, 0.001)


def _beeclust(tmp_path, backend, seeds: int, steps: int, since: int):
    """The fraction of robots resting, averaged over each second from `since` (s) to
    the end, per seed; and Kilombo's positions, to check its arena."""
    text = BEECLUST.format(steps=steps)
    program = compile_source(text, "bee.swarm")
    rest = program.status_code("bot", "rest")
    ours = []
    for seed in range(seeds):
        sim = Simulation(program, seed=seed, backend=backend)
        sim.run(10 * since - 10)
        fractions = []
        for _ in range(steps // 10 - since + 1):
            sim.run(10)
            fractions.append((sim.agents.cols["status"] == rest).mean())
        ours.append(np.mean(fractions))
    kilombo, theirs, where = Kilombo(tmp_path, "bee", text), [], []
    for seed in range(seeds):
        states = kilombo.run(seed)
        theirs.append(np.mean([[b["state"]["status"] == "rest" for b in s["bot_states"]]
                               for s in states[since:]]))
        where += [_pos(s) for s in states]
    return np.array(ours), np.array(theirs), np.concatenate(where)


def test_beeclust_rests_alike_and_kilombos_arena_holds_its_robots(tmp_path, backend):
    """Twenty robots that stop where they hear another, in a 400 x 400 walled world:
    from 30 s to 60 s, about half rest in both (the mean fractions within 0.1 over 3
    seeds a side); Kilombo's robots stay inside the world's walls (without its arena,
    seed 0: robots out at x = 779 and none resting from 30 s on)."""
    ours, theirs, where = _beeclust(tmp_path, backend, 3, 600, 30)
    assert abs(ours.mean() - theirs.mean()) < 0.1
    assert 0.2 < theirs.mean() < 0.8
    assert where.min() >= 0 and where.max() <= 400


def test_the_kilobot_profiles_motions_are_kilombos(tmp_path, backend):
    """`forward(0.7)` and `turn_left(0.0227)` (7 mm/s, 13 degrees/s) on the kilobot
    profile without noise, and the same program in Kilombo: straight for 10 s, the
    same distance within 3 %; turning for 10 s, the same turn within 3 % and the
    centre on a circle of about half a body (swarmdsl 16.5 mm, Kilombo 17) in both."""
    text = """
robot exact { like kilobot; heading_noise 0; speed_noise 0 }
world { size 2000 x 2000; steps 200 }
agent bot {
  robot exact
  count 1
  place (1000, 1000)
  status go { forward(0.7); when tick == 99 -> spin }
  status spin { turn_left(0.0227) }
}
"""
    sim = Simulation(compile_source(text, "m.swarm"), seed=0, backend=backend)
    ours = []
    for _ in range(21):
        ours.append((*sim.agents.cols["pos"][0], sim.agents.cols["heading"][0]))
        sim.run(10)
    states = Kilombo(tmp_path, "motion", text).run(0)
    theirs = [(*_pos(s)[0], _bots(s)[0]["direction"]) for s in states[:21]]
    ours, theirs = np.array(ours), np.array(theirs)
    for track in (ours, theirs):
        straight = np.hypot(*(track[10, :2] - track[0, :2]))
        turned = np.unwrap(track[10:, 2])
        assert straight == pytest.approx(70.0, rel=0.03)
        assert turned[-1] - turned[0] == pytest.approx(2.27, rel=0.03)
        spin = track[10:, :2]
        centre = spin.mean(axis=0)
        assert np.hypot(*(spin - centre).T).max() < 20.0


@pytest.mark.slow
def test_thirty_seeds_a_side_agree(tmp_path, backend):
    """The docs' table: 30 seeds a side. Leader election (p = 0.0005, 100 s): the first
    claim's tick, Mann-Whitney p > 0.01; the random walk's turn, p > 0.01, its spread
    within the stated 15 %; BEECLUST's resting fraction from 30 s to 90 s, p > 0.01.
    Prints the figures."""
    ours, theirs = _leaders(tmp_path / "l", backend, 30, 0.0005, 1000)
    p_leader = stats.mannwhitneyu(ours[:, 0], theirs[:, 0]).pvalue
    print("leader first claim", ours[:, 0].mean(), theirs[:, 0].mean(), p_leader,
          "leaders", ours[:, 1].mean(), theirs[:, 1].mean())
    assert p_leader > 0.01
    walk_ours, walk_theirs = _walk(tmp_path / "w", backend, 30)
    print("walk spread", walk_ours[:, 0].mean(), walk_theirs[:, 0].mean(),
          "turn", walk_ours[:, 1].mean(), walk_theirs[:, 1].mean(),
          stats.mannwhitneyu(walk_ours[:, 1], walk_theirs[:, 1]).pvalue)
    _assert_walks_agree(walk_ours, walk_theirs, 0.01)
    bee_ours, bee_theirs, where = _beeclust(tmp_path / "b", backend, 30, 900, 30)
    p_bee = stats.mannwhitneyu(bee_ours, bee_theirs).pvalue
    print("beeclust resting", bee_ours.mean(), bee_ours.std(), bee_theirs.mean(),
          bee_theirs.std(), p_bee)
    assert p_bee > 0.01
    assert where.min() >= 0 and where.max() <= 400
