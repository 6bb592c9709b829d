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
from swarmdsl.runtime.compiled.disk_cache import on_disk
from swarmdsl.runtime.compiled.plan import Unsupported
from swarmdsl.runtime.compiled.tick_kernel import kernel
from swarmdsl.runtime.compiled.tick_plan import TickPlan, plan_tick, refusal
from swarmdsl.runtime.world import corner_nodes

_RECHECK = 2.0     # seconds between looks for the kernel on disk, while it is not there
COMPILE_AFTER = 30.0   # seconds of ticks left that are worth compiling the kernel for


class _State:
    """A run's whole-tick kernel: its plan and kernel, or why there is none; what it
    did (for `-v`)."""

    def __init__(self):
        self.plan: TickPlan | None = None
        self.kernel = None
        self.reason: str | None = None
        self.ticks = 0        # ticks run whole
        self.calls = 0
        self.stops = 0        # calls stopped by a check (that tick ran per tick)
        self.refused: str | None = None   # why the run (not its program) cannot
        self.fixed = None     # what every call passes alike (`_fixed`)
        self.scratch = None   # the kernel's work arrays (`_scratch`)
        self.at_hand = False  # its machine code is compiled or on disk (`ready`)
        self.looked = -_RECHECK   # when `ready` last looked on disk
        self.waited = False   # a run asked while it was not at hand
        self.compiling = False    # ... and had another process compile it


_STATES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()   # backend -> _State


def state_of(backend, sim) -> _State:
    """The whole-tick kernel of the run whose backend is `backend` (one per run)."""
    got = _STATES.get(backend)
    if got is None:
        got = _STATES[backend] = _State()
        try:
            got.plan = plan_tick(sim.program)
        except Unsupported as exc:
            got.reason = str(exc)
    return got


def ready(backend, sim, left: float = 0.0) -> bool:
    """Whether `sim` can run whole ticks now without compiling first: its program has a
    whole-tick plan, the run allows it, and the kernel's machine code is compiled in this
    process or kept on disk (looked for at most every `_RECHECK` seconds). A run with
    more than `COMPILE_AFTER` seconds `left` of ticks, whose kernel is not at hand, has
    another process compile it (`tiered.compile_for`, the tiered start's warm-up, which
    compiles the per-tick kernels and then this one) and takes it once it is on disk.
    `SWARMDSL_WHOLE_TICKS=0` says no to every run (ticks one by one, as `step()`)."""
    if os.environ.get("SWARMDSL_WHOLE_TICKS", "1").strip().lower() in ("0", "no", "off"):
        return False
    st = state_of(backend, sim)
    if st.reason is not None or refusal(sim) is not None:
        return False
    if st.at_hand or st.kernel is not None:
        return True
    now = time.perf_counter()
    if now - st.looked < _RECHECK:
        return False
    st.looked = now
    k, _new = kernel(st.plan)
    st.at_hand = bool(k.overloads) or on_disk(k)
    if not st.at_hand:
        st.waited = True
        if left > COMPILE_AFTER and not st.compiling:
            st.compiling = _compile_elsewhere(sim.program)
    return st.at_hand


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
        v = cols[name]
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
    for name in ("pos", "vel", "heading", "status", *lay.vars):
        c, w = lay.cols[name]
        dtype = cols[name].dtype
        if w == 2:
            cols[name] = np.ascontiguousarray(A[:, c:c + 2])
        elif dtype == np.bool_:
            cols[name] = A[:, c] != 0.0
        else:
            cols[name] = A[:, c].astype(dtype)


def _scratch(st: _State, plan: TickPlan, n: int, width: int) -> tuple:
    """The kernel's work arrays for n agents (kept between calls of a run)."""
    got = st.scratch
    if got is None or got[0] != n:
        sites = len(plan.sites)
        got = st.scratch = (n, (
            np.empty((n, width)), np.zeros((n, plan.s_width)), np.empty((n, width)),
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
        consts = np.array([v if isinstance(v, float) else 0.0 for v in plan.consts])
        tick_cols = np.array([plan.layout.width + c for c, v in enumerate(plan.consts)
                              if v == "tick"], np.int64)
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


def advance(backend, sim, ticks: int) -> int:
    """Run up to `ticks` ticks of `sim` whole, in one compiled call; how many ran (0:
    the first one stopped at a check; -1: they cannot, `summary` says why)."""
    st = state_of(backend, sim)
    if st.reason is not None:
        return -1
    why = refusal(sim)
    if why is not None:
        st.refused = why
        return -1
    plan = st.plan
    if ticks <= 0 or not spatial.positions_finite(sim.agents.cols["pos"]):
        return 0
    consts, (site_keys, tick_cols, names, radius, wrap, bw, bh, motion) = _fixed(st, sim,
                                                                                plan)
    A = pack(sim, plan, consts)
    (B, S, T, keys, called), rest = _scratch(st, plan, sim.agents.n, A.shape[1])
    args = (A, B, S, T, sim.agents.cols["id"].astype(np.uint64), ticks, sim.tick,
            np.uint64(sim.rng._key), site_keys, keys, called, tick_cols, names, radius,
            wrap, bw, bh, motion, *rest)
    if st.kernel is None:
        t0 = time.perf_counter()
        try:
            k, _new = kernel(plan)
            k(*args[:5], 0, *args[6:])     # compiles (or loads) it; runs no tick
        except Exception as exc:   # numba refused: the per-tick path for good
            st.reason = "numba could not compile it: " + (
                str(exc).strip().splitlines() or ["?"])[0]
            return -1
        backend.compile_seconds += time.perf_counter() - t0
        st.kernel = k
    done = st.kernel(*args)
    st.calls += 1
    st.stops += done < ticks
    if done == 0:
        return 0
    unpack(sim, plan, A)
    st.ticks += done
    rng = sim.rng
    rng.tick = sim.tick + done - 1
    rng._calls = {plan.sites[c]: 1 for c in np.flatnonzero(called)}
    sim.tick += done
    sim.pairs = None
    return done


def summary(backend) -> list[str]:
    """The `-v` line of the run on `backend`: whether ticks ran whole, and if not why
    (none when nothing asked: a run that observes every tick)."""
    st = _STATES.get(backend)
    if st is None:
        return []
    if st.ticks:
        line = f"whole-tick kernel: yes ({st.ticks:,} ticks in {st.calls:,} calls"
        if st.stops:
            line += f"; {st.stops:,} stopped at a check, that tick ran per tick"
        return [line + ")"]
    why = st.reason or st.refused or (
        ("its kernel was compiling in another process; runs take it once it is on disk"
         if st.compiling else "its kernel is not compiled yet; a run of over "
         f"{COMPILE_AFTER:.0f} s compiles it in another process") if st.waited
        else "no tick asked for it")
    return [f"whole-tick kernel: no ({why})"]
