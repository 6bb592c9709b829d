"""One program watched in the studio: its text, its param values, the running simulation
and what the page plots. No web code here: the server and the notebook widget both
drive a `Session`, so the page and the widget show the same run the same way.

Every change goes through `lock` (the simulation steps in a worker thread while the
page sends controls). Nothing a program does stops the session: a program with errors
keeps the last good run on screen with its diagnostics beside it, and a run that
faults pauses with the located message.
"""

from __future__ import annotations

import bisect
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmdsl.errors import SwarmCheckError, SwarmError, SwarmOptionError
from swarmdsl.studio import frame_arrays, wire
from swarmdsl.studio import params as param_controls
from swarmdsl.studio.frame_arrays import plain

SPEEDS = (1 / 16, 1 / 8, 1 / 4, 1 / 2, 1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024)
HISTORY_POINTS = 2000       # plot points sent to a page that (re)connects
SPLAT_ABOVE = 3000          # as the viewer's RenderOptions.splat_above and renderer.js
LAYERS = ("field", "vectors", "grid", "links", "believed", "leaf")   # a page's choices


def diagnostics(err: SwarmError) -> list[dict]:
    """A compile error as the page lists it: one entry per checker diagnostic."""
    found = err.diagnostics if isinstance(err, SwarmCheckError) else [err]
    return [diagnostic(d) for d in found]


def diagnostic(d: SwarmError) -> dict:
    span = d.span
    return {"severity": d.severity, "message": d.message, "hint": d.hint,
            "line": span.line if span else None, "col": span.col if span else None,
            "end_line": span.end_line if span else None,
            "end_col": span.end_col if span else None, "text": str(d)}


def check_text(text: str, path: Path, overrides: dict[str, str]) -> list[dict]:
    """The checker's diagnostics for `text` as if it were the file at `path` (errors and
    warnings; empty when clean). Compiled with the reference lowering: it never runs."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.compiler.lowering import REFERENCE

    try:
        program = compile_source(text, str(path), _known(text, path, overrides),
                                 Path(path).resolve().parent, lowering=REFERENCE)
    except SwarmError as err:
        return diagnostics(err)
    return [diagnostic(w) for w in program.info.warnings]


def _known(text: str, path: Path, overrides: dict[str, str]) -> dict[str, str]:
    """The overrides that still name a param of `text`: a param removed in the editor
    drops its slider value instead of failing every check after it."""
    if not overrides:
        return overrides
    from swarmdsl.compiler.parse import parse

    try:
        tree = parse(text, str(path))
    except SwarmError:
        return {}
    names = {getattr(d, "name", None) for d in tree.decls if type(d).__name__ == "ParamDecl"}
    return {k: v for k, v in overrides.items() if k in names}


@dataclass
class History:
    """Per-tick samples for the plots: every metric and the live count of each status."""

    metric_names: list[str] = field(default_factory=list)
    status_names: list[str] = field(default_factory=list)
    ticks: list[int] = field(default_factory=list)
    rows: list[list[float | None]] = field(default_factory=list)  # metrics then counts

    def add(self, tick: int, metrics: np.ndarray, counts: np.ndarray) -> None:
        if self.ticks and tick <= self.ticks[-1]:
            return
        row = [None if not np.isfinite(v) else float(v) for v in metrics]
        self.ticks.append(int(tick))
        self.rows.append(row + [int(c) for c in counts])

    def since(self, tick: int, limit: int = HISTORY_POINTS) -> list[list]:
        """Samples after `tick`, at most `limit` of them spread evenly (the last kept)."""
        start = bisect.bisect_right(self.ticks, tick)
        idx = range(start, len(self.ticks))
        if len(idx) > limit:
            idx = np.unique(np.linspace(start, len(self.ticks) - 1, limit).astype(int))
        return [[self.ticks[i], *self.rows[i]] for i in idx]


class Session:
    """The program at `path`, compiled with `overrides` (`--set` texts) and run with
    `seed`. `out` is the outputs folder exports go under."""

    def __init__(self, path, overrides: dict[str, str] | None = None, seed: int = 0,
                 out: Path | None = None, backend: str | None = None,
                 text: str | None = None):
        self.path = Path(path)
        self.file = self.path.resolve()
        self.out = Path(out) if out is not None else self.file.parent / f"{self.file.stem}-studio"
        self.backend = backend
        self.overrides = dict(overrides or {})
        self.seed = int(seed)
        self.lock = threading.RLock()
        try:
            if text is None:
                text = self.file.read_text(encoding="utf-8")
            self.text = text.removeprefix("\ufeff")
        except UnicodeDecodeError:
            raise SwarmOptionError(f"{path}: not UTF-8 text") from None
        except OSError as exc:
            raise SwarmOptionError(f"{path}: cannot read it ({exc.strerror})") from None
        self.program = None
        self.driver = None      # steps the run (`runtime/driver.py`); None: no run
        # the editor's text as the session last saw it (run, checked or reloaded) and
        # the checker's diagnostics of that text: a scene shows only these, so errors
        # of a text since fixed never come back
        self.draft = self.text
        self.diagnostics: list[dict] = []
        self._reproduce_key = None
        self._reproduce = None
        self.fault: str | None = None     # a run that stopped with an error
        self.playing = False
        self.speed = 1.0
        self._owed = 0.0                  # fractions of a tick at speeds below 1
        self.selected: int | None = None  # the inspected agent's id
        self.changed_at: int | None = None  # a param changed mid-run at this tick
        self.history = History()
        self.version = 0                  # bumped by every change a page must redraw
        self.scene_version = 0            # bumped when the scene (names, params) changes
        self.run_text(self.text)

    @classmethod
    def of_program(cls, program, seed: int = 0, backend: str | None = None) -> Session:
        """A session of a compiled Program (`swarmdsl.load_program`): its text, and the
        params it was compiled with as overrides of the text's own values."""
        from swarmdsl.compiler import compile_source
        from swarmdsl.compiler.lowering import REFERENCE
        from swarmdsl.runtime.arguments import param_text

        own = compile_source(program.source, program.filename, {}, program.program_dir,
                             lowering=REFERENCE).params
        overrides = {name: param_text(value) for name, value in program.params.items()
                     if name in own and repr(own[name]) != repr(value)}
        return cls(program.filename, overrides, seed, backend=backend, text=program.source)

    # ---- compiling ----
    def compile(self, text: str, overrides: dict[str, str]):
        from swarmdsl.compiler import compile_source

        return compile_source(text, str(self.path), overrides, self.file.parent)

    def run_text(self, text: str) -> list[dict]:
        """Compile `text` (the editor's) and restart on it; on errors keep the old run
        and return the diagnostics."""
        with self.lock:
            self.draft = text
            overrides = _known(text, self.path, self.overrides)
            try:
                program = self.compile(text, overrides)
            except SwarmError as err:
                self.diagnostics = diagnostics(err)
                self._changed(scene=True)
                return self.errors
            self.text, self.overrides, self.program = text, overrides, program
            self.diagnostics = [diagnostic(w) for w in program.info.warnings]
            self.reset()
            return []

    def check(self, text: str) -> list[dict]:
        """The checker's diagnostics of `text`, the editor's new text (not run): from
        now on the scenes show these."""
        with self.lock:
            overrides = dict(self.overrides)
        found = check_text(text, self.path, overrides)
        with self.lock:
            self.draft, self.diagnostics = text, found
        return found

    def reload(self) -> str:
        """Read the file again and run it with the params' values given so far (the
        editor's unsaved edits are dropped); returns its text."""
        text = self.saved_text()
        if text is None:
            raise SwarmOptionError(f"{self.path.name}: cannot read it")
        self.run_text(text)
        return text

    def saved_text(self) -> str | None:
        """The program's file as it is on disk now (None: unreadable or not text)."""
        try:
            return self.file.read_text(encoding="utf-8").removeprefix("\ufeff")
        except (OSError, UnicodeDecodeError):
            return None

    def saved(self) -> None:
        """The file was written: the scenes' unsaved mark and Reproduce line change."""
        with self.lock:
            self._changed(scene=True)

    @property
    def errors(self) -> list[dict]:
        """The errors of the editor's text (`draft`): empty when it compiles."""
        return [d for d in self.diagnostics if d.get("severity") == "error"]

    @property
    def warnings(self) -> list[dict]:
        return [d for d in self.diagnostics if d.get("severity") != "error"]

    # ---- the run ----
    @property
    def sim(self):
        """The simulation on screen (None: no run, the program has errors)."""
        return None if self.driver is None else self.driver.sim

    def reset(self) -> None:
        """Tick 0 again: the same program, params and seed."""
        from swarmdsl.runtime.driver import Driver

        with self.lock:
            self.fault, self.selected, self.changed_at = None, None, None
            self.driver = None
            if self.program is None:
                return self._changed(scene=True)
            try:
                program = self.program
                work = sum(k.count for k in program.kinds) * program.world.steps
                # no end (play goes on past the program's steps) and no stop checks:
                # the page pauses the run, a signal stops the server; the plots take
                # one sample a frame (`observe`), not one a tick
                driver = Driver(self._simulation(program, self.backend, work), None,
                                every=None, stops=False)
                driver.observers.append(_Plots(self))
                self.driver = driver
                self.history = History(self._metric_names(), list(program.status_display))
                driver.start()
            except SwarmError as err:
                self.fault = err.with_source(self.program.source).render()
                self.playing = False
            except Exception as exc:    # a bug in swarmdsl must not stop the server
                self._internal(exc)
            self._changed(scene=True)

    def _simulation(self, program, backend: str | None, work=None):
        from swarmdsl.runtime.simulation import Simulation

        sim = Simulation(program, self.seed, backend=backend, work=work)
        if getattr(program, "tree_index", None):
            from swarmdsl.runtime.trees import record_active_leaf

            record_active_leaf(sim)     # the inspector's running tree path
        return sim

    def set_seed(self, seed: int) -> None:
        from swarmdsl.runtime.arguments import whole

        seed = whole("seed", seed, 0, 2**63 - 1)
        with self.lock:
            self.seed = int(seed)
            self.reset()

    def set_speed(self, speed: float) -> None:
        with self.lock:
            self.speed = min(SPEEDS, key=lambda s: abs(np.log2(s) - np.log2(max(speed, 1e-3))))
            self._owed = 0.0
            self._changed()

    def set_playing(self, playing: bool) -> None:
        with self.lock:
            self.playing = bool(playing) and self.sim is not None and self.fault is None
            self._changed()

    def step(self, ticks: int = 1) -> None:
        """Advance `ticks` ticks (a fault pauses the run and is kept in `fault`). The
        plots take the last of them: one sample per frame drawn, so at 64 ticks a frame
        the metrics cost what one tick's do."""
        with self.lock:
            driver = self.driver
            if driver is not None and self.fault is None:
                driver.attempt(lambda: (driver.run(int(ticks)), driver.observe()))
                if isinstance(driver.error, KeyboardInterrupt):
                    raise driver.error
                if isinstance(driver.error, SwarmError):
                    self.fault = driver.fault.render()
                    self.playing = False
                elif driver.fault is not None:  # a bug in swarmdsl: one line, no trace
                    self.fault = str(driver.fault)
                    self.playing = False
            self._changed()

    def advance(self) -> None:
        """One frame's worth of ticks while playing (`speed` ticks per frame)."""
        with self.lock:
            if not self.playing:
                return
            self._owed += self.speed
            ticks = int(self._owed)
            self._owed -= ticks
            if ticks:
                self.step(ticks)
                if self.sim is not None and self.sim.tick == self.program.world.steps:
                    self.playing = False    # the program's own end; play goes on past it

    def set_param(self, name: str, value) -> dict:
        """Give param `name` a new value. A value that changes array shapes (a count,
        the world's size or grid) restarts the run; any other applies from the next
        tick, the run going on from where it is. Returns {"reset": bool} or
        {"errors": [...]} (the value refused, nothing changed)."""
        with self.lock:
            if self.program is None or name not in self.program.params:
                return {"errors": [{"severity": "error", "message": f"no param `{name}`",
                                    "text": f"error: no param `{name}`"}]}
            overrides = {**self.overrides, name: param_controls.value_text(value)}
            try:
                program = self.compile(self.text, overrides)
            except SwarmError as err:
                return {"errors": diagnostics(err)}
            old, self.program, self.overrides = self.program, program, overrides
            if self.sim is None or self.fault is not None or _shapes(old) != _shapes(program):
                self._recheck()
                self.reset()
                return {"reset": True}
            try:    # the state carried as a checkpoint carries it (`checkpoint.carry`)
                from swarmdsl.runtime.checkpoint import carry

                new = self._simulation(program, self.backend or self.sim.backend.name)
                self.driver.switch(carry(self.sim, new))
            except (SwarmError, KeyError, ValueError):
                self._recheck()
                self.reset()        # the state does not fit the new program: start over
                return {"reset": True}
            if self.sim.tick:
                self.changed_at = self.sim.tick
            self._recheck()
            self._changed(scene=True)
            return {"reset": False}

    def control(self, op: dict) -> dict:
        """One control from the page or the widget ({"op": NAME, ...}); the reply to
        send back. A bad control is an error in the reply, never an exception."""
        name = op.get("op")
        try:
            if name in ("play", "pause"):
                self.set_playing(name == "play")
            elif name == "step":
                self.step(min(max(int(op.get("n", 1)), 1), 10_000))
            elif name == "speed":
                self.set_speed(float(op["value"]))
            elif name == "reset":
                self.reset()
            elif name == "seed":
                self.set_seed(int(op["value"]))
            elif name == "param":
                return {"type": "result", "op": "param", "name": op["name"],
                        **self.set_param(str(op["name"]), op["value"])}
            elif name == "run":
                text = op.get("text")
                if not isinstance(text, str):
                    raise ValueError("run needs the program text as `text`")
                return {"type": "result", "op": "run", "errors": self.run_text(text)}
            elif name == "reload":
                text = self.reload()
                return {"type": "result", "op": "reload", "text": text,
                        "errors": self.errors}
            elif name == "inspect":
                chosen = self.inspect_at(float(op["x"]), float(op["y"]),
                                         float(op.get("reach", 10)))
                return {"type": "result", "op": "inspect", "id": chosen}
            else:
                raise ValueError(f"unknown control {name!r}")
        except (ValueError, TypeError, KeyError, OverflowError, SwarmError) as exc:
            text = exc.message if isinstance(exc, SwarmError) else str(exc)
            return {"type": "result", "op": name, "errors": [
                {"severity": "error", "message": text, "text": text}]}
        return {"type": "result", "op": name}

    # ---- what the page shows ----
    def scene(self) -> dict:
        """Everything that changes only with the program or its params (JSON)."""
        from swarmdsl.viz import layers as viz_layers
        from swarmdsl.viz import palette
        from swarmdsl.viz.palette import colormap_lut, status_palette

        with self.lock:
            program = self.program
            out = {"type": "scene", "file": self.path.name, "text": self.text,
                   "draft": self.draft, "saved": self.saved_text(),
                   "errors": self.errors, "warnings": self.warnings, "fault": self.fault,
                   "seed": self.seed, "speed": self.speed, "playing": self.playing,
                   "speeds": list(SPEEDS), "version": self.scene_version}
            if program is None:
                return out
            names = list(program.status_display)
            snap = self.sim.snapshot() if self.sim is not None else None
            out.update({
                "world": [program.world.width, program.world.height],
                "steps": program.world.steps,
                "wraps": bool(snap.wraps) if snap else False,
                "status_names": names, "kind_names": [k.name for k in program.kinds],
                "palette": status_palette(max(len(names), 1)).tolist(),
                "kind_palette": status_palette(max(len(program.kinds), 1)).tolist(),
                "metrics": self.history.metric_names,
                "params": [c.as_json() for c in param_controls.controls(program,
                                                                        self.overrides)],
                "set_line": self.set_line(),
                "set_line_exact": self.reproduce().exact,
                "changed_at": self.changed_at,
                "fields": list(snap.fields) if snap else [],
                "vectors": list(snap.vectors) if snap else [],
                "grid": bool(snap) and (snap.grid_points is not None
                                        or snap.grid_x is not None),
                "lut": colormap_lut("magma", 0.75).tolist(),
                "colours": {"background": palette.BACKGROUND, "letterbox": palette.LETTERBOX,
                            "border": palette.BORDER, "link": palette.LINK_COLOUR,
                            "belief": palette.BELIEF_LINE, "text": palette.TEXT,
                            "regions": palette.REGION_COLOURS,
                            "region": palette.REGION_DEFAULT, "no_leaf": palette.NO_LEAF,
                            "arrow": viz_layers.ARROW, "grid_point": viz_layers.GRID_POINT},
                "leaf_palette": status_palette(max(len(snap.tree_leaf_names) - 1, 1)
                                               ).tolist() if snap else [],
                "regions": snap.regions if snap else [],
                "leaf_names": list(snap.tree_leaf_names) if snap else [],
                "history": self.history.since(-1),
            })
            return out

    def set_line(self) -> str:
        """The Reproduce line: the command making the run on screen, or why none does."""
        return self.reproduce().line

    def reproduce(self):
        """The Reproduce line of the run on screen against the file on disk now
        (`reproduce.py`), remembered while neither changes."""
        from swarmdsl.studio.reproduce import Reproduce, reproduce

        with self.lock:
            if self.program is None:
                return Reproduce("nothing runs yet: the program has errors", False)
            disk = self.saved_text()
            key = (disk, self.text, tuple(self.overrides.items()), self.seed)
            if key != self._reproduce_key:
                self._reproduce = reproduce(self.path, disk, self.text,
                                            self.program.params, self.overrides, self.seed)
                self._reproduce_key = key
            return self._reproduce

    def frame(self, layers: dict | None = None, since: int = -1) -> tuple[bytes, int]:
        """The current tick as one binary message (`wire`) with the plot samples after
        tick `since`, and the last tick those samples reach (the next call's `since`).
        `layers`: {"field": name or None, "vectors": name or None, "grid", "links",
        "believed", "leaf"} (`LAYERS`; the others booleans, absent is off)."""
        layers = layers or {}
        with self.lock:
            header = {"tick": 0, "n": 0, "playing": self.playing, "speed": self.speed,
                      "version": self.version, "scene_version": self.scene_version,
                      "fault": self.fault, "selected": None, "samples": []}
            if self.sim is None:
                return wire.encode(header, []), since
            snap = self.sim.snapshot()
            header["samples"] = self.history.since(since)
            reached = self.history.ticks[-1] if self.history.ticks else since
            selected = self._selected(snap)
        n = len(snap.ids)
        header.update(tick=int(snap.tick), n=n, selected=selected)
        if n > SPLAT_ABOVE:     # drawn as pixel marks with 8 noses: a byte is plenty
            turn = np.mod(np.nan_to_num(snap.heading), 2 * np.pi) * (128 / np.pi)
            heading = ("heading8", np.rint(turn).astype(np.int64).astype(np.uint8))
        else:
            heading = ("heading", snap.heading.astype(np.float32))
        arrays = [("pos", snap.pos.astype(np.float32).reshape(-1)), heading,
                  ("status", snap.status.astype(
                      np.uint8 if len(snap.status_names) <= 256 else np.uint16)),
                  ("kind", snap.kind.astype(np.uint8))]
        if snap.led is not None:
            arrays.append(("led", np.asarray(snap.led, np.uint8).reshape(-1)))
        if layers.get("leaf") and snap.tree_leaf is not None:
            arrays.append(("leaf", np.asarray(snap.tree_leaf).astype(np.uint16)))
        if layers.get("links") and snap.links is not None and len(snap.links):
            arrays.append(("links", np.asarray(snap.links).astype(np.uint32).reshape(-1)))
        if layers.get("believed") and snap.believed is not None:
            arrays.append(("believed", snap.believed.astype(np.float32).reshape(-1)))
        field_name = layers.get("field")
        if field_name is not None and snap.fields:
            if field_name not in snap.fields:
                field_name = next(iter(snap.fields))
            grid, values, lo, hi = frame_arrays.field_bytes(snap, field_name)
            header["field"] = {"name": field_name, "lo": lo, "hi": hi, **grid}
            arrays.append(("field", values))
        vector_name = layers.get("vectors")
        if vector_name is not None and snap.vectors and snap.grid_x is not None:
            if vector_name not in snap.vectors:
                vector_name = next(iter(snap.vectors))
            header["vectors"], more = frame_arrays.vector_arrays(snap, vector_name)
            arrays += more
        if layers.get("grid"):
            arrays += frame_arrays.grid_arrays(snap)
        return wire.encode(header, arrays), reached

    def inspect_at(self, x: float, y: float, reach: float) -> int | None:
        """Select the agent nearest world point (x, y) within `reach` (None: none)."""
        with self.lock:
            if self.sim is None:
                return None
            pos = self.sim.snapshot().pos
            ids = self.sim.agents.cols["id"]
            self.selected = None
            if len(pos):
                d = np.hypot(pos[:, 0] - x, pos[:, 1] - y)
                row = int(np.argmin(d))
                if d[row] <= reach:
                    self.selected = int(ids[row])
            self._changed()
            return self.selected

    # ---- internals ----
    def _recheck(self) -> None:
        """The editor's text checked again under new param values (a value can make or
        clear a warning); the text running needs no check: its program holds them."""
        if self.draft == self.text and self.program is not None:
            self.diagnostics = [diagnostic(w) for w in self.program.info.warnings]
        else:
            self.diagnostics = check_text(self.draft, self.path, self.overrides)

    def _selected(self, snap) -> dict | None:
        """The inspected agent: id, kind, status, every variable, its running tree path."""
        if self.selected is None:
            return None
        rows = np.nonzero(snap.ids == self.selected)[0]
        if not len(rows):
            return {"id": self.selected, "gone": True}
        row = int(rows[0])
        kind = self.program.info.kinds[int(snap.kind[row])]
        cols = self.sim.agents.cols
        values = {}
        for name in ("vel", "index", "sense", *kind.vars):
            if name in cols:
                values[name] = plain(cols[name][row])
        out = {"id": self.selected, "row": row, "kind": kind.name,
               "status": snap.status_names[int(snap.status[row])],
               "pos": plain(snap.pos[row]), "heading": plain(snap.heading[row]),
               "vars": values, "path": None}
        if snap.tree_leaf is not None and snap.tree_leaf_paths:
            leaf = int(snap.tree_leaf[row])
            if 0 < leaf < len(snap.tree_leaf_paths):
                out["path"] = snap.tree_leaf_paths[leaf]
        return out

    def _metric_names(self) -> list[str]:
        from swarmdsl.runtime.metrics import MetricLog

        return list(MetricLog(self.program).names)

    def _sample(self) -> None:
        """The current tick's metrics and status counts into the plot history."""
        from swarmdsl.runtime.metrics import MetricLog

        sim = self.sim
        log = MetricLog(self.program)
        if log:
            log.sample(sim)
            values = log.pending()[1][-1]
        else:
            values = np.zeros(0)
        counts = np.bincount(sim.agents.cols["status"],
                             minlength=len(self.program.status_display))
        self.history.add(sim.tick, values, counts)

    def _internal(self, exc: Exception) -> None:
        from swarmdsl.internal import internal_error

        tick = self.sim.tick if self.sim is not None else None
        self.fault = str(internal_error(exc, tick))
        self.playing = False

    def _changed(self, scene: bool = False) -> None:
        self.version += 1
        if scene:
            self.scene_version += 1


class _Plots:
    """The plot history as an observer of the session's run: a sample of the metrics
    and status counts at each tick the session shows (`Driver.observe`)."""

    def __init__(self, session: Session):
        self.session = session

    def start(self, driver) -> None:
        """The history was made new with the run (`Session.reset`)."""

    def tick(self, driver) -> None:
        self.session._sample()

    def close(self, driver, outcome: str) -> None:
        """The history stays on screen."""


def _shapes(program) -> tuple:
    """What fixes the run's array shapes: the counts, the world's size, grid and edges."""
    w = program.world
    return (tuple((k.name, k.count) for k in program.kinds), w.width, w.height, w.grid,
            w.edges, tuple(program.var_specs))
