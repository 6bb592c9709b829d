"""`swarmdsl.show(...)`: the studio's view, controls, sliders and plots in a notebook cell.

An anywidget whose front end is the page's own `renderer.js` (the view, plots and
controls) with a few lines that put the widget's messages where the page puts its
websocket's: the same binary frames (`wire`), the same controls, answered by the same
`Session`. A finished run's `metrics.parquet` is plotted beside it.

The kernel answers each `ready` with the next frame while playing, so frames come as
fast as the notebook draws them and stop when it stops asking.
"""

from __future__ import annotations

from pathlib import Path

import anywidget
import traitlets

from swarmdsl.errors import SwarmOptionError
from swarmdsl.studio.session import LAYERS, Session

STATIC = Path(__file__).parent / "static"

_GLUE = """
export default {
  render({ model, el }) {
    const root = document.createElement("div");
    el.append(root);
    const core = new StudioCore(root, { send: obj => model.send(obj) });
    const width = model.get("width");
    core.onScene = scene => {
      if (!scene.world) return;
      const [ww, wh] = scene.world;
      core.canvas.width = width;
      core.canvas.height = Math.round(width * wh / ww);
      core.canvas.style.width = width + "px";
    };
    const onMessage = (msg, buffers) => {
      if (msg.type === "frame") {
        const b = buffers[0];
        const view = b instanceof ArrayBuffer ? new Uint8Array(b)
          : new Uint8Array(b.buffer, b.byteOffset, b.byteLength);
        core.onFrame(view.slice().buffer);      // its own buffer: arrays start aligned
      } else {
        core.onText(msg);
      }
    };
    model.on("msg:custom", onMessage);
    const recorded = () => core.showRecorded(model.get("recorded"));
    model.on("change:recorded", recorded);
    recorded();
    core.hello();
    return () => {
      model.off("msg:custom", onMessage);
      model.send({ op: "pause" });
    };
  },
};
"""


def _esm() -> str:
    return (STATIC / "renderer.js").read_text(encoding="utf-8") + _GLUE


class StudioWidget(anywidget.AnyWidget):
    """The view of one `Session` in a notebook."""

    _esm = traitlets.Unicode(_esm()).tag(sync=True)
    _css = traitlets.Unicode((STATIC / "studio.css").read_text(encoding="utf-8")).tag(
        sync=True)
    width = traitlets.Int(560).tag(sync=True)       # the view's width in pixels
    recorded = traitlets.Dict({}).tag(sync=True)    # a finished run's metrics, by name

    def __init__(self, session: Session, recorded: dict | None = None, width: int = 560):
        super().__init__(width=width, recorded=recorded or {})
        self.session = session
        self.layers: dict = {"field": None}
        self.since = -1
        self.credits = 0            # frames the view asked for and was not sent
        self.seen = -1
        self.scene_version = -1
        self.on_msg(self._on_msg)

    def _on_msg(self, _widget, content, _buffers) -> None:
        if not isinstance(content, dict):
            return
        op = content.get("op")
        if op == "ready":
            self.credits = 1
        elif op == "layers":
            self.layers = {k: content.get(k) for k in LAYERS}
            self.seen = -1
        elif op == "hello":
            self.scene_version, self.seen, self.credits = -1, -1, 1
        else:
            self.send(self.session.control(content))
        self.pump()

    def pump(self) -> None:
        """Send what the view lacks: the scene when it changed, a frame when it asked
        for one and the run moved (or plays)."""
        session = self.session
        if session.scene_version != self.scene_version:
            scene = session.scene()
            self.scene_version = scene["version"]
            history = scene.get("history") or []
            self.since = history[-1][0] if history else -1
            self.send(scene)
        if self.credits <= 0:
            return
        session.advance()
        if session.version == self.seen:
            return
        self.credits -= 1
        self.seen = session.version
        data, self.since = session.frame(self.layers, self.since)
        self.send({"type": "frame"}, buffers=[data])


def recorded_metrics(folder) -> dict:
    """`metrics.parquet` of a run folder as {name: [[tick, value], ...]} (empty without)."""
    path = Path(folder) / "metrics.parquet"
    if not path.exists():
        return {}
    import pyarrow.parquet as pq

    table = pq.read_table(path).to_pydict()
    out: dict[str, list] = {}
    for tick, name, value in zip(table["tick"], table["name"], table["value"], strict=True):
        out.setdefault(name, []).append([int(tick), value])
    for rows in out.values():
        rows.sort(key=lambda r: r[0])
    return out


def show(target, *, seed: int | None = None, width: int = 560) -> StudioWidget:
    """The studio view of `target` in a notebook: a `.swarm` path, a Program from
    `swarmdsl.load_program`, or a `Run` (its program and seed, and, once it has run with
    `out=`, the plots of its `metrics.parquet`)."""
    from swarmdsl.runtime.arguments import whole

    if seed is not None:
        seed = whole("seed", seed, 0, 2**63 - 1)
    width = whole("width", width, 160, 4096)
    recorded = {}
    if hasattr(target, "sim") and hasattr(target, "program"):          # a Run
        run = target
        session = Session.of_program(run.program, run.sim.seed if seed is None else seed)
        if run.out is not None:
            recorded = recorded_metrics(Path(run.out))
    elif hasattr(target, "source") and hasattr(target, "info"):        # a Program
        session = Session.of_program(target, seed or 0)
    elif isinstance(target, str | Path):
        if not Path(target).is_file():
            raise SwarmOptionError(f"show: no such program file: {target}")
        session = Session(target, seed=seed or 0)
    else:
        raise SwarmOptionError(f"show takes a .swarm path, a Program or a Run, got "
                               f"{type(target).__name__}")
    return StudioWidget(session, recorded, width)
