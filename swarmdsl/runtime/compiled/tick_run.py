"""A run's whole-tick kernel: its plan, whether its machine code is at hand, the state
packed into the kernel's table and back, and what it did (for `-v`).

Why "at hand" matters: composing a program's whole tick makes one large loop, which
numba takes tens of seconds to compile the first time (then a tenth of a second from
the kernel cache on disk). A run never waits for that: the driver asks `ready` and runs
whole ticks only once the machine code is compiled in this process or on disk (the
tiered start's background process compiles it, `warmup.py`); until then ticks run one
by one on the per-construct kernels, which give the same bits.
"""

from __future__ import annotations

import os
import time
import weakref

import numpy as np

from swarmdsl.runtime import randomness, spatial
from swarmdsl.runtime.compiled import tick_fields
from swarmdsl.runtime.compiled.disk_cache import on_disk
from swarmdsl.runtime.compiled.plan import Unsupported
from swarmdsl.runtime.compiled.tick_checks import (
    CheckPlan,
    plan_checks,
    tick_columns,
    watched_arrays,
)
from swarmdsl.runtime.compiled.tick_kernel import kernel
from swarmdsl.runtime.compiled.tick_plan import TickPlan, plan_tick, refusal
from swarmdsl.runtime.world import corner_nodes

_RECHECK = 2.0     # seconds between looks for the kernel on disk, while it is not there
COMPILE_AFTER = 30.0   # seconds of ticks left that are worth compiling the kernel for


class _Shape:
    """A program's whole-tick plan, its compiled checks and its kernel, or why there is
    none: worked out once per program in a process, not per run (the tester makes
    hundreds of short runs of one program, each a fresh simulation)."""

    def __init__(self, program):
        self.plan: TickPlan | None = None
        self.checks: CheckPlan | None = None
        self.reason: str | None = None
        self.kernel = None    # the jitted loop (`tick_kernel.kernel`), once asked
        self.at_hand = False  # its machine code is compiled or on disk (`ready`)
        self.looked = -_RECHECK   # when `ready` last looked on disk
        self.compiling = False    # a run had another process compile it
        self.failed: str | None = None   # numba could not compile it
        self.noted = False        # looked whether to mark it kept (`warm.note_whole`)
        try:
            self.plan = plan_tick(program)
        except Unsupported as exc:
            self.reason = str(exc)
            return
        self.checks = plan_checks(program, self.plan)
        consts = [*self.plan.consts, *self.checks.consts]
        self.consts = np.array([v if isinstance(v, float) else 0.0 for v in consts])
        self.tick_cols = np.array([self.plan.layout.width + c
                                   for c, v in enumerate(self.plan.consts) if v == "tick"],
                                  np.int64)
        self.check_cols = tick_columns(self.plan, self.checks)

    def loop(self):
        if self.kernel is None:
            self.kernel, _new = kernel(self.plan, self.checks)
        return self.kernel


# id(program) -> _Shape, while the program lives (a Program compares by value, so it
# is no dictionary key of its own; its identity is what the shape was made from)
_SHAPES: dict[int, _Shape] = {}


def shape_of(program) -> _Shape:
    """The whole-tick plan of `program` (made on first request, kept while it lives)."""
    key = id(program)
    got = _SHAPES.get(key)
    if got is None:
        got = _SHAPES[key] = _Shape(program)
        weakref.finalize(program, _SHAPES.pop, key, None)
    return got


class _State:
    """A run's use of its program's whole-tick kernel: what it did (for `-v`)."""

    def __init__(self, shape: _Shape):
        self.shape = shape
        self.ticks = 0        # ticks run whole
        self.calls = 0
        self.stops = 0        # calls stopped by a check (that tick ran per tick)
        self.failed = 0       # ... of them, at a property that failed (`watch`)
        self.watched = 0      # ticks run whole with properties checked in the kernel
        self.measured = 0     # ... with metrics sampled in it
        self.refused: str | None = None   # why the run (not its program) cannot
        self.unwatched: str | None = None   # why its observers could not be compiled
        self.fixed = None     # what every call passes alike (`_fixed`)
        self.scratch = None   # the kernel's work arrays (`_scratch`)
        self.waited = False   # a run asked while it was not at hand

    @property
    def plan(self):
        return self.shape.plan

    @property
    def reason(self):
        return self.shape.reason or self.shape.failed


_STATES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()   # backend -> _State


def state_of(backend, sim) -> _State:
    """The whole-tick kernel of the run whose backend is `backend` (one per run)."""
    got = _STATES.get(backend)
    if got is None or got.shape is not _SHAPES.get(id(sim.program)):
        got = _STATES[backend] = _State(shape_of(sim.program))
    return got


def ready(backend, sim, left: float = 0.0, watch=None) -> bool:
    """Whether `sim` can run whole ticks now without compiling first: its program has a
    whole-tick plan, the run allows it, and the kernel's machine code is compiled in this
    process or kept on disk (looked for at most every `_RECHECK` seconds). A run with
    more than `COMPILE_AFTER` seconds `left` of ticks, whose kernel is not at hand, has
    another process compile it (`tiered.compile_for`, the tiered start's warm-up, which
    compiles the per-tick kernels and then this one) and takes it once it is on disk.
    `SWARMDSL_WHOLE_TICKS=0` says no to every run (ticks one by one, as `step()`).
    With a `watch` (the driver's `Watch`: properties its observers need checked after
    every tick), also whether the kernel compiles every check it asks for."""
    if os.environ.get("SWARMDSL_WHOLE_TICKS", "1").strip().lower() in ("0", "no", "off"):
        return False
    st = state_of(backend, sim)
    if st.reason is not None or refusal(sim, watch) is not None:
        return False
    shape = st.shape
    if watch is not None:
        why = _unwatchable(shape, watch)
        if why is not None:
            st.unwatched = why
            return False
    if shape.at_hand:
        return True
    now = time.perf_counter()
    if now - shape.looked < _RECHECK:
        st.waited = True
        return False
    shape.looked = now
    k = shape.loop()
    shape.at_hand = bool(k.overloads) or on_disk(k)
    if not shape.at_hand:
        st.waited = True
        if left > COMPILE_AFTER and not shape.compiling:
            shape.compiling = _compile_elsewhere(sim.program)
    return shape.at_hand


def _compile_elsewhere(program) -> bool:
    from swarmdsl.runtime.compiled import tiered

    if not tiered.environment_ready():
        return False
    try:
        tiered.compile_for(program)
    except OSError:         # no process could start: ticks stay per tick
        return False
    return True


def pack(sim, plan: TickPlan, consts: np.ndarray) -> np.ndarray:
    """The (N, C) state table of `sim`'s agents: their columns, then the constants."""
    cols, lay = sim.agents.cols, plan.layout
    A = np.empty((sim.agents.n, lay.width + consts.size))
    for name, (c, w) in lay.cols.items():
        if name in ("speed", "status_name"):
            continue
        v = cols.get(name)
        if v is None:    # a tree's active leaf or result, which nothing records
            A[:, c] = 0.0
            continue
        if w == 2:
            A[:, c:c + 2] = v
        else:
            A[:, c] = v
    A[:, lay.width:] = consts
    return A


def unpack(sim, plan: TickPlan, A: np.ndarray) -> None:
    """Write the columns a tick changes back from the state table (fresh arrays, as a
    tick's commit makes them)."""
    cols, lay = sim.agents.cols, plan.layout
    for name in ("pos", "vel", "heading", "status", *lay.vars, *lay.memory):
        if name not in cols:
            continue
        c, w = lay.cols[name]
        dtype = cols[name].dtype
        if w == 2:
            cols[name] = np.ascontiguousarray(A[:, c:c + 2])
        elif dtype == np.bool_:
            cols[name] = A[:, c] != 0.0
        else:
            cols[name] = A[:, c].astype(dtype)


def _scratch(st: _State, shape: _Shape, n: int, width: int) -> tuple:
    """The kernel's work arrays for n agents (kept between calls of a run)."""
    got = st.scratch
    if got is None or got[0] != n:
        plan = shape.plan
        sites = len(plan.sites)
        got = st.scratch = (n, (
            np.empty((n, width)), np.zeros((n, shape.checks.s_width)), np.empty((n, width)),
            np.zeros(sites, np.uint64), np.zeros(sites, np.uint8)), (
            np.empty((n, 2)), np.empty(n, np.int64), np.empty(n, np.int64),
            (np.empty(n + 1, np.int64), np.empty(n + 1), np.empty((n + 1, 2)),
             np.empty(6, np.int64), np.empty(6, np.int64), np.full(2, -1, np.int64)),
            np.empty((n, 2)), np.empty((n, 2)), np.empty(n), np.empty((n, 2)),
            np.empty((n, 2))))
    return got[1], got[2]


def _fixed(st: _State, sim, plan: TickPlan) -> tuple:
    """What every call of a run passes alike: constants, draw streams, the world."""
    if st.fixed is None:
        consts, tick_cols = st.shape.consts, st.shape.tick_cols
        site_keys = np.array([randomness.stream_key(x) for x in plan.sites], np.uint64)
        w = sim.world
        box = w.box
        bw, bh = (float(box[0]), float(box[1])) if box is not None else (0.0, 0.0)
        motion = (w.edges == "repel" and w.edge_weight > 0, w.width, w.height, w.grid,
                  w.edge_weight, w.edge_range, corner_nodes(w.width, w.height, w.grid))
        st.fixed = (consts, (site_keys, tick_cols,
                             sim.program.status_name_ids.astype(np.float64), plan.radius,
                             box is not None, bw, bh, motion))
    return st.fixed


def advance(backend, sim, ticks: int, watch=None) -> int:
    """Run up to `ticks` ticks of `sim` whole, in one compiled call; how many ran (0:
    the first one stopped at a check; -1: they cannot, `summary` says why). With a
    `watch`, its properties are checked after every tick inside the call, which stops
    after the first tick where one fails (`watch.failed`: the observers check that
    tick themselves); the counts of the other ticks go into the watch."""
    st = state_of(backend, sim)
    if st.reason is not None:
        return -1
    why = refusal(sim, watch)
    if why is not None:
        st.refused = why
        return -1
    plan, shape = st.plan, st.shape
    watching = _watching(shape, watch, ticks)
    if watching is None:
        st.unwatched = _unwatchable(shape, watch)
        return -1
    if ticks <= 0 or not spatial.positions_finite(sim.agents.cols["pos"]):
        return 0
    consts, (site_keys, tick_cols, names, radius, wrap, bw, bh, motion) = _fixed(st, sim,
                                                                                plan)
    A = pack(sim, plan, consts)
    (B, S, T, keys, called), rest = _scratch(st, shape, sim.agents.n, A.shape[1])
    fields = tick_fields.load(sim, plan)
    args = (A, B, S, T, sim.agents.cols["id"].astype(np.uint64), ticks, sim.tick,
            np.uint64(sim.rng._key), site_keys, keys, called, tick_cols, names, radius,
            wrap, bw, bh, motion, *rest, fields, watching)
    k = shape.loop()
    if not k.overloads:     # compiled here, or loaded from disk: once per process
        t0 = time.perf_counter()
        try:
            k(*args[:5], 0, *args[6:])     # compiles (or loads) it; runs no tick
        except Exception as exc:   # numba refused: the per-tick path for good
            shape.failed = "numba could not compile it: " + (
                str(exc).strip().splitlines() or ["?"])[0]
            return -1
        backend.compile_seconds += time.perf_counter() - t0
        shape.at_hand = True
    done = k(*args)
    if not shape.noted:   # once: later runs may take numba for it (`choice.py`)
        shape.noted = True
        if on_disk(k):
            from swarmdsl.runtime.compiled import warm

            warm.note_whole(sim.program)
    st.calls += 1
    st.stops += done < ticks
    if watch is not None:
        _report(shape.checks, watching, watch)
        st.failed += watch.failed
        if watch.properties:
            st.watched += done - watch.failed
        if watch.metrics:
            st.measured += done - watch.failed
    if done == 0:
        return 0
    unpack(sim, plan, A)
    if plan.field_rows:
        tick_fields.store(sim, plan, fields)
    st.ticks += done
    rng = sim.rng
    rng.tick = sim.tick + done - 1
    rng._calls = {plan.sites[c]: 1 for c in np.flatnonzero(called)}
    sim.tick += done
    sim.pairs = None
    return done


def _unwatchable(shape: _Shape, watch) -> str | None:
    """Why the kernel cannot compute what `watch` asks (a property or a metric it
    does not compile), or None."""
    if watch.properties or watch.premises:
        got, why = watched_arrays(shape.checks, watch.properties, watch.premises)
        if got is None:
            return why
    if watch.metrics and shape.checks.unmeasured:
        return shape.checks.unmeasured
    return None


def _watching(shape: _Shape, watch, ticks: int) -> tuple | None:
    """The kernel's `watch` argument (`tick_checks.observer`) for a call of `ticks`
    ticks with `watch` (None: nothing watched), or None when it cannot compute it. Its
    items have one type whatever is watched, so one machine code serves every call."""
    checks = shape.checks
    active, counts = _IDLE_CHECKS
    rows, row_ticks = _IDLE_ROWS
    checking = measuring = False
    every, last, check_every = 1, -1, 1
    if watch is not None:
        if _unwatchable(shape, watch) is not None:
            return None
        if watch.properties:
            (active, counts), _why = watched_arrays(checks, watch.properties,
                                                   watch.premises)
            checking = True
        measuring = bool(watch.metrics and checks.metrics)
        if measuring:
            every = max(int(watch.every), 1)
            rows = np.empty((ticks // every + 2, len(checks.metrics)))
            row_ticks = np.empty(rows.shape[0], np.int64)
        every = max(int(watch.every), 1)
        last = -1 if watch.last is None else int(watch.last)
        check_every = 1 if getattr(watch, "each_tick", False) else every
    return (checking or measuring, np.int64(every), np.int64(last), checking,
            np.int64(check_every), active, counts, shape.check_cols, measuring, rows,
            row_ticks, np.zeros(1, np.int64))


# what a call that checks nothing / samples nothing passes
_IDLE_CHECKS = (np.zeros(1, np.uint8), np.zeros((2, 1), np.int64))
_IDLE_ROWS = (np.zeros((1, 1)), np.zeros(1, np.int64))


def _report(checks: CheckPlan, watching: tuple, watch) -> None:
    """The call's results into `watch`: per property checked, agent-ticks checked and
    (for the premises it counts) agent-ticks its premise held; whether it stopped at a
    failing tick; the metric samples, (ticks, rows)."""
    counts = watching[6]
    slots = len(checks.checks)
    watch.failed = bool(watching[3] and counts[1, 2 * slots])
    for name in watch.properties:
        slot = checks.slot(name)
        watch.agent_ticks[name] = int(counts[1, slot])
    for name in watch.premises:
        slot = checks.slot(name)
        if slot is not None and name in watch.agent_ticks:
            watch.premise_ticks[name] = int(counts[1, slots + slot])
    if watching[8]:
        taken = int(watching[11][0])
        watch.samples = (watching[10][:taken].copy(), watching[9][:taken].copy())


def summary(backend) -> list[str]:
    """The `-v` line of the run on `backend`: whether ticks ran whole, and if not why
    (none when nothing asked: a run that observes every tick)."""
    st = _STATES.get(backend)
    if st is None:
        return []
    if st.ticks:
        line = (f"whole-tick kernel: yes ({st.ticks:,} tick{'s' * (st.ticks != 1)} in "
                f"{st.calls:,} call{'s' * (st.calls != 1)}")
        if st.watched:
            line += f"; properties checked in the kernel at {st.watched:,} ticks"
        if st.measured:
            line += f"; metrics sampled in the kernel over {st.measured:,} ticks"
        if st.stops - st.failed:
            line += (f"; {st.stops - st.failed:,} stopped at a check, that tick ran per "
                     "tick")
        if st.failed:
            line += (f"; {st.failed:,} stopped at a property that failed, that tick "
                     "checked in Python")
        lines = [line + ")"]
        if st.unwatched:
            lines.append(f"properties checked in the kernel: no ({st.unwatched})")
        return lines
    if st.unwatched and not st.reason and not st.refused:
        return [f"whole-tick kernel: no ({st.unwatched})"]
    why = st.reason or st.refused or (
        ("its kernel was compiling in another process; runs take it once it is on disk"
         if st.shape.compiling else "its kernel is not compiled yet; a run of over "
         f"{COMPILE_AFTER:.0f} s compiles it in another process") if st.waited
        else "no tick asked for it")
    return [f"whole-tick kernel: no ({why})"]
