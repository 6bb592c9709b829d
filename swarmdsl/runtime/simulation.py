"""Simulation: places the agents, then runs synchronous ticks of the compiled program.

A tick: build the neighbour pairs once; run every status closure over its agents, all
reading the state as it was at the start of the tick; commit every write together;
apply deferred effects (deposits, messages); move agents by their clamped velocity;
let extensions (fields, ...) advance.
"""

from __future__ import annotations

import contextlib

import numpy as np

from swarmdsl.errors import SwarmError, SwarmOptionError, SwarmRuntimeError
from swarmdsl.ops import portable
from swarmdsl.runtime import backends
from swarmdsl.runtime.agents import AgentStore
from swarmdsl.runtime.arguments import Forkable
from swarmdsl.runtime.frame import AgentFrame
from swarmdsl.runtime.layout import (check_fit, place_count, place_ids, place_indexes,
                                     place_positions, place_values)
from swarmdsl.runtime.protocols import Backend, Extension, RunnableProgram, hooks
from swarmdsl.runtime.randomness import RandomSource
from swarmdsl.runtime.snapshot import Snapshot
from swarmdsl.runtime.spatial import PairTable, build_pairs, positions_finite
from swarmdsl.runtime.world import World

MAX_SEED = 2**63 - 1        # a run's seed is an int64 (run.json, checkpoints, sweeps)


class Simulation(Forkable):
    def __init__(self, program, seed: int = 0, layout=None, backend: str | None = None,
                 work: float | None = None):
        from swarmdsl.runtime.arguments import check_program, real, whole

        check_program(program, "Simulation")   # a notebook's mistakes name the argument
        seed = whole("seed", seed, 0, MAX_SEED)
        if work is not None:
            work = real("work", work, 0.0, float("inf"))
        if layout is not None:   # before anything is built: a misfit is the caller's
            check_fit(layout, program)
        self.program: RunnableProgram = program
        self.layout = layout   # an explicit initial swarm (runtime/layout.py) or None
        # a registered backend (runtime/backends.py); `work` (agents x ticks) guides the
        # default, which may start on numpy and switch between ticks (`tiered`)
        self.backend: Backend = backends.make(backend, work, program, tiered=True)
        self.backend.prepare(program)
        self.seed = int(seed)
        self.rng = RandomSource(self.seed)   # per-agent streams (randomness.py)
        self.rng.compiled_units = self.backend.random_units
        w = program.world
        self.world = World(w.width, w.height, w.grid, w.edges, w.edge_weight, w.edge_range)
        self.tick = 0
        self.agents = AgentStore(program.var_specs)
        self.pairs: PairTable | None = None
        # Services extensions provide (runtime/protocols.py), None until one does.
        self.environment = None    # fields, regions, obstacles, memories
        self.sensing = None        # a robot profile's sensing model
        self.maps = None           # internal maps
        self.record_columns: dict = {}   # extra agents.parquet columns (trees.py)
        with np.errstate(all="ignore"):  # twin fields evaluate formulas here, as in a tick
            self.extensions: list[Extension] = [make(self) for make in program.extensions]
        try:
            with np.errstate(all="ignore"):  # NaN and inf are caught as located errors
                for kind in program.kinds:
                    self._place(kind)
        except MemoryError:
            total = sum(k.count for k in program.kinds)
            raise SwarmRuntimeError(f"not enough memory to place {total:,} agents") from None
        for hook in hooks(self.extensions, "after_placement"):
            hook(self)

    # ---- setup ----
    def _place(self, kind) -> None:
        declared = {name for name, _t, _init in kind.vars}
        rows = self.agents.append(place_count(self.layout, kind), declared)
        cols = self.agents.cols
        base = int(rows[0]) if rows.size else 0
        cols["id"][rows] = place_ids(self.layout, kind, rows)
        cols["kind"][rows] = kind.index
        cols["index"][rows] = place_indexes(self.layout, kind, rows - base)
        cols["sense"][rows] = kind.sense
        cols["max_speed"][rows] = np.inf
        cols["status"][rows] = kind.statuses[0].code
        f = AgentFrame(self, rows, kind, None)
        inits = {("var", name): init for name, _t, init in kind.vars}
        steps = {("option", "place"): self._place_positions,
                 ("option", "velocity"): self._place_velocity,
                 ("option", "heading"): self._place_heading,
                 ("option", "max_speed"): self._place_max_speed}
        order = kind.init_order or [*steps, *inits]
        step = None
        try:
            for step in order:     # each once what it reads is known (init_order.py)
                if step in inits:
                    cols[step[1]][rows] = inits[step](f)
                else:
                    steps[step](kind, f, rows)
            place_values(self.layout, kind, cols, rows)
            if kind.initial is not None:
                cols["status"][rows] = self._initial_codes(kind, kind.initial(f))
        except SwarmError:
            raise
        except Exception as exc:  # a kernel fault while placing: name the kind and line
            where = None if step is None else kind.option_spans.get(
                step[1] if step[0] == "option" else f"var {step[1]}")
            raise SwarmRuntimeError(f"placing agents of `{kind.name}` failed: {exc}",
                                    where) from exc
        bad = ~np.isfinite(cols["pos"][rows]).all(axis=1)
        if bad.any():
            raise SwarmRuntimeError(
                f"agent {int(rows[bad][0])} of `{kind.name}` was placed at a non-finite "
                "position", kind.option_spans.get("place"))

    def _place_positions(self, kind, f, rows) -> None:
        cols, w = self.agents.cols, self.world
        if kind.place_region is not None:
            cols["pos"][rows] = self._place_in_region(kind, f)
        elif kind.place is not None:
            pts = np.asarray(kind.place(f), dtype=np.float64)
            if w.wraps:   # a torus has no outside: a point beyond an edge is across it
                size = np.array([w.width, w.height])
                with np.errstate(invalid="ignore"):
                    pts = np.mod(pts, size)
                pts = np.where(pts >= size, 0.0, pts)   # the mod of -tiny rounds up
            cols["pos"][rows] = pts
        else:
            cols["pos"][rows] = self._place_uniform(kind, f, rows.size)
        cols["pos"][rows] = place_positions(self.layout, kind, cols["pos"][rows])

    def _place_uniform(self, kind, f, n: int) -> np.ndarray:
        """`place uniform`: over the world, outside what an extension keeps agents out
        of (the environment's obstacles: `place_uniform`)."""
        for place in hooks(self.extensions, "place_uniform"):
            pts = place(self, kind, f)
            if pts is not None:
                return pts
        w = self.world
        return f.rng.at("pos").uniform((0, 0), (w.width, w.height), (n, 2))

    def _place_velocity(self, kind, f, rows) -> None:
        if kind.velocity is not None:
            self.agents.cols["vel"][rows] = kind.velocity(f)

    def _place_heading(self, kind, f, rows) -> None:
        cols = self.agents.cols
        vel = cols["vel"][rows]
        moving = np.any(vel != 0, axis=1)
        heading = kind.heading(f) if kind.heading is not None else np.zeros(rows.size)
        cols["heading"][rows] = np.where(moving, portable.atan2_array(vel[:, 1], vel[:, 0]),
                                         heading)

    def _place_max_speed(self, kind, f, rows) -> None:
        if kind.max_speed is not None:
            limit = kind.max_speed(f)
            if (limit < 0).any():
                raise SwarmRuntimeError(
                    f"the max_speed of `{kind.name}` must be 0 or more, got "
                    f"{float(limit[limit < 0][0]):g}", kind.option_spans.get("max_speed"))
            self.agents.cols["max_speed"][rows] = limit

    def _place_in_region(self, kind, frame):
        for place in hooks(self.extensions, "place_in"):
            return place(self, kind.place_region, frame.n, frame)
        raise SwarmRuntimeError(f"no region named `{kind.place_region}` to place agents in",
                                kind.option_spans.get("place"))

    def _initial_codes(self, kind, name_ids) -> np.ndarray:
        lut = np.full(len(self.program.info.status_names), -1, dtype=np.int32)
        for st in kind.statuses:
            lut[self.program.status_name_ids[st.code]] = st.code
        codes = lut[np.asarray(name_ids, dtype=np.int64)]
        if (codes < 0).any():
            raise SwarmRuntimeError(f"the initial status of `{kind.name}` is not one of its "
                                    "statuses", kind.option_spans.get("initial"))
        return codes

    # ---- ticks ----
    def step(self) -> None:
        ticking = getattr(self.backend, "ticking", None)   # a backend's own pacing
        with np.errstate(all="ignore"), (
                ticking(self) if ticking is not None else contextlib.nullcontext()):
            try:
                self._step()
            except MemoryError:
                raise SwarmRuntimeError(
                    f"out of memory at tick {self.tick} with {self.agents.n:,} agents "
                    "(neighbour pairs grow with density x sense radius)") from None

    def _step(self) -> None:
        prog = self.program
        cols = self.agents.cols
        self.rng.begin_tick(self.tick)
        if prog.pair_radius > 0:
            self.pairs = None   # last tick's table: freed before this one is built
            self.pairs = self._build_pairs(cols["pos"], prog.pair_radius)
        for hook in hooks(self.extensions, "begin_tick"):
            hook(self)
        frames = []
        try:
            self._run_frames(frames)
        finally:
            # A `let` holding a neighbour set points back to its frame (and the frame
            # to its effects' closures): a cycle that would keep this tick's pair table
            # alive until the garbage collector runs. Break it, so memory stays flat.
            for f in frames:
                f.close()
        self._move()
        for hook in hooks(self.extensions, "end_tick"):
            hook(self)
        self.tick += 1

    def advance(self, ticks: int) -> int:
        """Run `ticks` ticks, as many `step()`s would, and return how many ran (all of
        them, unless a tick raises). For a caller that needs the state only after the
        last of them (no recording, viewer frame or check in between): a backend that
        can runs them whole, several ticks in one compiled call (the numba backend's
        whole-tick kernel, `compiled/tick_kernel.py`), with the same bits as stepping;
        ticks it cannot run so (or a tick where one of its checks stopped it) run as
        `step()`s."""
        from swarmdsl.limits import upper
        from swarmdsl.runtime.arguments import whole

        ticks = whole("ticks", ticks, 0, upper("steps"))
        whole_ticks = getattr(self.backend, "advance", None)
        done = 0
        while done < ticks:
            if whole_ticks is not None:
                with np.errstate(all="ignore"):
                    got = whole_ticks(self, ticks - done)
                if got < 0:   # this run cannot (the backend says why with -v): step
                    whole_ticks = None
                    continue
                done += got
                if done >= ticks:
                    break
            self.step()
            done += 1
        return done

    def _build_pairs(self, pos, radius: float):
        """The tick's pair table (a batch of replicas builds one per replica)."""
        return self.backend.build_pairs(pos, radius, self.world.box)

    def reference_pairs(self, radius: float) -> PairTable:
        """The pairs within `radius` as the numpy search finds them, whatever the
        backend (messages wider than the tick's table)."""
        return build_pairs(self.agents.cols["pos"], radius, self.world.box)

    def replicas_of(self, rows) -> np.ndarray | None:
        """The replica of each agent row, for what keeps a grid per replica (fields):
        None in a run of its own (a batch of replicas answers, `runtime/batch.py`)."""
        return None

    def replica_bounds(self) -> np.ndarray:
        """Where each run's agent rows start and end: `[0, n]` for a solo run; a batch
        of replicas gives each replica's, so a search over every agent of a kind
        searches each replica's alone."""
        return np.array([0, self.agents.n], dtype=np.int64)

    def run_any(self, mask: np.ndarray) -> np.ndarray:
        """Per agent row: whether `mask` holds for any agent of its run (a batch of
        replicas answers per replica)."""
        return np.full(mask.shape[0], bool(mask.any()))

    def _run_frames(self, frames: list) -> None:
        """Run every status closure, then commit their writes and run their effects."""
        prog = self.program
        cols = self.agents.cols
        status = cols["status"]
        for kind in prog.kinds:
            for st in kind.statuses:
                idx = np.flatnonzero(status == st.code)
                if idx.size == 0:
                    continue
                f = AgentFrame(self, idx, kind, st.name)
                f.next_status = np.full(idx.size, st.code, dtype=np.int32)
                frames.append(f)
                try:
                    st.run(f)
                except SwarmError:
                    raise
                except Exception as exc:
                    raise SwarmRuntimeError(
                        f"status `{st.name}` of `{kind.name}` failed at tick {self.tick}: "
                        f"{exc}") from exc
        written: dict[str, np.ndarray] = {}
        n = status.shape[0]
        if len(frames) == 1 and frames[0].n == n:
            # One frame of every agent (its rows are 0..n-1 in order): its writes become
            # the new columns as they are, when each is a fresh array of the column's
            # shape and type (a statement's result always is), else a copy.
            f = frames[0]
            for col, values in f.overlay.items():
                old = cols[col]
                if not (type(values) is np.ndarray and values.dtype == old.dtype
                        and values.shape == old.shape and values.flags.writeable
                        and values.flags.c_contiguous
                        and not np.may_share_memory(values, old)):
                    values = old.copy()
                    values[f.idx] = f.overlay[col]
                written[col] = values
            new_status = f.next_status
        else:
            new_status = status.copy()
            for f in frames:
                for col, values in f.overlay.items():
                    if col not in written:
                        written[col] = cols[col].copy()
                    written[col][f.idx] = values
                new_status[f.idx] = f.next_status
        cols.update(written)
        cols["status"] = new_status
        for f in frames:
            for effect in f.effects:
                effect()

    def _move(self) -> None:
        cols = self.agents.cols
        compiled = self.backend.move(self)   # numba: the whole step in one loop, or None
        if compiled is not None:
            pos, vel, heading = compiled
            self._check_finite(pos)
            cols["pos"], cols["vel"], cols["heading"] = pos, vel, heading
            return
        vel = cols["vel"]
        if self.world.edges == "repel" and self.world.edge_weight > 0:
            vel = vel + self.world.edge_push(cols["pos"])
        speed = np.sqrt(np.einsum("ij,ij->i", vel, vel))
        limit = cols["max_speed"]
        too_fast = speed > limit
        if too_fast.any():
            vel = vel.copy()
            vel[too_fast] *= (limit[too_fast] / speed[too_fast])[:, None]
        step = vel
        for motion in hooks(self.extensions, "motion"):   # noisy vibration, ...
            step = motion(self, step)
        pos, moved = self.world.move(cols["pos"], step)
        vel = moved if step is vel else vel   # agents keep their commanded velocity
        self._check_finite(pos)
        moving = np.any(moved != 0, axis=1)
        cols["heading"] = np.where(moving, portable.atan2_array(moved[:, 1], moved[:, 0]),
                                   cols["heading"])
        cols["pos"], cols["vel"] = pos, vel

    def _check_finite(self, pos) -> None:
        if positions_finite(pos):
            return
        bad = ~np.isfinite(pos).all(axis=1)
        if bad.any():
            cols = self.agents.cols
            row = int(np.flatnonzero(bad)[0])
            kind = self.program.kinds[int(cols["kind"][row])]
            status = self.program.status_display[int(cols["status"][row])]
            raise SwarmRuntimeError(
                f"agent {int(cols['id'][row])} (kind `{kind.name}`, status `{status}`) "
                f"moved to a non-finite position at tick {self.tick}")

    def run(self, steps: int, on_tick=None) -> None:
        from swarmdsl.limits import upper
        from swarmdsl.runtime.arguments import whole

        steps = whole("steps", steps, 0, upper("steps"))
        if on_tick is not None and not callable(on_tick):   # not after the first tick
            raise SwarmOptionError(f"on_tick must be a function of the simulation, got "
                                   f"{type(on_tick).__name__}")
        from swarmdsl.runtime.driver import Callback, Driver

        # the one tick loop (`runtime/driver.py`); no stop checks: a notebook's
        # Ctrl-C interrupts a bare simulation as Python does
        driver = Driver(self, None, every=None if on_tick is None else 1, subject=self,
                        stops=False)
        if on_tick is not None:
            driver.observers.append(Callback(on_tick))
        driver.run(steps)

    # ---- views ----
    def status_counts(self) -> dict[str, int]:
        counts = np.bincount(self.agents.cols["status"],
                             minlength=len(self.program.status_display))
        return {name: int(c) for name, c in zip(self.program.status_display, counts,
                                                strict=True)}

    def snapshot(self) -> Snapshot:
        cols = self.agents.cols
        snap = Snapshot(
            tick=self.tick,
            world_size=(self.world.width, self.world.height),
            wraps=self.world.wraps,
            pos=cols["pos"].copy(),
            heading=cols["heading"].copy(),
            status=cols["status"].astype(np.int32),
            kind=cols["kind"].astype(np.int32),
            ids=cols["id"].copy(),
            status_names=list(self.program.status_display),
            kind_names=[k.name for k in self.program.kinds],
        )
        for hook in hooks(self.extensions, "decorate_snapshot"):
            hook(self, snap)
        return snap
