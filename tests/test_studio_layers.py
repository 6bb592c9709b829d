"""The studio's environment layers, as the pygame viewer draws them: a vector field as
arrows and the grid's nodes as dots. The session's frames carry them only when asked
(values equal to the snapshot's), and the page draws them (chromium, when installed)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from swarmdsl.studio import wire
from swarmdsl.studio.session import Session

ROOT = Path(__file__).resolve().parents[1]
MAS = ROOT / "programs" / "mas_environment.swarm"
BOIDS = ROOT / "programs" / "boids.swarm"
WAIT = 60_000      # ms: a first numba compile in the server, on a loaded machine

# a fine, unrefined grid (81 x 41 nodes) with two vector fields
FINE = """
world { size 400 x 200; grid 5; steps 10 }
field wind { twin (pos.x / 400, 0.5) }
field spin { twin (200 - pos.y, pos.x - 200) }
agent a { count 5; place uniform; status s { velocity = wind at pos } }
"""


def frame(session, **layers):
    return wire.decode(session.frame(layers)[0])


@pytest.fixture(scope="module")
def mas(backend):
    session = Session(MAS, backend=backend)
    session.step(3)
    return session


def test_the_frame_carries_the_vector_field_and_grid_nodes_of_a_refined_grid(mas):
    snap = mas.sim.snapshot()
    header, arrays = frame(mas, vectors="current", grid=True)
    assert header["vectors"]["name"] == "current"
    assert (header["vectors"]["nx"], header["vectors"]["ny"]) == (21, 21)   # <= 32: all
    np.testing.assert_array_equal(arrays["vectors"].reshape(21, 21, 2),
                                  snap.vectors["current"].astype(np.float32))
    np.testing.assert_array_equal(arrays["vector_x"], snap.grid_x.astype(np.float32))
    np.testing.assert_array_equal(arrays["vector_y"], snap.grid_y.astype(np.float32))
    # the longest arrow is 0.8 of the grid's spacing (20), as in the viewer
    top = np.hypot(*snap.vectors["current"].reshape(-1, 2).T).max()
    assert header["vectors"]["top"] == pytest.approx(top)
    assert header["vectors"]["scale"] * top == pytest.approx(16.0)
    # every node of the refined grid, not only the base grid's 21 x 21
    assert len(snap.grid_points) > 21 * 21
    np.testing.assert_array_equal(arrays["grid_points"].reshape(-1, 2),
                                  snap.grid_points.astype(np.float32))
    assert "grid_x" not in arrays


def test_layers_off_send_nothing(mas):
    plain = mas.frame({})[0]
    assert mas.frame({"vectors": None, "grid": False})[0] == plain
    header, arrays = wire.decode(plain)
    assert "vectors" not in header
    assert not {"vectors", "vector_x", "vector_y", "grid_points", "grid_x"} & set(arrays)
    scene = mas.scene()
    assert scene["vectors"] == ["current"] and scene["grid"] is True
    # what the layers cost: 3.5 KB of arrows, 10 KB of 1251 refined nodes
    with_vectors = len(mas.frame({"vectors": "current"})[0])
    assert with_vectors - len(plain) < 4 * 21 * 21 * 2 + 4 * 42 + 200


def test_a_fine_grid_is_subsampled_to_32_arrows_a_side_and_sends_its_axes(tmp_path,
                                                                            backend):
    path = tmp_path / "fine.swarm"
    path.write_text(FINE)
    session = Session(path, backend=backend)
    snap = session.sim.snapshot()
    assert snap.grid_points is None and len(snap.grid_x) == 81
    header, arrays = frame(session, vectors="spin", grid=True)
    values = snap.vectors["spin"][::2, ::3]     # rows: ceil(41 / 32) = 2, columns: 3
    assert (header["vectors"]["ny"], header["vectors"]["nx"]) == values.shape[:2] == (21, 27)
    np.testing.assert_array_equal(arrays["vectors"], values.astype(np.float32).reshape(-1))
    np.testing.assert_array_equal(arrays["vector_x"], snap.grid_x[::3].astype(np.float32))
    np.testing.assert_array_equal(arrays["vector_y"], snap.grid_y[::2].astype(np.float32))
    # the grid's two axes (81 + 41 numbers), not its 3,321 nodes
    np.testing.assert_array_equal(arrays["grid_x"], snap.grid_x.astype(np.float32))
    np.testing.assert_array_equal(arrays["grid_y"], snap.grid_y.astype(np.float32))
    assert "grid_points" not in arrays
    # a name the program lacks (renamed in the editor) shows its first vector field
    assert frame(session, vectors="gone")[0]["vectors"]["name"] == "wind"
    assert session.scene()["vectors"] == ["wind", "spin"]


def test_a_program_without_vectors_or_grid_sends_nothing(backend):
    session = Session(BOIDS, backend=backend)
    header, arrays = frame(session, vectors="current", grid=True)
    assert "vectors" not in header and set(arrays) <= {"pos", "heading", "status", "kind",
                                                        "led"}
    scene = session.scene()
    assert scene["vectors"] == [] and scene["grid"] is False


def test_the_notebook_widget_passes_the_layers_on(tmp_path):
    pytest.importorskip("anywidget")
    import swarmdsl

    shutil.copy(MAS, tmp_path / "mas.swarm")
    widget = swarmdsl.show(str(tmp_path / "mas.swarm"))
    widget.sent = []
    widget.send = lambda content, buffers=None: widget.sent.append((content, buffers))
    widget._handle_custom_msg({"op": "layers", "field": None, "vectors": "current",
                               "grid": True}, [])
    widget._handle_custom_msg({"op": "hello"}, [])
    _, arrays = wire.decode(widget.sent[-1][1][0])
    assert {"vectors", "grid_points"} <= set(arrays)


# ---- in chromium ----

def _browser_or_skip():
    chromium = shutil.which("chromium") or "/usr/bin/chromium"
    if not Path(chromium).exists():
        pytest.skip("chromium is not installed (apt-get install chromium); .ci/run "
                    "installs it")
    return chromium, pytest.importorskip("playwright.sync_api")


@pytest.fixture(scope="module")
def browser():
    chromium, sync_api = _browser_or_skip()
    from tests.test_studio_browser import ARGS

    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=chromium, args=ARGS)
        yield b
        b.close()


def _open(browser, program: Path):
    from tests.studio_server import StudioProcess

    server = StudioProcess(program)
    page = browser.new_page(viewport={"width": 1400, "height": 850})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(server.url)
    page.wait_for_function("window.studio && window.studio.frames > 0", timeout=WAIT)
    return server, page, errors


def _count(page, colour, tolerance: int) -> int:
    """Pixels of the view's canvas (its own 640 x 480, not the scaled screenshot) within
    `tolerance` of `colour` in every channel."""
    return page.evaluate("""([c, tol]) => {
        const cv = window.studio.canvas;
        const d = cv.getContext("2d").getImageData(0, 0, cv.width, cv.height).data;
        let n = 0;
        for (let i = 0; i < d.length; i += 4) {
            if (Math.abs(d[i] - c[0]) <= tol && Math.abs(d[i + 1] - c[1]) <= tol &&
                Math.abs(d[i + 2] - c[2]) <= tol) n++;
        }
        return n;
    }""", [colour, tolerance])


def _frame_has(page, name: str, present: bool = True) -> None:
    page.wait_for_function(f"!!(window.studio.frame.arrays.{name}) === {str(present).lower()}",
                           timeout=WAIT)


def test_the_page_draws_arrows_and_grid_nodes(browser, tmp_path, backend):
    shutil.copy(MAS, tmp_path / "mas.swarm")
    server, page, errors = _open(browser, tmp_path / "mas.swarm")
    try:
        arrow = page.evaluate("window.studio.scene.colours.arrow")
        node = page.evaluate("window.studio.scene.colours.grid_point")
        page.select_option("[data-role=field]", "")       # the heatmap off: a plain floor
        _frame_has(page, "field", False)
        _frame_has(page, "vectors")                       # arrows are on at start
        assert page.input_value("[data-role=vectors]") == "current"
        # 441 arrows of several pixels each (1-pixel lines: their edges are blended)
        arrows = _count(page, arrow, 60)
        assert arrows > 21 * 21 * 4
        assert _count(page, node, 0) == 0                 # the grid is off at start
        page.locator("canvas.view").click(position={"x": 2, "y": 2})   # focus the view
        page.keyboard.press("g")
        _frame_has(page, "grid_points")
        assert page.is_checked("[data-role=grid]")
        page.keyboard.press("v")
        _frame_has(page, "vectors", False)
        assert page.input_value("[data-role=vectors]") == ""
        assert _count(page, arrow, 60) < arrows / 5       # the captions' text is left
        assert _count(page, node, 0) > 900                # 1,251 nodes, one pixel each
    finally:
        page.close()
        server.stop()
    assert errors == []


def test_a_program_without_them_hides_the_toggles_and_keeps_drawing(browser, tmp_path,
                                                                     backend):
    shutil.copy(BOIDS, tmp_path / "boids.swarm")
    server, page, errors = _open(browser, tmp_path / "boids.swarm")
    try:
        assert page.is_hidden("[data-role=vectors]")
        assert page.is_hidden("[data-role=grid]")
        page.locator("canvas.view").click(position={"x": 2, "y": 2})
        page.keyboard.press("v")
        page.keyboard.press("g")
        page.click("[data-role=step]")
        page.wait_for_function("window.studio.frame.header.tick >= 1", timeout=WAIT)
        arrays = page.evaluate("Object.keys(window.studio.frame.arrays)")
        assert not {"vectors", "grid_points", "grid_x"} & set(arrays)
    finally:
        page.close()
        server.stop()
    assert errors == []
