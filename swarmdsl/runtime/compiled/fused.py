"""A neighbour aggregate with two paths: the fused kernel and the reference closure.

`codegen` wraps every aggregate it compiles in a `FusedAggregate`. Under the numpy
backend it calls the reference closure. Under numba it gathers the owner-only values
of the plan (one column each, per owner), the neighbours' columns (once per tick), and
the pair rows of the owner frame, calls the kernel and finishes the result exactly as
the reference does (defaults, mean, dtype). An aggregate without a plan, or whose
neighbour set at run time is not a query of the tick's pair table, runs the reference
closure; `Backend.parts` counts both, and `swarmdsl run -v` prints them.
"""

from __future__ import annotations

import time

import numpy as np

from swarmdsl.compiler.builtins import AGGREGATES, VEC
from swarmdsl.runtime import sensing
from swarmdsl.runtime.compiled import threads
from swarmdsl.runtime.compiled.plan import Plan, Unsupported, plan_aggregate, plan_filter, remap
from swarmdsl.runtime.frame import AgentFrame, NeighborSet
from swarmdsl.runtime.spatial import CellPairs, PairTable


def wrap(cg, e, reference):
    """The aggregate closure for call `e`: fused where possible, `reference` otherwise."""
    return listed(cg, FusedAggregate(cg, e, reference))


def wrap_filter(cg, e, source, reference):
    """The closure of neighbour filter `e` (`SET where COND`): a compiled mask over the
    tick's cell-order pairs where possible, else `reference(f, pairs)` on the set
    `source(f)`."""
    return listed(cg, FusedFilter(cg, e, source, reference))


def listed(cg, part, kind: str = "fused_parts"):
    """`part`, added to the program's list `kind` (what `swarmdsl run -v` reports)."""
    parts = getattr(cg.program, kind, None)
    if parts is None:
        parts = []
        setattr(cg.program, kind, parts)
    parts.append(part)
    return part


def part_line(part, label: str, calls, why_numpy: str) -> str:
    """The `-v` line of a fused part: compiled, or on numpy and why (`why_numpy` when
    it has a kernel but every call, `calls` = (compiled, numpy), took the reference)."""
    where = f"{part.span.line}:{part.span.col}"
    done, ref = calls
    if part.plan is None:
        return f"{where} {label}: numpy ({part.reason})"
    if ref and not done:
        return f"{where} {label}: numpy ({why_numpy})"
    return f"{where} {label}: compiled" + (f" ({ref} calls on numpy)" if ref else "")


def first_compile(part, backend, build) -> bool:
    """Compile `part`'s kernel: `build()` makes it and calls it once (numba compiles on
    the first call) and returns it. False if numba refused: the reason is kept on the
    part, which stays on the reference path for good."""
    t0 = time.perf_counter()
    try:
        k = build()
    except Exception as exc:   # numba refused: keep the reference path for good
        part.plan, part.reason = None, "numba could not compile it: " + (
            str(exc).strip().splitlines() or ["?"])[0]
        return False
    backend.compile_seconds += time.perf_counter() - t0
    part.kernel = k
    return True


def run_kernel(part, backend, args, make) -> bool:
    """Run `part`'s kernel on `args`, made by `make(part.plan)` and compiled on first
    use; False if numba refused it, which sends the part to the reference path for
    good."""
    if part.kernel is not None:
        part.kernel(*args)
        return True

    def build():
        k, _new = make(part.plan)
        k(*args)   # compiles if new
        return k
    return first_compile(part, backend, build)


# what shared loops and direct searches add: the aggregates a running sum accumulates
SUMS = tuple(name for name, row in AGGREGATES.items() if row.kernel == "sum")
# Candidate pairs a direct search writes down before summing them (a tile: ~320 KB,
# which stays in the CPU's second-level cache); more if one owner has more.
TILE = 8192


class Direct:
    """A sum's (or a shared loop's) kernel that searches the cell list itself: its plan
    (None once numba refused it: the sum reads the written pairs from then on)."""

    def __init__(self, plan, span):
        self.plan, self.span = plan, span
        self.kernel = None
        self.kernels = {}   # (the filter's condition (None: none), batch?) -> kernel
        self.reason = None


_NOT_DIRECT = Direct(None, None)


def search(direct: Direct, f, backend, cells: CellPairs, groups, keep, S, O, out, cnt,
           dest) -> bool:
    """Run `direct`'s kernel over the frame's owners `groups` in `cells` and the pairs
    a pending filter `keep` keeps (the tables and results as the written-pairs kernel
    has them); False if numba refused it."""
    from swarmdsl.runtime.compiled.cells import candidates_bound, split_work
    from swarmdsl.runtime.compiled.kernels import direct_kernel

    m = groups.size if groups.size else cells.order.size
    chunks = threads.chunks(m)
    seen = backend.pair_counts(cells.order.size)
    if chunks == 1:
        bounds = _ONE_RUN
    elif not groups.size and backend.pair_offsets(m) is not None:
        bounds = split_work(backend.pair_offsets(m), m, chunks)   # where they were
    else:
        bounds = np.arange(chunks + 1, dtype=np.int64) * m // chunks
    if isinstance(keep, Pending):
        cond, S2, O2 = keep.cond, keep.S, keep.O
    else:
        cond, S2, O2 = None, _NO_OTHERS, _NO_OTHERS
    args = (groups, *cells.grid, S, O, S2, O2, out, cnt, dest, seen,
            max(candidates_bound(cells), TILE), bounds)
    key = (cond, cells.batch)
    k = direct.kernels.get(key)
    if k is not None:
        k(*args)
        return True

    def build():
        k, _new = direct_kernel(direct.plan, cond, cells.batch)
        k(*args)   # compiles if new
        return k
    if not first_compile(direct, backend, build):
        return False
    direct.kernels[key] = direct.kernel
    return True


_ONE_RUN = np.zeros(2, np.int64)


class _Whole:
    """Stands in for a pair frame so the reference readers give whole columns."""

    def __init__(self, cols, n, backend):
        self.cols, self.n, self.backend = cols, n, backend

    def other(self, col):
        return self.cols[col]


def _readonly(a: np.ndarray) -> np.ndarray:
    """A read-only view: every call passes the kernel the same array types (one compile)."""
    a = a.view()
    a.flags.writeable = False
    return a


_NO_ROWS = _readonly(np.zeros(0, np.int64))
_NO_MASK = _readonly(np.zeros(0, np.bool_))
_NO_OFFSETS = _readonly(np.zeros(1, np.int64))   # a table of no owners
_NO_OTHERS = np.zeros((1, 1))                     # a plan that reads no neighbour column


def _offsets(seg: np.ndarray, m: int) -> np.ndarray:
    off = np.zeros(m + 1, np.int64)
    np.cumsum(np.bincount(seg, minlength=m), out=off[1:])
    return _readonly(off)


def owner_table(f, hoisted, width: int, limit, order, reuse=None) -> np.ndarray:
    """S: one column per hoisted owner value (two per vector), (M, width), its rows
    in the loop's owner order (frame rows `order`; None: the frame's own order).
    Values the same for every owner (params, constants) are written, not gathered.
    `reuse`: last call's table, written again if it has the shape (no page faults)."""
    shape = (f.n, max(width, 1))
    S = reuse if reuse is not None and reuse.shape == shape else np.empty(shape)
    values = []
    for key, vt, fn in hoisted:
        if key == "limit":
            values.append((limit, vt))
        elif key == "pos":
            values.append((f.state("pos"), vt))
        else:
            values.append((fn(f), vt))
    if f.n > _BLOCK:
        return _owner_blocks(S, values, order)
    c = 0
    for v, vt in values:
        if order is not None and np.ndim(v) == (2 if vt == VEC else 1):
            v = np.take(v, order, axis=0)
        c = _put(S, c, v, vt)
    return S


_BLOCK = 1 << 15   # rows of a big S built at a time: a block of columns fits in cache


def _owner_blocks(S, values, order):
    """`owner_table`'s S for a big swarm, a block of rows at a time: each column
    gathered (or a constant written) into a small transposed block in one contiguous
    run, then the block turned into rows. Writing each column of S itself, every one
    a strided pass over all of S, took twice as long at 10^6 agents."""
    n = S.shape[0]
    block = np.empty((S.shape[1], _BLOCK))
    pairs = np.empty((_BLOCK, 2))
    gathered, c = [], 0
    for v, vt in values:
        w = 2 if vt == VEC else 1
        if np.ndim(v) == w and np.shape(v)[0] == n:   # one value per owner
            gathered.append((c, np.ascontiguousarray(v, np.float64), w))
        else:                      # the same for every owner: written once
            block[c:c + w] = np.reshape(v, (w, 1)) if w == 2 else v
        c += w
    for k0 in range(0, n, _BLOCK):
        k1 = min(k0 + _BLOCK, n)
        rows = block[:, :k1 - k0]
        for c, v, w in gathered:
            if w == 2:
                got = pairs[:k1 - k0]
                if order is None:
                    got[:] = v[k0:k1]
                else:
                    np.take(v, order[k0:k1], axis=0, out=got, mode="clip")
                rows[c:c + 2] = got.T
            elif order is None:
                rows[c] = v[k0:k1]
            else:
                np.take(v, order[k0:k1], out=rows[c], mode="clip")
        np.copyto(S[k0:k1], rows.T)
    return S


def _put(T: np.ndarray, c: int, v, vt: str) -> int:
    """Write value `v` (a vector: two columns) into table `T` from column `c`; the next
    free column."""
    if vt == VEC:
        T[:, c:c + 2] = v
        return c + 2
    T[:, c] = v
    return c + 1


def other_table(f, backend, order, key, readers) -> np.ndarray:
    """O: the neighbours' columns `readers` ((type, reader) each; `key` names them) at
    the start of the tick, built once per tick, in row order or (given the table's
    `order`) in cell order."""
    sim = f.sim
    pos = sim.agents.cols.get("pos")
    cache = backend._others
    if cache is None or cache[0] != sim.tick or cache[1] is not pos:
        cache = backend._others = (sim.tick, pos, {})
    slot = (key, order is not None)
    got = cache[2].get(slot)
    if got is not None:
        return got
    if order is not None:
        rows = other_table(f, backend, None, key, readers)
        if rows.shape[0] == order.size:   # else no columns: a (1, 1) placeholder
            rows = np.take(rows, order, axis=0)
        cache[2][slot] = rows
        return rows
    whole = _Whole(sim.agents.cols, sim.agents.n, backend)
    width = sum(2 if vt == VEC else 1 for vt, _r in readers)
    O = np.empty((sim.agents.n if width else 1, max(width, 1)))
    c = 0
    for vt, read in readers:
        c = _put(O, c, read(whole), vt)
    cache[2][slot] = O
    return O


def neighbour_readers(cg, others) -> list:
    """(type, reader) of each `O` column a plan lists: its whole column at the start of
    the tick, read from a `_Whole`."""
    readers = []
    for cat, col, vt in others:
        if cat == "other_var":
            readers.append((vt, lambda f, c=col: f.other(c)))
        elif cat == "derived":
            readers.append((vt, _Derived(*col, neighbour_readers(cg, col[1]))))
        else:
            readers.append((vt, cg._state_reader(col, other=True)))
    return readers


class _Derived:
    """A derived `O` column (see plan.py): scalar tree `tree` worked out per agent
    over the columns `base` (read by `readers`), by the kernels' own functions."""

    def __init__(self, tree, base, readers):
        self.tree, self.readers = tree, readers
        self.width = sum(2 if vt == VEC else 1 for _c, _n, vt in base)
        self._buffers = None   # (B, out), written again every tick

    def __call__(self, whole) -> np.ndarray:
        from swarmdsl.runtime.compiled.kernels import derived_kernel

        n = whole.n
        if self._buffers is None or self._buffers[1].size != n:
            self._buffers = np.empty((n, max(self.width, 1))), np.empty(n)
        B, out = self._buffers
        c = 0
        for vt, read in self.readers:
            c = _put(B, c, read(whole), vt)
        t0 = time.perf_counter()
        k, new = derived_kernel(self.tree)
        k(B, out, threads.chunks(n))
        if new:
            whole.backend.compile_seconds += time.perf_counter() - t0
        return out


class _Fused:
    """What a fused aggregate and a fused filter share: the plan, its owner-side and
    neighbour-side tables, and the kernel, compiled on first call."""

    def __init__(self, cg, e, planner):
        self.span = e.span
        self.kernel = None
        try:
            self.plan = planner(cg, e, cg.program.world.edges == "wrap")
            self.reason = None
        except Unsupported as exc:
            self.plan, self.reason = None, str(exc)
            return
        plan = self.plan
        self.hoisted = [(key, vt, None if isinstance(key, str) else cg.expr(key))
                        for key, vt in plan.hoisted]
        self.s_width = sum(2 if vt == VEC else 1 for _k, vt in plan.hoisted)
        self.others = neighbour_readers(cg, plan.others)
        self.others_key = tuple(plan.others)
        self.o_width = sum(2 if vt == VEC else 1 for vt, _r in self.others)

    def _owner_table(self, f, limit, order) -> np.ndarray:
        return owner_table(f, self.hoisted, self.s_width, limit, order)

    def _other_table(self, f, backend, order) -> np.ndarray:
        return other_table(f, backend, order, self.others_key, self.others)

    def _run(self, f, backend, args) -> bool:
        from swarmdsl.runtime.compiled.kernels import kernel

        return run_kernel(self, backend, args, kernel)

    def _tables(self, f, backend, limit, ranks, order):
        """(S, O) for the kernel: S in the loop's owner order (`order`: cell order)."""
        S = self._owner_table(f, limit, order)
        O = self._other_table(f, backend, ranks if ranks.size else None)
        return S, O


class FusedAggregate(_Fused):
    def __init__(self, cg, e, reference):
        self.name = e.name
        self.node_id = id(e)
        self.siblings = None   # the Siblings that may compute it in a shared loop
        self.direct = _NOT_DIRECT   # its kernel that searches the cell list itself
        self.reference = reference
        super().__init__(cg, e, plan_aggregate)
        if self.plan is None:
            return
        plan = self.plan
        self.source = cg.expr(plan.source)
        self.radius = cg.expr(plan.radius) if plan.radius is not None else None
        self.default = cg.expr(e.default) if e.default is not None else (lambda f: 0.0)
        self.vtype = cg.type_of(e)
        if plan.name in SUMS:
            self.direct = Direct(("siblings", ((plan.width, plan.cond, plan.each),)),
                                 self.span)

    def __call__(self, f):
        backend = getattr(f.sim, "backend", None)
        if backend is None or not backend.fused:
            return self.reference(f)
        if self.plan is not None and type(f) is AgentFrame:
            out = self._fused(f, backend)
            if out is not None:
                backend.note(self, True)
                return out
        backend.note(self, False)
        return self.reference(f)

    # ---- the compiled path ----
    def _pairs(self, f):
        """The owner frame's pairs as the kernel reads them, or None (reference path):
        (groups, off, rows, J, D, DL, K, ranks, order, limit). In row order `groups`,
        `ranks` are empty (the identity) and `order` None. In cell order (the compiled
        search's layout) the kernel visits the frame's owners in the table's order:
        `groups` their groups (empty: all, in order), `order` their rows in the frame
        (owner-side arrays are permuted to it and back); `J` holds sorted positions,
        `ranks` the agent rows behind them and `K` a filtered set's mask (empty: all)."""
        limit = None
        if self.plan.neighbors_call and f.sim.sensing is not None:
            # the sensing model's view of `neighbors(r)`, made once (as the reference
            # makes it: its radius may draw) and read below like any set, its limit
            # tested already; a model that draws per pair is the reference's
            if f.sim.sensing.view(f) is None:
                return None
            limit = np.full(f.n, np.inf)
        elif self.plan.neighbors_call:
            table = f.sim.pairs
            limit = f.sim.agents.cols["sense"][f.idx]
            if self.radius is not None:
                limit = np.minimum(limit, self.radius(f))
            if table is None:   # nobody senses anything this tick
                return (_NO_ROWS, _readonly(np.zeros(f.n + 1, np.int64)), _NO_ROWS,
                        *_empty(), _NO_MASK, _NO_ROWS, None, limit)
            if isinstance(table, CellPairs):
                return (*self._cell_layout(f, table, _NO_MASK), limit)
            return (_NO_ROWS, *_row_order(table, *table.select(f.idx), f.n), _NO_MASK,
                    _NO_ROWS, None, limit)
        pairs = self.source(f)
        if not isinstance(pairs, NeighborSet) or pairs.owner is not f or pairs.perceived:
            return None   # a perceived (noisy) set: `other.pos` is sensed, not a column
        keep = _cell_set(pairs)
        if keep is not None:
            return (*self._cell_layout(f, pairs.base, keep), limit)
        base = pairs.base
        if isinstance(base, (PairTable, CellPairs)):
            return (_NO_ROWS, *_row_order(base, pairs.seg, pairs.rows, f.n), _NO_MASK,
                    _NO_ROWS, None, limit)
        j = _readonly(np.ascontiguousarray(pairs.j, np.int64))
        dist = _readonly(np.ascontiguousarray(pairs.dist, np.float64))
        delta = _readonly(np.ascontiguousarray(pairs.delta, np.float64).reshape(-1, 2))
        return (_NO_ROWS, _offsets(pairs.seg, f.n), _NO_ROWS, j, dist, delta, _NO_MASK,
                _NO_ROWS, None, limit)

    def _cell_layout(self, f, cells: CellPairs, keep):
        """`_cell_order`, or for a sum over the whole table whose pairs nobody has
        written yet (and none are wanted this tick: `Backend.search_directly`) the same
        owners with `cells` in place of `off` and None for the pair arrays: the kernel
        searches the cell list itself."""
        if ((keep is _NO_MASK or isinstance(keep, Pending)) and self.direct.plan is not None
                and not cells.filled and f.sim.backend.search_directly):
            groups, order = _cell_owners(f, cells)
            return groups, cells, None, None, None, None, keep, cells.order, order
        return _cell_order(f, cells, mask(keep))

    def _fused(self, f, backend):
        if self.siblings is not None:
            got = self.siblings.sums(self, f, backend)
            if got is not None:
                return self._finish(f, *got)
        return self._alone(f, backend)

    def _alone(self, f, backend):
        got = self._pairs(f)
        if got is None:
            return None
        groups, off, rows, J, D, DL, K, ranks, order, limit = got
        m = f.n
        if m == 0:
            return self._finish(f, np.zeros((0, 2)), np.zeros(0, np.int64))
        S, O = self._tables(f, backend, limit, ranks, order)
        out = np.empty((m, 2))
        cnt = np.empty(m, np.int64)
        dest = _NO_ROWS if order is None else order   # results straight to frame rows
        if J is None:
            if not search(self.direct, f, backend, off, groups, K, S, O, (out,), (cnt,),
                          dest):
                return None
            return self._finish(f, out, cnt)
        args = (groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, dest,
                threads.chunks(m))
        if not self._run(f, backend, args):
            return None
        return self._finish(f, out, cnt)

    def _finish(self, f, out, cnt):
        """The reference closure's result from the kernel's sums, extremes or picks:
        the aggregate row's own finishing form."""
        m, vtype = f.n, self.vtype
        value = out if self.plan.width == 2 else np.ascontiguousarray(out[:, 0])
        return AGGREGATES[self.name].finish(
            value, cnt,
            lambda: np.broadcast_to(self.default(f), (m, 2) if vtype == VEC else (m,)),
            vtype)


class FusedFilter(_Fused):
    """`SET where COND` over a query of the tick's cell-order table: the kernel tests
    the condition pair by pair and the result is the same query with a mask (one byte
    per pair of the table), read as it is by fused aggregates. Readers that need rows
    get them on first use (`NeighborSet._selected`), so results match the reference's
    subset exactly. Any other set goes to the reference filter."""

    name = "where"

    def __init__(self, cg, e, source, reference):
        self.source = source
        self.reference = reference
        super().__init__(cg, e, plan_filter)

    def __call__(self, f):
        pairs = self.source(f)
        backend = getattr(f.sim, "backend", None)
        if backend is None or not backend.fused:
            return self.reference(f, pairs)
        if (self.plan is not None and type(f) is AgentFrame
                and isinstance(pairs, NeighborSet) and pairs.owner is f
                and not pairs.perceived):
            keep = _cell_set(pairs)
            if keep is not None:
                out = self._fused(f, backend, pairs, keep)
                if out is not None:
                    backend.note(self, True)
                    return out
        backend.note(self, False)
        return self.reference(f, pairs)

    def _fused(self, f, backend, pairs, keep):
        cells = pairs.base
        if (keep is _NO_MASK and not cells.filled and backend.search_directly
                and (self.kernel is not None or self._compile(f, backend, cells))):
            groups, order = _cell_owners(f, cells)
            S, O = self._tables(f, backend, None, cells.order, order)
            pending = Pending(self.plan.cond, self.kernel, f, cells, S, O, self.o_width)
            return NeighborSet(f, None, base=cells, query=pairs.query, keep=pending)
        if isinstance(keep, Pending) and not cells.filled and backend.search_directly:
            # no kernel of its own: the sums compile the joined condition into theirs
            _groups, order = _cell_owners(f, cells)
            S, O = self._tables(f, backend, None, cells.order, order)
            return NeighborSet(f, None, base=cells, query=pairs.query,
                               keep=keep.also(self.plan.cond, S, O, self.o_width))
        groups, off, rows, J, D, DL, K, ranks, order = _cell_order(f, cells, mask(keep))
        S, O = self._tables(f, backend, None, ranks, order)
        out = np.zeros(J.size, np.bool_)
        cnt = np.empty(f.n, np.int64)
        args = (groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, _NO_ROWS,
                threads.chunks(f.n))
        if not self._run(f, backend, args):
            return None
        return NeighborSet(f, None, base=cells, query=pairs.query, keep=_readonly(out))

    def _compile(self, f, backend, cells) -> bool:
        """Compile the kernel on a set of no pairs (so compiling it writes none)."""
        groups, order = _cell_owners(f, cells)
        S, O = self._tables(f, backend, None, cells.order, order)
        J, D, DL = _empty()
        args = (_NO_ROWS, _NO_OFFSETS, _NO_ROWS, J, D, DL, _NO_MASK, S, O, _NO_ROWS,
                np.zeros(0, np.bool_), np.empty(0, np.int64), _NO_ROWS, 1)
        return self._run(f, backend, args)


class Pending:
    """A filter's mask over the cell-order pairs, not worked out yet: its condition and
    kernel (None: compiled on first use), with its owner and neighbour tables as they
    were when the filter ran. Sums over the set that search the cell list test the
    condition themselves, and the pairs are never written; anything else gets the mask
    (`mask`), computed on first use over the written pairs, with the same bits."""

    def __init__(self, cond, kernel, f, cells: CellPairs, S, O, o_width: int = 0):
        self.cond, self.kernel = cond, kernel
        self.f, self.cells, self.S, self.O = f, cells, S, O
        self.o_width = o_width   # O's columns (0: O is a placeholder)
        self._mask = None

    def also(self, cond, S, O, o_width: int) -> Pending:
        """This condition and `cond` (over its own tables `S`, `O` of `o_width`
        columns) both, pending as one condition over the two tables side by side: a
        filter of a filtered set (`neighbors(r) where a` then `where b`, a field of
        view then a `where`) writes no pairs either, and a sum over it tests both as
        it searches."""
        ws, wo = self.S.shape[1], self.o_width
        O2 = O if not wo else self.O if not o_width else np.hstack((self.O, O))
        cond = remap(cond, range(ws, ws + S.shape[1]), range(wo, wo + max(o_width, 1)))
        first, then = sorted((self.cond, cond), key=_cost)   # pure tests: either order
        return Pending(("if", first, then, ("not", ("true",))), None, self.f, self.cells,
                       np.hstack((self.S, S)), O2, wo + o_width)

    def mask(self) -> np.ndarray:
        if self._mask is None:
            f = self.f
            if self.kernel is None:
                self.kernel = filter_kernel(f, self.cond, self.S, self.O)
            groups, off, rows, J, D, DL, K, ranks, _order = _cell_order(f, self.cells,
                                                                         _NO_MASK)
            out = np.zeros(J.size, np.bool_)
            self.kernel(groups, off, rows, J, D, DL, K, self.S, self.O, ranks, out,
                        np.empty(f.n, np.int64), _NO_ROWS, threads.chunks(f.n))
            self._mask = _readonly(out)
        return self._mask


# What a condition costs a pair, roughly, in basic operations: the cheaper of two is
# tested first, and the other only for the pairs it keeps.
_CALL_COST = {"atan2": 30, "hypot": 15, "sin": 30, "cos": 30, "exp": 30, "log": 30,
              "pow": 60, "sqrt": 5}


def _cost(tree) -> int:
    if not isinstance(tree, tuple) or not tree:
        return 0
    return _CALL_COST.get(tree[0], 1) + sum(_cost(t) for t in tree[1:])


def mask(keep):
    """A cell-order set's mask (`_NO_MASK`: all pairs), worked out if pending."""
    return keep.mask() if isinstance(keep, Pending) else keep


_WITHIN = ("le", ("d",), ("s", 0))


def within(f, cells: CellPairs, limit: np.ndarray, view=None) -> NeighborSet:
    """`neighbors(r)` narrower than the tick's cell-order table, or seen through a field
    of view (`view`: a `sensing.View`): the frame's query with a mask of the pairs
    within each owner's `limit` (and in its view), pending until something reads it."""
    _groups, order = _cell_owners(f, cells)
    if view is None:
        cond, values = _WITHIN, [limit]
    else:
        cond = sensing.view_tree(view.fov)
        values = view.columns(limit, f.state("heading"))
    S = np.empty((f.n, len(values)))
    for c, v in enumerate(values):
        if order is not None and np.ndim(v) == 1:
            v = np.take(v, order)
        S[:, c] = v
    pending = Pending(cond, None, f, cells, S, _NO_OTHERS)
    return NeighborSet(f, None, base=cells, query=f.idx, keep=pending)


def filter_kernel(f, cond, S, O):
    """The compiled filter of pair condition `cond` (one per tree), compiled on a set
    of no pairs when new (so compiling it writes none)."""
    from swarmdsl.runtime.compiled.kernels import kernel

    k, new = kernel(Plan("filter", 1, cond, (), None, None, False))
    if new:
        t0 = time.perf_counter()
        J, D, DL = _empty()
        k(_NO_ROWS, _NO_OFFSETS, _NO_ROWS, J, D, DL, _NO_MASK, S, O, _NO_ROWS,
          np.zeros(0, np.bool_), np.empty(0, np.int64), _NO_ROWS, 1)
        f.sim.backend.compile_seconds += time.perf_counter() - t0
    return k


def _row_order(table, seg, rows, m):
    """(off, rows, J, D, DL) of the pairs `rows` (None: all, in order) of a row-order table."""
    if rows is None:
        return table.offsets, _NO_ROWS, table.j, table.dist, table.delta
    return (_offsets(seg, m), _readonly(np.ascontiguousarray(rows)), table.j, table.dist,
            table.delta)


def _cell_set(pairs: NeighborSet):
    """The mask (`_NO_MASK`: none; a `Pending` one) of a set that is still a query of
    the tick's cell-order table, its rows not worked out; None for any other set."""
    if pairs.query is not None and not pairs.selected and isinstance(pairs.base, CellPairs):
        return _NO_MASK if pairs.keep is None else pairs.keep
    return None


def _cell_order(f, cells: CellPairs, keep):
    """(groups, off, rows, J, D, DL, K, ranks, order) of a cell-order table for the frame's
    agents (`_cell_owners`)."""
    groups, order = _cell_owners(f, cells)
    return (groups, cells.soff, _NO_ROWS, cells.t, cells.c_dist, cells.c_delta, keep,
            cells.order, order)


def _cell_owners(f, cells: CellPairs):
    """(groups, order) of the frame's agents in a cell-order table, worked out once per
    frame and table: the owners are visited in the table's order, so owner-side values
    permuted by `order` are read in sequence (read at random, they cost more than the
    whole pair loop of a large swarm); each owner's results are written once, to its
    frame row `order[k]`. `groups`: their sorted positions (empty: all, in order)."""
    got = f.__dict__.get("_cell_groups")
    if got is None or got[0] is not cells:
        n = cells.order.size
        if f.n == n:   # every agent: frame rows are the store's (select() relies on it)
            groups, order = _NO_ROWS, cells.order
        else:
            where = np.full(n, -1, np.int64)
            where[f.idx] = np.arange(f.n)
            rows = np.take(where, cells.order)
            groups = np.flatnonzero(rows >= 0)
            order = _readonly(np.take(rows, groups))
            groups = _readonly(groups)
        got = f._cell_groups = (cells, groups, order)
    return got[1], got[2]


def _empty():
    return (_readonly(np.zeros(0, np.int64)), _readonly(np.zeros(0)),
            _readonly(np.zeros((0, 2))))
