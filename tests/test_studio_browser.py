"""`swarmdsl studio` in a real browser: Debian's chromium driven by playwright, against a
real server process, as a user would click it. Skipped only where chromium is missing
(CI installs it: .ci/run)."""

from __future__ import annotations

import shutil
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from tests.studio_server import StudioProcess, program_copy

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
if not Path(CHROMIUM).exists():
    pytest.skip("chromium is not installed (apt-get install chromium); .ci/run installs it",
                allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api")

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]
WAIT = 20_000       # ms: a loaded two-core machine


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


@pytest.fixture
def program(tmp_path):
    return program_copy(tmp_path)


@pytest.fixture
def studio(program):
    server = StudioProcess(program)
    yield server
    server.stop()


@pytest.fixture
def page(browser, studio):
    page = browser.new_page(viewport={"width": 1400, "height": 850})
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(studio.url)
    page.wait_for_function("window.studio && window.studio.frames > 0", timeout=WAIT)
    yield page
    page.close()
    assert errors == []


def tick(page) -> int:
    return page.evaluate("window.studio.frame.header.tick")


def wait_tick(page, at_least: int) -> int:
    page.wait_for_function(f"window.studio.frame.header.tick >= {at_least}", timeout=WAIT)
    return tick(page)


def canvas_pixels(page, selector: str = "canvas.view") -> np.ndarray:
    from io import BytesIO

    from PIL import Image

    png = page.locator(selector).screenshot()
    return np.asarray(Image.open(BytesIO(png)).convert("RGB"))


def test_the_page_draws_the_agents(page):
    pixels = canvas_pixels(page)
    colour = page.evaluate("window.studio.scene.palette[0]")   # the one status's colour
    agent = (np.abs(pixels.astype(int) - colour).sum(axis=2) <= 30)
    assert agent.sum() >= 300 * 4         # 300 walkers, several pixels each
    ys, xs = np.nonzero(agent)            # spread over the world, not one blot
    assert xs.max() - xs.min() > pixels.shape[1] / 2
    assert ys.max() - ys.min() > pixels.shape[0] / 2


def test_step_and_play_advance_the_tick(page):
    assert tick(page) == 0
    page.click("[data-role=step]")
    assert wait_tick(page, 1) == 1
    page.click("[data-role=play]")
    wait_tick(page, 10)
    page.click("[data-role=play]")       # pause
    page.wait_for_function("!window.studio.frame.header.playing", timeout=WAIT)
    paused = tick(page)
    time.sleep(0.5)
    assert tick(page) == paused


def test_a_slider_changes_the_param_the_run_uses(page):
    page.click("[data-role=step]")
    wait_tick(page, 1)
    box = page.locator("[data-role=value-cruise]")
    box.fill("5")
    box.press("Enter")
    page.wait_for_function("window.studio.scene.set_line.includes('cruise=5')", timeout=WAIT)
    page.click("[data-role=step]")
    wait_tick(page, 2)                   # the run went on: cruise is not a shape
    # click an agent: the inspector shows it moving at the new speed
    x, y = page.evaluate("""() => {
        const s = window.studio, pos = s.frame.arrays.pos, t = s.renderer.transform();
        return [t.ox + pos[0] * t.s, t.oy + (t.wh - pos[1]) * t.s];
    }""")
    page.locator("canvas.view").click(position={"x": x, "y": y})
    page.wait_for_function("window.studio.frame.header.selected", timeout=WAIT)
    vel = page.evaluate("window.studio.frame.header.selected.vars.vel")
    assert np.hypot(*vel) == pytest.approx(5.0)


def type_text(page, text: str) -> None:
    """Replace the editor's text as a user would: select all, type (CodeMirror's
    editor stands in for the textarea #source, which stays the page's model)."""
    page.click(".cm-content")
    page.keyboard.press("Control+A")
    page.keyboard.insert_text(text)


def test_an_error_typed_in_the_editor_is_shown_at_its_line(page):
    text = page.input_value("#source")
    lines = text.split("\n")
    row = next(i for i, s in enumerate(lines) if "deposit(warmth" in s)
    lines[row] = lines[row].replace("deposit(warmth, 1)", "deposit(warmt, 1)")
    type_text(page, "\n".join(lines))
    page.wait_for_selector("#diagnostics .error", timeout=WAIT)
    shown = page.inner_text("#diagnostics .error")
    assert shown.startswith(f"{row + 1}:")
    assert "warmt" in shown
    assert page.get_attribute(f"#gutter div[data-line='{row + 1}']", "class") == "error"
    type_text(page, text)               # fixed: the diagnostics go
    page.wait_for_selector("#diagnostics .error", state="detached", timeout=WAIT)


def test_a_failed_runs_errors_go_for_good_once_the_text_is_fixed(page):
    text = page.input_value("#source")
    type_text(page, text.replace("* cruise", "* cruisezz"))
    page.press(".cm-content", "Control+Enter")
    page.wait_for_selector("#diagnostics .error:has-text('cruisezz')", timeout=WAIT)
    type_text(page, text)          # fixed, not run: the check clears the errors
    page.wait_for_selector("#diagnostics .error", state="detached", timeout=WAIT)
    box = page.locator("[data-role=value-cruise]")      # a slider move: a new scene
    box.fill("5")
    box.press("Enter")
    page.wait_for_function("window.studio.scene.set_line.includes('cruise=5')", timeout=WAIT)
    assert page.locator("#diagnostics .error").count() == 0
    page.reload()                       # a page reloaded: the session's text, no errors
    page.wait_for_function("window.studio && window.studio.frames > 0", timeout=WAIT)
    assert page.input_value("#source") == text
    assert page.locator("#diagnostics .error").count() == 0


def test_unsaved_edits_are_marked_until_saved_or_reloaded(page, program):
    assert page.locator("#unsaved").is_hidden()
    text = page.input_value("#source")
    edited = text.replace("deposit(warmth, 1)", "deposit(warmth, 2)")
    type_text(page, edited)
    assert page.locator("#unsaved").is_visible() and page.title().startswith("●")
    page.press(".cm-content", "Control+s")
    page.wait_for_selector("#unsaved", state="hidden", timeout=WAIT)
    assert program.read_text() == edited and not page.title().startswith("●")
    type_text(page, edited + "# more\n")
    assert page.locator("#unsaved").is_visible()
    page.once("dialog", lambda dialog: dialog.accept())    # "drop the unsaved edits?"
    page.click("#reload")
    page.wait_for_selector("#unsaved", state="hidden", timeout=WAIT)
    assert page.input_value("#source") == edited


def test_the_reproduce_line_follows_the_text_on_screen(page, program):
    line = "window.studio.scene.set_line"
    text = page.input_value("#source")
    edited = text.replace("param cruise = 2 in", "param cruise = 1.5 in")
    type_text(page, edited)        # a param's value edited in the text, and run
    page.press(".cm-content", "Control+Enter")
    page.wait_for_function(f"{line}.endsWith('--set cruise=1.5')", timeout=WAIT)
    assert "save-first" not in page.get_attribute(".set-line", "class")
    type_text(page, edited.replace("deposit(warmth, 1)", "deposit(warmth, 2)"))
    page.press(".cm-content", "Control+Enter")      # a rule edited: no --set says that
    page.wait_for_function(f"{line}.startsWith('save first')", timeout=WAIT)
    assert "save-first" in page.get_attribute(".set-line", "class")
    page.press(".cm-content", "Control+s")          # saved: the file is the run
    page.wait_for_function(f"{line} === 'swarmdsl run {program}'", timeout=WAIT)
    assert "save-first" not in page.get_attribute(".set-line", "class")


def test_the_metric_plots_grow_while_it_runs(page):
    names = page.evaluate("window.studio.scene.metrics")
    assert names == ["polarisation", "mean_speed"]
    before = page.evaluate("window.studio.plots.map(p => p.points())")
    page.click("[data-role=play]")
    wait_tick(page, 20)
    page.click("[data-role=play]")
    after = page.evaluate("window.studio.plots.map(p => p.points())")
    assert all(a >= b + 20 for a, b in zip(after, before, strict=True))
    speed = page.evaluate("window.studio.plots[1].series[0].slice(-1)[0]")
    assert speed == pytest.approx(2.0)


def test_requests_without_the_token_are_refused(studio):
    for path in ("/", "/static/studio.js", "/api/check"):
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(studio.base + path, timeout=10)
        refused.value.close()
        assert refused.value.code == 403
    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.urlopen(studio.base + "/?token=wrong", timeout=10)
    refused.value.close()
    assert refused.value.code == 403
    with urllib.request.urlopen(studio.url, timeout=10) as ok:
        assert ok.status == 200
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    ws_url = studio.base.replace("http", "ws", 1) + "/ws"
    for query in ("", "?token=wrong"):
        with pytest.raises(InvalidStatus) as refused:
            connect(ws_url + query, open_timeout=10).close()
        assert refused.value.response.status_code == 403
    with connect(f"{ws_url}?token={studio.token}", open_timeout=10) as ws:
        ws.send('{"op": "hello"}')
        assert '"type":"scene"' in ws.recv(timeout=10).replace(" ", "")


def test_the_page_reconnects_after_a_server_restart(browser, program):
    server = StudioProcess(program)
    page = browser.new_page()
    try:
        page.goto(server.url)
        page.wait_for_function("window.studio && window.studio.frames > 0", timeout=WAIT)
        server.stop()
        page.wait_for_function("document.getElementById('connection').className === 'lost'",
                               timeout=WAIT)
        server = StudioProcess(program, server.port)
        page.wait_for_function("document.getElementById('connection').textContent "
                               "=== 'connected'", timeout=WAIT)
        frames = page.evaluate("window.studio.frames")
        page.click("[data-role=step]")
        page.wait_for_function(f"window.studio.frames > {frames} && "
                               "window.studio.frame.header.tick === 1", timeout=WAIT)
        # the restarted server's run, stepped from the page it never served before
        assert page.evaluate("window.studio.frame.header.tick") == 1
        assert page.text_content("#connection") == "connected"
    finally:
        page.close()
        server.stop()


# The notebook's side of a widget, in the page: anywidget's `model` (get, on, off, send)
# over playwright's bridge to the kernel's side, the Python widget itself.
FAKE_NOTEBOOK = """async ([esm, traits]) => {
  const url = URL.createObjectURL(new Blob([esm], {type: "text/javascript"}));
  const widget = (await import(url)).default;
  const listeners = {};
  const bytes = text => {
    const s = atob(text), u = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) u[i] = s.charCodeAt(i);
    return new DataView(u.buffer);
  };
  const model = {
    get: key => traits[key],
    on: (event, fn) => { (listeners[event] = listeners[event] || []).push(fn); },
    off: () => {},
    send: async content => {
      for (const [reply, buffers] of await window.toKernel(content)) {
        (listeners["msg:custom"] || []).forEach(fn => fn(reply, buffers.map(bytes)));
      }
    },
  };
  widget.render({model, el: document.getElementById("cell")});
}"""


def test_the_notebook_widget_draws_and_plays_in_the_browser(browser, program):
    import base64

    import swarmdsl

    w = swarmdsl.show(program, width=400)
    out = []
    w.send = lambda content, buffers=None: out.append(
        [content, [base64.b64encode(bytes(b)).decode() for b in buffers or []]])

    def to_kernel(content):
        w._handle_custom_msg(content, [])
        replies = list(out)
        out.clear()
        return replies

    page = browser.new_page()
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.expose_function("toKernel", to_kernel)
        page.set_content("<div id='cell'></div>")
        page.add_style_tag(content=w._css)
        page.evaluate(FAKE_NOTEBOOK, [w._esm, {"width": w.width, "recorded": w.recorded}])
        view = "document.querySelector('#cell canvas.view')"
        page.wait_for_function(f"{view} && {view}.dataset.frames > 0", timeout=WAIT)
        page.click("#cell [data-role=play]")
        page.wait_for_function(f"{view}.dataset.tick >= 5", timeout=WAIT)
        assert w.session.sim.tick >= 5
        pixels = canvas_pixels(page, "#cell canvas.view")
        colour = w.session.scene()["palette"][0]
        assert (np.abs(pixels.astype(int) - colour).sum(axis=2) <= 30).sum() >= 300 * 4
        assert errors == []
    finally:
        page.close()


def test_a_big_swarm_is_drawn_as_pixel_marks(browser, program):
    """Above 3,000 agents the page writes marks into a pixel buffer (headings as bytes)."""
    from tests.studio_server import TOKEN

    server = StudioProcess(program, 0, TOKEN, "--set", "n=5000")
    page = browser.new_page(viewport={"width": 1400, "height": 850})
    try:
        page.goto(server.url)
        page.wait_for_function("window.studio && window.studio.frames > 0", timeout=WAIT)
        assert page.evaluate("!!window.studio.frame.arrays.heading8")
        page.click("[data-role=step]")
        wait_tick(page, 1)
        pixels = canvas_pixels(page)
        colour = page.evaluate("window.studio.scene.palette[0]")
        marked = np.abs(pixels.astype(int) - colour).sum(axis=2) <= 30
        assert marked.sum() >= 5000 * 3          # a 3x3 body each, some overlapping
    finally:
        page.close()
        server.stop()


def test_the_viewers_keys_work_on_the_page(page):
    page.locator("canvas.view").click(position={"x": 2, "y": 2})     # focus off the editor
    page.keyboard.press(".")
    wait_tick(page, 1)
    assert page.evaluate("window.studio.opts.field") == "warmth"     # the first, as shown
    page.keyboard.press("f")
    page.wait_for_function("!window.studio.frame.header.field", timeout=WAIT)
    page.keyboard.press("f")
    page.wait_for_function("window.studio.frame.header.field", timeout=WAIT)
    page.keyboard.press("k")
    assert page.evaluate("window.studio.opts.kind")
    page.keyboard.press("+")
    page.wait_for_function("window.studio.frame.header.speed === 2", timeout=WAIT)
