"""The studio without a browser: the session the page drives (params, resets, faults,
inspection), the binary frames, the checker endpoint, saving, exporting, and the
server's token."""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from swarmdsl.studio import params as param_controls
from swarmdsl.studio import wire
from swarmdsl.studio.session import Session, check_text
from tests.studio_server import PROGRAM, StudioProcess, program_copy


@pytest.fixture
def program(tmp_path):
    return program_copy(tmp_path)


@pytest.fixture
def session(backend, program, tmp_path):
    return Session(program, out=tmp_path / "runs", backend=backend)


def frame(session, **layers):
    data, _ = session.frame(layers)
    return wire.decode(data)


def test_the_frame_carries_every_agent_as_typed_arrays(session):
    header, arrays = frame(session, field="warmth")
    assert header["n"] == 300 and header["tick"] == 0
    assert arrays["pos"].dtype == np.float32 and arrays["pos"].shape == (600,)
    assert arrays["heading"].dtype == np.float32 and arrays["status"].dtype == np.uint8
    snap = session.sim.snapshot()
    np.testing.assert_array_equal(arrays["pos"], snap.pos.astype(np.float32).reshape(-1))
    f = header["field"]
    assert arrays["field"].dtype == np.uint8 and arrays["field"].size == f["nx"] * f["ny"]


def test_big_swarms_send_headings_as_bytes(backend, program):
    s = Session(program, {"n": "5000"}, backend=backend)
    s.step(1)
    header, arrays = frame(s)
    assert "heading" not in arrays and arrays["heading8"].dtype == np.uint8
    sent = arrays["heading8"].astype(float) * np.pi / 128
    error = np.angle(np.exp(1j * (sent - s.sim.agents.cols["heading"])))
    assert np.abs(error).max() <= np.pi / 256 + 1e-9


@given(st.lists(st.tuples(st.sampled_from(["float32", "uint8", "uint16", "uint32"]),
                          st.integers(0, 40)), max_size=5))
def test_wire_round_trips_any_arrays(specs):
    rng = np.random.default_rng(0)
    arrays = [(f"a{i}", (rng.random(n) * 200).astype(dtype)) for i, (dtype, n)
              in enumerate(specs)]
    header, back = wire.decode(wire.encode({"tick": 3}, arrays))
    assert header["tick"] == 3
    for name, arr in arrays:
        np.testing.assert_array_equal(back[name], arr)
        assert back[name].dtype == arr.dtype


def test_a_param_that_keeps_shapes_applies_from_the_next_tick(session):
    session.step(5)
    before = session.sim.agents.cols["pos"].copy()
    assert session.set_param("cruise", 4) == {"reset": False}
    assert session.sim.tick == 5                        # the run goes on
    np.testing.assert_array_equal(session.sim.agents.cols["pos"], before)
    session.step(1)
    speed = np.hypot(*session.sim.agents.cols["vel"].T)
    np.testing.assert_allclose(speed, 4.0)
    assert session.set_line().endswith("--set cruise=4")
    assert session.scene()["changed_at"] == 5


def test_the_run_after_a_change_is_the_run_the_set_line_makes_from_then_on(backend, session,
                                                                          program):
    """Carrying the state keeps the random streams: a run changed at tick 0 is the run
    started with the new value."""
    session.set_param("noise", 0.5)
    session.step(10)
    fresh = Session(program, {"noise": "0.5"}, backend=backend)
    fresh.step(10)
    np.testing.assert_array_equal(session.sim.agents.cols["pos"],
                                  fresh.sim.agents.cols["pos"])


def test_a_count_or_world_change_resets_the_run(session):
    session.step(3)
    assert session.set_param("n", 50) == {"reset": True}
    assert session.sim.tick == 0 and session.sim.agents.n == 50


def test_a_value_outside_the_declared_range_is_refused_and_changes_nothing(session):
    session.step(2)
    result = session.set_param("cruise", 11)
    assert "outside the declared range 0..10" in result["errors"][0]["message"]
    assert session.sim.tick == 2 and "cruise" not in session.overrides


def test_sliders_come_from_the_declarations(session):
    got = {c.name: c for c in param_controls.controls(session.program, {})}
    assert (got["cruise"].lo, got["cruise"].hi, got["cruise"].declared_range) == (0, 10, True)
    assert got["n"].type == "int" and got["n"].step == 1
    assert not got["n"].declared_range and got["n"].hi == 600


def test_booleans_are_switches(tmp_path):
    path = tmp_path / "b.swarm"
    path.write_text("param loud = true\nworld { size 10 x 10 }\n"
                    "agent a { count 2\n status s { velocity = (0, 0) } }\n")
    (control,) = param_controls.controls(Session(path).program, {})
    assert (control.type, control.value, control.lo) == ("bool", True, None)


def test_a_broken_program_keeps_the_last_run_and_says_where(session):
    session.step(2)
    text = session.text.replace("deposit(warmth, 1)", "deposit(warmt, 1)")
    errors = session.run_text(text)
    line = next(i for i, s in enumerate(text.splitlines(), 1) if "warmt," in s)
    assert errors[0]["line"] == line and "warmt" in errors[0]["message"]
    assert session.sim.tick == 2 and session.scene()["errors"] == errors


def test_check_reports_line_and_column_with_the_hint(program):
    text = program.read_text().replace("normal(0, noise)", "normal(0, nois)")
    (d,) = check_text(text, program, {})
    line = next(i for i, s in enumerate(text.splitlines(), 1) if "nois)" in s)
    assert (d["line"], d["col"]) == (line, text.splitlines()[line - 1].index("nois)") + 1)
    assert d["hint"] and "noise" in d["hint"]


def test_a_fault_pauses_the_run_and_is_shown(backend, tmp_path):
    path = tmp_path / "nan.swarm"
    path.write_text("world { size 10 x 10 }\nagent a { count 2\n var e = 1\n"
                    " status s { e = e - 1\n let v = sqrt(e)\n velocity = (v, 0) } }\n")
    s = Session(path, backend=backend)
    s.set_playing(True)
    for _ in range(5):
        s.advance()
    assert s.fault and ":5:" in s.fault and not s.playing
    header, _ = frame(s)
    assert header["fault"] == s.fault


def test_clicking_an_agent_shows_its_variables(session):
    x, y = session.sim.agents.cols["pos"][7]
    chosen = session.inspect_at(x, y, 0.001)
    assert chosen == int(session.sim.agents.cols["id"][7])
    header, _ = frame(session)
    sel = header["selected"]
    assert sel["kind"] == "walker" and sel["status"] == "moving"
    assert np.hypot(*sel["vars"]["vel"]) == pytest.approx(2.0)
    assert session.inspect_at(-1e6, -1e6, 1) is None


def test_export_writes_what_run_out_writes(session, tmp_path):
    pytest.importorskip("pyarrow")
    from swarmdsl.studio.export import export

    session.step(4)
    result = export(session, None)
    folder = tmp_path / "runs" / "walkers-seed0-tick4"
    assert result["folder"] == str(folder) and result["outcome"] == "completed"
    assert {"agents.parquet", "metrics.parquet", "run.json"} <= set(result["files"])
    meta = json.loads((folder / "run.json").read_text())
    assert (meta["steps"], meta["last_tick"], meta["finished"]) == (4, 4, "completed")
    import pyarrow.parquet as pq

    rows = pq.read_table(folder / "agents.parquet").to_pydict()
    last = [i for i, t in enumerate(rows["tick"]) if t == 4]
    order = np.argsort([rows["id"][i] for i in last])
    xy = np.array([[rows["x"][i], rows["y"][i]] for i in last])[order]
    np.testing.assert_array_equal(xy, session.sim.agents.cols["pos"])   # the run shown
    again = export(session, None)        # never over another export
    assert again["folder"].endswith("tick4-2")


def test_the_server_saves_only_its_own_file_and_refuses_without_the_token(program):
    server = StudioProcess(program)
    try:
        def post(path, body, token=server.token):
            req = urllib.request.Request(f"{server.base}{path}?token={token}",
                                         data=json.dumps(body).encode(), method="POST")
            with urllib.request.urlopen(req, timeout=20) as r:
                return json.loads(r.read())

        got = post("/api/check", {"text": "param n = \n"})
        assert got["diagnostics"][0]["line"] == 1
        text = program.read_text() + "# saved\n"
        assert post("/api/save", {"text": text, "path": "/tmp/elsewhere"})["saved"] == \
            program.name
        assert program.read_text() == text
        assert sorted(p.name for p in program.parent.iterdir()) == [program.name]
        with pytest.raises(urllib.error.HTTPError) as refused:
            post("/api/save", {"text": "x"}, token="")
        refused.value.close()
        assert refused.value.code == 403 and program.read_text() == text
    finally:
        server.stop()


# ---- the notebook widget, without Jupyter: its traits and messages ----

@pytest.fixture
def widget(program):
    pytest.importorskip("anywidget")
    import swarmdsl

    w = swarmdsl.show(program)
    w.sent = []
    w.send = lambda content, buffers=None: w.sent.append((content, buffers))
    return w


def test_the_widget_shares_the_pages_renderer(widget):
    from swarmdsl.studio.server import STATIC

    renderer = (STATIC / "renderer.js").read_text()
    assert widget._esm.startswith(renderer) and "export default" in widget._esm
    assert ".swarm-studio" in widget._css and "#editor" not in widget._css


def test_the_widget_answers_the_views_messages_with_frames(backend, widget):
    widget._handle_custom_msg({"op": "hello"}, [])
    (scene, _), (kind, (data,)) = widget.sent
    assert scene["type"] == "scene" and [p["name"] for p in scene["params"]] == [
        "n", "cruise", "noise"]
    assert kind == {"type": "frame"} and wire.decode(data)[0]["tick"] == 0
    widget._handle_custom_msg({"op": "ready"}, [])
    assert len(widget.sent) == 2                     # paused, nothing new: no frame
    widget._handle_custom_msg({"op": "param", "name": "cruise", "value": 3}, [])
    replies = [c for c, _ in widget.sent[2:]]
    assert {"type": "result", "op": "param", "name": "cruise", "reset": False} in replies
    widget._handle_custom_msg({"op": "play"}, [])
    for _ in range(4):
        widget._handle_custom_msg({"op": "ready"}, [])
    header, arrays = wire.decode(widget.sent[-1][1][0])
    assert header["tick"] == 4 and header["playing"]
    np.testing.assert_allclose(np.hypot(*widget.session.sim.agents.cols["vel"].T), 3.0)


def test_show_takes_a_program_and_a_finished_run(backend, program, tmp_path):
    pytest.importorskip("anywidget")
    import swarmdsl
    from swarmdsl.runtime.runner import Run

    loaded = swarmdsl.load_program(program, {"cruise": 4})
    assert swarmdsl.show(loaded).session.overrides == {"cruise": "4"}
    run = Run(loaded, seed=3, steps=6, out=tmp_path / "out", backend=backend)
    run.show_progress = False
    run.execute()
    w = swarmdsl.show(run)
    assert w.session.seed == 3 and w.session.set_line().endswith("--set cruise=4 --seed 3")
    assert sorted(w.recorded) == ["mean_speed", "polarisation"]
    assert [t for t, _ in w.recorded["mean_speed"]] == list(range(7))
    assert w.recorded["mean_speed"][-1][1] == pytest.approx(4.0)
    with pytest.raises(swarmdsl.SwarmOptionError, match="show takes"):
        swarmdsl.show(42)


def test_the_boids_cohesion_slider_changes_the_flock(backend):
    """The issue's new user: boids, the cohesion slider dragged to 0 mid-run, and the
    flock spreads out where the unchanged one gathers."""
    from tests.studio_server import ROOT

    boids = ROOT / "programs" / "boids.swarm"
    kept, loose = Session(boids, backend=backend), Session(boids, backend=backend)
    kept.step(20)
    loose.step(20)
    assert loose.set_param("cohesion", 0) == {"reset": False}
    kept.step(150)
    loose.step(150)

    def spread(s):
        pos = s.sim.agents.cols["pos"]
        return np.mean(np.linalg.norm(pos - pos.mean(axis=0), axis=1))

    assert spread(loose) > 1.2 * spread(kept)
    assert loose.set_line() == f"swarmdsl run {boids} --set cohesion=0"


def test_show_names_a_bad_argument(program):
    pytest.importorskip("anywidget")
    import swarmdsl

    with pytest.raises(swarmdsl.SwarmOptionError, match="width"):
        swarmdsl.show(program, width=5)
    with pytest.raises(swarmdsl.SwarmOptionError, match="seed"):
        swarmdsl.show(program, seed=-1)
    with pytest.raises(swarmdsl.SwarmOptionError, match="no such program file"):
        swarmdsl.show(program.parent / "missing.swarm")


def test_export_records_a_video_of_the_replayed_run(session, tmp_path):
    pytest.importorskip("pygame")
    pytest.importorskip("PIL")
    from PIL import Image

    from swarmdsl.studio.export import export

    session.step(3)
    result = export(session, "gif")
    assert "run.gif" in result["files"] and "video_error" not in result
    with Image.open(tmp_path / "runs" / "walkers-seed0-tick3" / "run.gif") as gif:
        assert gif.n_frames == 4                      # ticks 0 to 3
    from swarmdsl.compiler.errors import SwarmOptionError

    with pytest.raises(SwarmOptionError, match="gif or mp4"):
        export(session, "../../etc/passwd")


@pytest.mark.parametrize("argv, message", [
    (["studio", "missing.swarm", "--no-browser"], "no such program file: missing.swarm"),
    (["studio", str(PROGRAM), "--no-browser", "--port", "70000"], "--port 70000"),
    (["studio", str(PROGRAM), "--no-browser", "--seed", "-1"], "--seed -1"),
])
def test_the_command_names_a_bad_option(argv, message, capsys):
    from swarmdsl.cli import main

    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_a_program_with_errors_still_serves_its_page(tmp_path):
    broken = tmp_path / "broken.swarm"
    broken.write_text("world { size 10 x 10 }\nagent a { count 2\n"
                      " status s { velocity = (speeed, 0) } }\n")
    server = StudioProcess(broken)
    try:
        from websockets.sync.client import connect

        with urllib.request.urlopen(server.url, timeout=20) as page:
            assert page.status == 200
        ws_url = server.base.replace("http", "ws", 1) + f"/ws?token={server.token}"
        with connect(ws_url, open_timeout=20) as ws:
            ws.send('{"op": "hello"}')
            scene = json.loads(ws.recv(timeout=20))
            assert scene["errors"][0]["line"] == 3 and "speeed" in scene["errors"][0]["text"]
            ws.send(json.dumps({"op": "run", "text": broken.read_text().replace(
                "speeed", "1")}))
            # frames (bytes) and the new scene may come first, in any number
            deadline, ran = time.monotonic() + 60, False
            while not ran and time.monotonic() < deadline:
                reply = ws.recv(timeout=20)
                ran = isinstance(reply, str) and (
                    '"op": "run", "errors": []' in reply or '"op":"run","errors":[]' in reply)
            assert ran
        assert server.proc.poll() is None
    finally:
        server.stop()


def test_a_bug_making_a_frame_is_reported_and_the_server_goes_on(backend, program, monkeypatch,
                                                                 caplog):
    """In-process: the server's frame loop meets an exception that is no SwarmError."""
    import threading

    import uvicorn
    from websockets.sync.client import connect

    from swarmdsl.studio.server import Studio, bind

    session = Session(program, backend=backend)
    real, calls = Session.frame, []

    def broken_once(self, *args):
        calls.append(1)
        if len(calls) == 1:
            raise ZeroDivisionError("a bug")
        return real(self, *args)

    monkeypatch.setattr(Session, "frame", broken_once)
    sock = bind("127.0.0.1", 0)
    server = uvicorn.Server(uvicorn.Config(Studio(session, "t").app(), log_level="error",
                                           lifespan="off"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    try:
        with connect(f"ws://127.0.0.1:{sock.getsockname()[1]}/ws?token=t",
                     open_timeout=20) as ws:
            ws.send('{"op": "hello"}')
            got = [ws.recv(timeout=20) for _ in range(2)]      # the scene, the report
            assert "internal error: ZeroDivisionError: a bug" in got[1]
            ws.send('{"op": "step"}')
            ticks = []      # the frame that failed may still come, at tick 0, before the step's
            while 1 not in ticks and len(ticks) < 5:
                message = ws.recv(timeout=20)
                if isinstance(message, bytes):
                    ticks.append(wire.decode(message)[0]["tick"])
            assert ticks[-1] == 1 and set(ticks) <= {0, 1}, ticks
            ws.send('{"op": "step"}')       # closed before its reply: no error either
    finally:
        server.should_exit = True
        thread.join(timeout=10)
        sock.close()
    assert [r.getMessage() for r in caplog.records if r.levelname == "ERROR"] == []


def test_an_inspected_agent_shows_its_running_tree_path(backend):
    from tests.studio_server import ROOT

    s = Session(ROOT / "programs" / "aco_bt.swarm", backend=backend)
    s.step(5)
    x, y = s.sim.agents.cols["pos"][0]
    s.inspect_at(x, y, 0.01)
    header, arrays = frame(s, leaf=True)
    path = header["selected"]["path"]
    assert path.startswith("reactive fallback > ") and " > " in path
    assert arrays["leaf"].shape == (header["n"],) and arrays["leaf"].max() > 0


def test_the_export_endpoint_writes_under_the_outputs_folder_only(program, tmp_path):
    out = tmp_path / "exports"
    server = StudioProcess(program, 0, "test-token-studio", "--out", str(out))
    try:
        req = urllib.request.Request(
            f"{server.base}/api/export?token={server.token}",
            data=json.dumps({"video": None, "folder": "/tmp/x", "path": "../x"}).encode(),
            method="POST")
        with urllib.request.urlopen(req, timeout=60) as r:
            result = json.loads(r.read())
        assert result["folder"] == str(out / "walkers-seed0-tick0")
        assert sorted(p.name for p in out.iterdir()) == ["walkers-seed0-tick0"]
        bad = urllib.request.Request(f"{server.base}/api/export?token={server.token}",
                                     data=b'{"video": "avi"}', method="POST")
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(bad, timeout=60)
        refused.value.close()
        assert refused.value.code == 400
    finally:
        server.stop()
