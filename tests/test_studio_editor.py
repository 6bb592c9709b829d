"""The studio's editor against its session, without a browser: the diagnostics every
scene carries are those of the editor's text, the file on disk is known (the unsaved
mark), and the Reproduce line is a command only when it makes the run on screen."""

from __future__ import annotations

import json
import shlex
import urllib.request

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.studio.reproduce import file_overrides
from swarmdsl.studio.session import Session
from tests.studio_server import PROGRAM, StudioProcess, program_copy


@pytest.fixture
def program(tmp_path):
    return program_copy(tmp_path)


@pytest.fixture
def session(backend, program, tmp_path):
    return Session(program, out=tmp_path / "runs", backend=backend)


def sets_of(line: str) -> tuple[dict[str, str], int]:
    """The `--set` values and the seed of a Reproduce command."""
    words = shlex.split(line)
    assert words[:2] == ["swarmdsl", "run"], line
    sets, seed = {}, 0
    for flag, value in zip(words[3::2], words[4::2], strict=True):
        if flag == "--set":
            name, text = value.split("=", 1)
            sets[name] = text
        else:
            assert flag == "--seed"
            seed = int(value)
    return sets, seed


def replay(line: str, backend: str, ticks: int) -> np.ndarray:
    """The agents' positions after `ticks` of the run the command makes (the file on disk
    with its `--set` values and seed)."""
    sets, seed = sets_of(line)
    s = Session(shlex.split(line)[2], sets, seed=seed, backend=backend)
    s.step(ticks)
    return s.sim.agents.cols["pos"]


# ---- the diagnostics shown are those of the text on screen ----
def test_a_failed_runs_errors_do_not_come_back_once_the_text_is_fixed(session):
    good = session.text
    broken = good.replace("* cruise", "* cruisezz")
    errors = session.run_text(broken)
    assert "cruisezz" in errors[0]["message"] and session.scene()["draft"] == broken
    assert session.check(good) == []            # the editor's text, fixed (not run)
    assert session.set_param("cruise", 3) == {"reset": False}     # a slider moved
    scene = session.scene()
    assert scene["errors"] == [] and scene["draft"] == good
    session.reset()                             # the reset button, a page reloaded
    assert session.scene()["errors"] == []


def test_a_scene_carries_the_errors_with_the_text_they_belong_to(session):
    good = session.text
    broken = good.replace("* cruise", "* cruisezz")
    session.run_text(broken)
    session.set_param("noise", 1)               # the text is still broken: still shown
    scene = session.scene()
    assert scene["draft"] == broken and "cruisezz" in scene["errors"][0]["message"]
    assert scene["text"] == good                # the run on screen is the last good one


def test_reload_reads_the_file_and_drops_the_edits(session, program):
    session.run_text(session.text.replace("deposit(warmth, 1)", "deposit(warmt, 1)"))
    reply = session.control({"op": "reload"})
    assert reply["text"] == program.read_text() and reply["errors"] == []
    scene = session.scene()
    assert scene["draft"] == scene["saved"] == scene["text"] == program.read_text()
    assert scene["errors"] == []


# ---- the Reproduce line ----
def test_a_param_edited_in_the_text_is_a_set_and_the_command_is_the_run(backend, session):
    session.run_text(session.text.replace("param cruise = 2 in", "param cruise = 1.5 in"))
    session.set_param("noise", 0.5)             # and a slider
    scene = session.scene()
    assert scene["set_line_exact"] and scene["saved"] != scene["text"]
    assert sets_of(scene["set_line"])[0] == {"noise": "0.5", "cruise": "1.5"}
    session.step(6)
    np.testing.assert_array_equal(replay(scene["set_line"], backend, 6),
                                  session.sim.agents.cols["pos"])


def test_a_param_derived_from_an_edited_one_needs_no_set_of_its_own(backend, tmp_path):
    path = tmp_path / "d.swarm"
    path.write_text("param n = 10\nparam m = n * 2\nworld { size 100 x 100 }\n"
                    "agent a { count m\n status s { velocity = (1, 0) } }\n")
    s = Session(path, backend=backend)
    s.run_text(path.read_text().replace("param n = 10", "param n = 12"))
    assert s.program.params["m"] == 24
    assert sets_of(s.set_line())[0] == {"n": "12"}


@pytest.mark.parametrize("edit", [
    ("deposit(warmth, 1)", "deposit(warmth, 2)"),             # a rule
    ("param n = 300\n", "# a comment\nparam n = 300\n"),      # where every line stands
    ("param noise = 0.2 in 0..3", "param noise = 0.2 in 0..4"),   # a declared range
    ("param cruise = 2 in 0..10\nparam noise = 0.2 in 0..3",     # params reordered
     "param noise = 0.2 in 0..3\nparam cruise = 2 in 0..10"),
])
def test_an_edit_no_set_can_express_says_to_save_first(session, program, edit):
    session.run_text(session.text.replace(*edit))
    assert session.errors == [] and session.text != program.read_text()
    reproduce = session.reproduce()
    assert not reproduce.exact and not session.scene()["set_line_exact"]
    assert reproduce.line.startswith("save first") and "walkers.swarm" in reproduce.line
    program.write_text(session.text)            # saved: the file is what runs
    assert session.reproduce().exact
    assert session.set_line().startswith(f"swarmdsl run {program}")


def test_a_text_equal_to_the_file_gives_the_plain_command(session, program):
    assert session.set_line() == f"swarmdsl run {program}"
    session.set_seed(4)
    assert session.set_line() == f"swarmdsl run {program} --seed 4"


def test_an_export_of_an_unsaved_text_gives_no_command(session, tmp_path):
    pytest.importorskip("pyarrow")
    from swarmdsl.studio.export import export

    session.run_text(session.text.replace("deposit(warmth, 1)", "deposit(warmth, 2)"))
    session.step(2)
    result = export(session, None)
    assert "command" not in result and result["note"].startswith("save first")


@settings(max_examples=25, deadline=None)
@given(st.floats(0, 3, allow_subnormal=False))
def test_any_value_typed_for_a_param_is_reproduced_to_the_bit(value):
    text = PROGRAM.read_text()
    edited = text.replace("param noise = 0.2 in", f"param noise = {value!r} in")
    sets = file_overrides(PROGRAM, text, edited, {"n": 300, "cruise": 2, "noise": value}, {})
    assert sets == {"noise": repr(value)}


def test_the_server_marks_the_saved_file_and_records_checked_text(program):
    """The page's check and save go through the session: the next scene has the checked
    text's diagnostics and the file as saved."""
    from websockets.sync.client import connect

    server = StudioProcess(program)
    try:
        def post(path, body):
            req = urllib.request.Request(f"{server.base}{path}?token={server.token}",
                                         data=json.dumps(body).encode(), method="POST")
            with urllib.request.urlopen(req, timeout=20) as r:
                return json.loads(r.read())

        broken = program.read_text().replace("* cruise", "* cruisezz")
        assert post("/api/check", {"text": broken})["diagnostics"]
        edited = program.read_text().replace("param cruise = 2 in", "param cruise = 3 in")
        assert post("/api/check", {"text": edited})["diagnostics"] == []
        post("/api/save", {"text": edited})
        ws_url = server.base.replace("http", "ws", 1) + f"/ws?token={server.token}"
        with connect(ws_url, open_timeout=20) as ws:
            ws.send('{"op": "hello"}')
            scene = json.loads(ws.recv(timeout=20))
        assert scene["draft"] == scene["saved"] == edited and scene["errors"] == []
        # the run is still the old text; the file now sets cruise = 3: a --set undoes it
        assert sets_of(scene["set_line"])[0] == {"cruise": "2"}
    finally:
        server.stop()
