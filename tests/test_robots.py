"""Robot profiles, capability checks, messaging, beliefs and noisy motion."""

from __future__ import annotations

import numpy as np
import pytest

from swarmdsl.compiler.errors import SwarmError
from swarmdsl.compiler.profiles import PROFILES

KILO_POS = """
agent a {
  robot ROBOT
  count 3
  status s { velocity = (pos.x, 0) * 0 }
}
"""


def _error(compile_src, text):
    with pytest.raises(SwarmError) as info:
        compile_src(text)
    errs = getattr(info.value, "errors", None) or [info.value]
    return [(e.span.line, e.span.col, e.message) for e in errs]


@pytest.mark.parametrize("snippet, sense, token", [
    ("velocity = (pos.x, 0) * 0", "position", "pos"),
    ("velocity = unit(heading) * 0", "heading", "heading"),
    ("velocity = sum(neighbors(50) : other.pos)", "bearing", "other.pos"),
    ("velocity = sum(neighbors(50) : other.vel)", "motion", "other.vel"),
    ("when any(neighbors(50) : other.status == s) -> s", "state", "other.status"),
])
def test_kilobot_lacks_senses_and_generic_has_them(compile_src, snippet, sense, token):
    text = f"agent a {{\n  robot ROBOT\n  count 3\n  status s {{\n    {snippet}\n  }}\n}}\n"
    compile_src(text.replace("ROBOT", "generic"))
    errs = _error(compile_src, text.replace("ROBOT", "kilobot"))
    line, c, msg = errs[0]
    assert (line, c) == (5, 5 + snippet.index(token))
    assert msg == f"`{token}` needs the sense `{sense}`, which robot `kilobot` lacks"


def test_user_profile_inherits_and_overrides(compile_src):
    prog = compile_src("""
param r = 100
robot scout { like kilobot; comm_range r; senses distance message position }
robot tiny { like kilobot; body 10 }
agent a { robot scout; count 2; message x num
  status s { broadcast(x, pos.x) } }
agent b { robot tiny; count 1; status s { } }
""")
    robots = prog.info.extra["robots"]
    assert robots["scout"].range == 100 and robots["scout"].message_bytes == 9
    assert robots["scout"].allows("position") and not robots["scout"].allows("bearing")
    assert robots["tiny"].range == 20           # two body diameters
    assert PROFILES["kilobot"].range == 66


def test_payload_larger_than_a_kilobot_message_is_an_error(compile_src):
    errs = _error(compile_src, """agent a {
  robot kilobot
  count 2
  message p vec q vec r num
  status s { broadcast(p, (0, 0)) }
}""")
    assert errs == [(4, 3, "the message of `a` takes 10 bytes (p 4, q 4, r 2); robot "
                     "`kilobot` sends 9")]



# ---- heard() needs a sender: without any broadcast it is empty on every tick ----

def test_heard_without_any_message_is_a_located_error_with_the_declaration(tmp_path,
                                                                           capsys):
    from swarmdsl.cli import main

    path = tmp_path / "h.swarm"
    path.write_text("agent a { count 5; var v = 0; status s { v = count(heard()) } }\n")
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0] == (f"{path}:1:52: error: `heard()` is always empty: no kind in the "
                      "program broadcasts a message, so agent `a` never hears one")
    assert err[2].index("^~~~~~~") == len("   1 | ") + 51
    assert err[3] == ("  hint: declare a message and send it, e.g. `message x num` in agent "
                      "`a` and `broadcast(x, VALUE)` in a status")


def test_a_layout_nobody_broadcasts_is_still_silence(compile_src):
    errs = _error(compile_src, "agent a {\n  count 5\n  message x num\n  var v = 0\n"
                  "  status s { v = count(heard()) }\n}\nagent b { count 1; message y "
                  "bool; status t { } }\n")
    assert errs == [(5, 24, "`heard()` is always empty: no kind in the program broadcasts "
                     "a message, so agent `a` never hears one")]


@pytest.mark.parametrize("sender", [
    "agent b { count 2; message x num; status t { broadcast(x, 1) } }",  # another kind
    "agent b { count 2; message x num; status t { tree sequence { broadcast(x, 1) } } }",
])
def test_a_broadcast_by_any_kind_lets_heard_hear(run_src, sender):
    sim = run_src("world { size 50 x 50 }\nagent a { count 3; place (10, 10); var v = 0\n"
                  "  status s { v = count(heard()) } }\n" + sender, steps=3)
    kinds = sim.agents.cols["kind"]
    assert (sim.agents.cols["v"][kinds == 0] == 2).all()   # both b's, every tick after 0


MESSAGES = """
param loss = 0
robot radio { like generic; comm_range 50; loss loss }
agent a {
  robot radio
  count 40
  place (10 * index, 0)
  var got = 0
  var far = 0
  message hello num
  status s {
    broadcast(hello, id)
    got += count(heard())
    far += count(heard() where dist > 50)
  }
}
world { size 500 x 10 }
"""


def test_messages_arrive_next_tick_and_never_beyond_range(run_src):
    sim = run_src(MESSAGES, steps=1)
    assert (sim.agents.cols["got"] == 0).all()          # nothing sent before tick 0
    sim.run(5)
    got, far = sim.agents.cols["got"], sim.agents.cols["far"]
    assert far.sum() == 0
    # neighbours within 50 on a line 10 apart: 5 each side, fewer at the ends
    expected = np.array([min(i, 5) + min(39 - i, 5) for i in range(40)]) * 5
    assert np.array_equal(got, expected)


def test_loss_rate_delivers_a_binomial_share(run_src):
    sim = run_src(MESSAGES, steps=201, overrides={"loss": "0.3"})
    delivered = sim.agents.cols["got"].sum()
    possible = sum(min(i, 5) + min(39 - i, 5) for i in range(40)) * 200
    p = 1 - 0.3
    sd = np.sqrt(possible * p * (1 - p))
    assert abs(delivered - possible * p) < 4 * sd
    again = run_src(MESSAGES, steps=201, overrides={"loss": "0.3"})
    assert np.array_equal(again.agents.cols["got"], sim.agents.cols["got"])


def test_msg_reads_the_sender_value_and_links_fill_the_snapshot(run_src):
    sim = run_src("""
robot radio { like generic; comm_range 15 }
agent a { robot radio; count 3; place (10 * index, 0); var left = -1
  message myid num
  status s { broadcast(myid, id); left = max(heard() : msg.myid else -1) } }
""", steps=3)
    assert sim.agents.cols["left"].tolist() == [1, 2, 1]
    snap = sim.snapshot()
    assert sorted(map(tuple, snap.links.tolist())) == [(0, 1), (1, 2)]


def test_kilobot_motion_is_noisy_bounded_and_odometry_tracks_commands(run_src):
    src = """
param hn = 0.1
robot bot { like kilobot; heading_noise hn; speed_noise 0.2 }
agent a { robot bot; count 400; place (500, 500); believe (0, 0)
  status s { velocity = (5, 0) } }
world { size 1000 x 1000 }
"""
    sim = run_src(src, steps=50)
    cols = sim.agents.cols
    assert np.allclose(cols["believed"], [50.0, 0.0])        # commanded: capped at 1/tick
    true = cols["pos"] - 500
    assert np.all(np.hypot(*cols["vel"].T) <= 1.0 + 1e-12)
    assert abs(true[:, 0].mean() - 50) < 2                    # unbiased on average
    # independent turns of sd 0.1 rad per 1-unit step: sideways spread 0.1 * sqrt(50)
    assert abs(true[:, 1].std() / (0.1 * np.sqrt(50)) - 1) < 0.15
    quiet = run_src(src, steps=50, overrides={"hn": "0"})
    assert np.allclose(quiet.agents.cols["pos"][:, 1], 500)
    again = run_src(src, steps=50)
    assert np.array_equal(again.agents.cols["pos"], cols["pos"])


def test_snapshot_led_and_believed_in_world_frame(run_src):
    sim = run_src("""
world { size 100 x 100; origin 20 30 }
agent a { robot kilobot; count 2; place (25 + index * 10, 35); believe pos - (20, 30)
  status s { led(red) } }
""", steps=1)
    snap = sim.snapshot()
    assert snap.led.tolist() == [[255, 32, 32], [255, 32, 32]]
    assert np.allclose(snap.believed, snap.pos)


@pytest.mark.parametrize(("args", "col", "name", "got"), [
    ("2, 0, 0", 35, "red", "2"), ("0, -0.5, 0", 38, "green", "-0.5"),
    ("index, 0.5, 1 + 1", 47, "blue", "2")])
def test_a_constant_led_channel_outside_0_to_1_is_a_located_error(compile_src, args, col,
                                                                  name, got):
    errs = _error(compile_src, f"agent a {{ count 2; status s {{ led({args}) }} }}\n")
    assert errs == [(1, col, f"the {name} channel of `led` must be from 0 to 1, got {got}")]


def test_a_nan_led_channel_is_a_located_fault_not_a_nan_colour(compile_src, backend):
    """A NaN channel used to be recorded as a NaN `led`; computed channels outside 0..1
    are still clamped."""
    from swarmdsl.compiler.errors import SwarmRuntimeError
    from swarmdsl.runtime.simulation import Simulation

    prog = compile_src("agent a { count 3; status s { led(index * 2, sqrt(index - 1), 0) } }")
    with pytest.raises(SwarmRuntimeError) as info:
        Simulation(prog, 0, backend=backend).run(1)
    assert info.value.message == ("the green channel of `led` is NaN for agent 0 (kind `a`, "
                                  "status `s`) at tick 0")
    assert (info.value.span.line, info.value.span.col) == (1, 46)
    sim = Simulation(compile_src("agent a { count 2; status s { led(index * 2, 0, 0) } }"),
                     0, backend=backend)
    sim.run(1)
    assert sim.snapshot().led.tolist() == [[0, 0, 0], [255, 0, 0]]


def test_recorder_writes_true_and_believed(tmp_path, compile_src):
    import pyarrow.parquet as pq

    from swarmdsl.runtime.record import Recorder
    from swarmdsl.runtime.simulation import Simulation

    sim = Simulation(compile_src("""
agent a { robot kilobot; count 2; place (10, 10 + index); believe (1, 2)
  status s { velocity = (1, 0) } }
"""), 0)
    rec = Recorder(tmp_path, sim)
    rec.record()
    sim.run(3)
    rec.record()
    rec.close(3)
    table = pq.read_table(tmp_path / "agents.parquet").to_pydict()
    assert {"x", "y", "believed_x", "believed_y", "located"} <= set(table)
    last = [i for i, t in enumerate(table["tick"]) if t == 3]
    assert [table["believed_x"][i] for i in last] == [4.0, 4.0]


def test_delivery_matches_a_brute_force_oracle(compile_src):
    """Random positions and two kinds with different ranges: exactly the pairs with the
    sender broadcasting last tick and within the receiver's range are heard."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from swarmdsl.runtime.messaging import messenger_of
    from swarmdsl.runtime.simulation import Simulation

    prog = compile_src("""
robot near { like generic; comm_range 15 }
robot far { like generic; comm_range 40 }
agent a { robot near; count 12; message v num
  status s { when chance(0.5) -> s { broadcast(v, 1) } } }
agent b { robot far; count 12; message v num
  status s { when chance(0.5) -> s { broadcast(v, 1) } } }
world { size 100 x 100 }
""")

    @settings(max_examples=25, deadline=None)
    @given(st.integers(0, 10_000))
    def check(seed):
        sim = Simulation(prog, seed)
        sim.step()
        sent = sim.agents.cols["msg_tick"] == sim.tick - 1
        m = messenger_of(sim)
        m.begin_tick(sim)
        t = m.table
        got = {(int(i), int(j)) for i in range(sim.agents.n)
               for j in t.j[t.offsets[i]:t.offsets[i + 1]]}
        pos, kind = sim.agents.cols["pos"], sim.agents.cols["kind"]
        reach = np.where(kind == 0, 15.0, 40.0)
        d = np.linalg.norm(pos[:, None] - pos[None], axis=2)
        want = {(i, j) for i in range(len(pos)) for j in range(len(pos))
                if i != j and sent[j] and d[i, j] <= reach[i]}
        assert got == want
    check()


def test_a_talking_robot_of_body_zero_is_refused_not_deaf(assert_located_error,
                                                           compile_src):
    """`like kilobot; body 0` inherits a comm_range of two body diameters, 0: every
    `heard()` used to be empty without a word, while `comm_range 0` is refused."""
    agent = ("agent a {{ robot {r}; count 3; place (10 * index, 50); message x num; "
             "status s {{ broadcast(x, 1) }} }}\n")
    assert_located_error("robot r { like kilobot; body 0 }\n" + agent.format(r="r"),
                         "2:53: agents of `a` would hear no message: robot `r` hears two "
                         "body diameters away, and its body is 0")
    compile_src("robot r { like kilobot; body 0; comm_range 30 }\n" + agent.format(r="r"))


def test_an_infinite_belief_is_a_located_fault(run_src):
    """`believe((1 / z, 0))` with z = 0 used to run on, recording `believed_x` = inf for
    the rest of the run; now it stops at the action, naming the agent."""
    from swarmdsl.compiler.errors import SwarmRuntimeError

    with pytest.raises(SwarmRuntimeError) as err:
        run_src("agent a { count 2; var z = 0; status s { believe((1 / z, 0)) } }", steps=2)
    assert "test.swarm:1:50: error: the belief is infinite for agent 0 (kind `a`, status " \
        "`s`) at tick 0" in str(err.value)
