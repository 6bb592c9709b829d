"""AST -> closures over whole arrays. Nothing from the program text is ever eval'd:
each node becomes a Python closure `fn(frame) -> array` built from the checked AST."""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler import ast, draws, nan_guard, stream_places
from swarmdsl.compiler.builtins import BOOL, FUNCTIONS, NUM, SET, VEC, vec_length
from swarmdsl.compiler.facts import NodeTable
from swarmdsl.compiler.lowering import REFERENCE, Lowering
from swarmdsl.compiler.visit import Visitor
from swarmdsl.errors import SwarmError, SwarmRuntimeError
from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS, NEGATE
from swarmdsl.runtime import spatial

# Extension points: resolution category -> fn(codegen, node, resolution) -> closure;
# call name -> fn(codegen, call_node) -> closure.
NAME_CODEGEN: dict = {}
CALL_CODEGEN: dict = {}
# Node classes an extension adds: EXPR_CODEGEN[cls](codegen, expr) -> closure,
# STMT_CODEGEN[cls](codegen, stmt, kind, status) -> closure (behaviour trees).
EXPR_CODEGEN: dict = {}
STMT_CODEGEN: dict = {}
# Types a `let` keeps as they are instead of broadcasting to one value per agent.
RAW_LET_TYPES: set = {SET}
LET_NAN_HINT = "guard the division, square root or log that produced it"


def broadcast(value, n: int, vtype: str):
    """A value as a full per-row array: (n,) for numbers/bools/statuses, (n, 2) vectors."""
    shape = (n, 2) if vtype == VEC else (n,)
    if type(value) is np.ndarray and value.shape == shape:
        # what `broadcast_to` returns for it (a read-only view), without its ~5 us:
        # small swarms call this some twenty times a tick
        view = value.view()
        view.flags.writeable = False
        return view
    return np.broadcast_to(value, shape)


def _col(a):
    """Make a per-row number broadcast against (n, 2) vectors."""
    a = np.asarray(a)
    return a[..., None] if a.ndim >= 1 else a


def _where_vec(test, a, b, vtype):
    if vtype == VEC:
        return np.where(_col(test), a, b)
    return np.where(test, a, b)


class CodeGen(Visitor):
    """Each expression class's closure (`visit_<Class>`, `visit.Visitor` dispatches; an
    extension's class: its `EXPR_CODEGEN` rule), and each statement's."""

    NODES = (ast.Expr, ast.Stmt)
    # `repeat forever`'s count: the tree's compiler reads it as no limit (tree_codegen),
    # it is never a value of its own.
    REFUSED = frozenset({"Forever"})

    def __init__(self, info, program, lowering: Lowering = REFERENCE):
        self.info = info
        self.program = program
        self.lowering = lowering   # a backend's own closures in place of the reference's
        self.facts = info.facts
        self.built: dict | None = None   # id(node) -> closure, while `recorded` runs
        self._nan_guarded = NodeTable()   # the comparisons of the `when` compiled now

    def extension_rule(self, node_cls: type):
        return EXPR_CODEGEN.get(node_cls) or STMT_CODEGEN.get(node_cls)


    def type_of(self, e: ast.Expr) -> str:
        return self.facts.type_of(e)

    @staticmethod
    def extension_call(name: str) -> bool:
        """Whether a language extension compiles calls to `name` (`CALL_CODEGEN`): a
        backend fuses only the built-ins it knows."""
        return name in CALL_CODEGEN

    # ---- expressions ----
    def expr(self, e: ast.Expr):
        fn = self.visit(e)
        if self.built is not None:
            self.built[id(e)] = fn
        return fn

    def recorded(self, e: ast.Expr):
        """`expr(e)`, and the closure built for each node under it by id: a fused
        statement evaluates some of them itself, and compiling them again would build
        (and report) each aggregate twice."""
        outer, self.built = self.built, {}
        try:
            return self.expr(e), self.built
        finally:
            self.built = outer

    def visit_Num(self, e):
        v = e.value
        return lambda f: v

    def visit_BoolLit(self, e):
        v = e.value
        return lambda f: v

    def visit_StrLit(self, e):
        v = e.value
        return lambda f: v

    def visit_Name(self, e):
        res = self.facts.name_of(e)
        if res is None:
            raise SwarmRuntimeError(f"internal: unresolved name `{e.id}`", e.span)
        cat = res[0]
        if cat == "local":
            name = res[1]
            return lambda f: f.local(name)
        if cat == "var":
            name = res[1]
            return lambda f: f.state(name)
        if cat == "state":
            return self._state_reader(res[1], other=False)
        if cat == "const":
            v = res[1]
            return lambda f: v
        if cat == "status":
            code = self.info.status_name_id(res[1])
            return lambda f: code
        if cat == "kind":
            k = res[1]
            return lambda f: k
        if cat == "global":
            return lambda f: float(f.tick)
        if cat == "pair":
            return lambda f: f.dist
        if cat in NAME_CODEGEN:
            return NAME_CODEGEN[cat](self, e, res)
        raise SwarmRuntimeError(f"internal: cannot compile name `{e.id}` ({cat})", e.span)

    def _state_reader(self, col: str, other: bool):
        read = (lambda f, c: f.other(c)) if other else (lambda f, c: f.state(c))
        if col == "speed":
            return lambda f: vec_length(read(f, "vel"))
        if col == "status":
            names = self.program.status_name_ids
            return lambda f: names[read(f, "status")]
        if col in ("id", "kind"):
            return lambda f: read(f, col).astype(np.float64) if col == "id" else read(f, col)
        return lambda f: read(f, col)

    def visit_Attr(self, e):
        res = self.facts.name_of(e)
        cat = res[0]
        if cat == "component":
            obj = self.expr(e.obj)
            i = res[1]
            return lambda f: np.asarray(obj(f))[..., i]
        if cat == "other_state":
            return self._state_reader(res[1], other=True)
        if cat == "other_var":
            name = res[1]
            return lambda f: f.other(name)
        if cat in NAME_CODEGEN:
            return NAME_CODEGEN[cat](self, e, res)
        raise SwarmRuntimeError(f"internal: cannot compile `.{e.name}`", e.span)

    def visit_Vec(self, e):
        if isinstance(e.x, ast.Num) and isinstance(e.y, ast.Num):
            # a literal point, `(40, 40)`: made once (a target a tree evaluates every
            # tick, an `if` of four such, cost a stack of two arrays each time)
            point = np.array([e.x.value, e.y.value], dtype=float)
            point.flags.writeable = False
            return lambda f: point
        x, y = self.expr(e.x), self.expr(e.y)

        def vec(f):
            a, b = np.broadcast_arrays(np.asarray(x(f), float), np.asarray(y(f), float))
            return np.stack([a, b], axis=-1)
        return vec

    def visit_BinOp(self, e):
        a, b = self.expr(e.left), self.expr(e.right)
        ta, tb = self.type_of(e.left), self.type_of(e.right)
        op = ARITHMETIC[e.op].numpy
        if e.op == "-" and self._is_pos(e.left, other=True) and self._is_pos(e.right):
            return lambda f: f.other_minus_own_pos()  # the pair table's delta, no gathers
        if e.op == "-" and self._is_pos(e.left) and self._is_pos(e.right, other=True):
            return lambda f: np.subtract(0.0, f.other_minus_own_pos())  # same bits, +0
        if ta == NUM and tb == VEC:
            return lambda f: op(_col(a(f)), b(f))
        if ta == VEC and tb == NUM:
            return lambda f: op(a(f), _col(b(f)))
        return lambda f: op(a(f), b(f))

    def visit_Chain(self, e):
        """One closure that folds the terms left to right: no nesting per term."""
        first = self.expr(e.first)
        if e.rest[0][0] in ("and", "or"):
            terms = [first, *(self.expr(t) for _, t in e.rest)]
            is_and = e.rest[0][0] == "and"
            ufunc = np.logical_and if is_and else np.logical_or

            def logical(f):
                acc = terms[0](f)
                for term in terms[1:]:
                    acc = ufunc(acc, term(f))
                return acc

            def checked_logical(f):
                acc = terms[0](f)
                for term in terms[1:]:
                    acc = ufunc(acc, draws.live(f, acc if is_and else np.logical_not(acc),
                                                term))
                return acc
            return checked_logical if draws.guarded(e, self.info.params) else logical
        steps = []
        t = self.type_of(e.first)
        for op, term in e.rest:
            tb = self.type_of(term)
            steps.append((ARITHMETIC[op].numpy, self.expr(term), t == NUM and tb == VEC,
                          t == VEC and tb == NUM))
            t = VEC if VEC in (t, tb) else NUM

        def arithmetic(f):
            acc = first(f)
            for ufunc, term, col_acc, col_term in steps:
                b = term(f)
                if col_acc:
                    acc = ufunc(_col(acc), b)
                elif col_term:
                    acc = ufunc(acc, _col(b))
                else:
                    acc = ufunc(acc, b)
            return acc
        return arithmetic

    def _is_pos(self, e: ast.Expr, other: bool = False) -> bool:
        """Whether `e` is `pos` (or, with `other`, `other.pos`) inside a neighbour filter."""
        want = ("other_state", "pos") if other else ("state", "pos")
        return (isinstance(e, ast.Attr if other else ast.Name)
                and tuple(self.facts.name_of(e, ())[:2]) == want)

    def visit_Neg(self, e):
        a = self.expr(e.operand)
        negate = NEGATE.numpy
        return lambda f: negate(a(f))

    def visit_Compare(self, e):
        a, b = self.expr(e.left), self.expr(e.right)
        if e in self._nan_guarded:
            hint = "NaN compares false, so this `when` would silently never fire"
            a = nan_guard.guard(a, e.left.span, "the left side of this comparison", hint)
            b = nan_guard.guard(b, e.right.span, "the right side of this comparison", hint)
        op = COMPARISONS[e.op].numpy
        if self.type_of(e.left) == VEC:
            if e.op == "==":
                return lambda f: np.all(np.equal(a(f), b(f)), axis=-1)
            return lambda f: np.any(np.not_equal(a(f), b(f)), axis=-1)
        return lambda f: op(a(f), b(f))

    def visit_AndOp(self, e):
        a, b = self.expr(e.left), self.expr(e.right)
        if draws.guarded(e, self.info.params):
            def checked_and(f):
                left = a(f)
                return np.logical_and(left, draws.live(f, left, b))
            return checked_and
        return lambda f: np.logical_and(a(f), b(f))

    def visit_OrOp(self, e):
        a, b = self.expr(e.left), self.expr(e.right)
        if draws.guarded(e, self.info.params):
            def checked_or(f):
                left = a(f)
                return np.logical_or(left, draws.live(f, np.logical_not(left), b))
            return checked_or
        return lambda f: np.logical_or(a(f), b(f))

    def visit_NotOp(self, e):
        a = self.expr(e.operand)
        return lambda f: np.logical_not(a(f))

    def visit_Cond(self, e):
        t, a, b = self.expr(e.test), self.expr(e.then), self.expr(e.orelse)
        vtype = self.type_of(e)
        if draws.guarded(e, self.info.params):
            def checked_cond(f):
                test = t(f)
                return _where_vec(test, draws.live(f, test, a),
                                  draws.live(f, np.logical_not(test), b), vtype)
            return checked_cond
        return lambda f: _where_vec(t(f), a(f), b(f), vtype)

    def visit_Where(self, e):
        src, cond = self.expr(e.source), self.expr(e.cond)

        def where(f, pairs):
            keep = broadcast(cond(pairs.pair_frame()), pairs.seg.size, BOOL)
            return pairs.subset(np.asarray(keep, dtype=bool))
        return self.lowering.filter(self, e, src, where)

    def visit_Call(self, e):
        res = self.facts.name_of(e)
        if e.name in CALL_CODEGEN:
            return CALL_CODEGEN[e.name](self, e)
        if res is None:
            raise SwarmRuntimeError(f"internal: unresolved call `{e.name}`", e.span)
        if res[0] == "neighbors":
            r = self.expr(e.args[0]) if e.args else (lambda f: None)
            return lambda f: f.neighbors(r(f))
        if res[0] == "agg":
            return self._aggregate(e)
        kernel = FUNCTIONS[e.name].numpy
        args = [self.expr(a) for a in e.args]
        if FUNCTIONS[e.name].random:
            kernel = draws.checked(e.name, e, kernel, self.info.params)
            return _sited(kernel, args, stream_places.place_of(self.info, e))
        return lambda f: kernel(f, *[a(f) for a in args])

    def _aggregate(self, e: ast.Call):
        """The reference closure of aggregate call `e`: its row's form from the pairs."""
        from swarmdsl.compiler.builtins import AGGREGATES

        form = AGGREGATES[e.name].pairs
        src = self.expr(e.args[0])
        each = self.expr(e.each) if e.each is not None else None
        default = self.expr(e.default) if e.default is not None else (lambda f: 0.0)
        vtype = self.type_of(e)
        each_type = self.type_of(e.each) if e.each is not None else None

        def aggregate(f):
            pairs = src(f)
            m = f.n
            return form(pairs, m,
                        lambda: broadcast(each(pairs.pair_frame()), pairs.seg.size, each_type),
                        lambda: broadcast(default(f), m, vtype), vtype)
        return self.lowering.aggregate(self, e, aggregate)

    # ---- statements ----
    def stmts(self, stmts, kind, status: str):
        out = [self.stmt(s, kind, status) for s in stmts]
        self.lowering.statement_list(self, stmts)
        return out

    def stmt(self, st: ast.Stmt, kind, status: str):
        """The closure of statement `st` of status `status` of `kind`."""
        return self.visit(st, kind, status)

    def visit_LetStmt(self, st: ast.LetStmt, kind, status: str):
        value, built = self.recorded(st.value)
        vtype = self.type_of(st.value)
        name = st.name
        guarded = (f"`{name}`", LET_NAN_HINT)
        if vtype in (NUM, VEC):
            value = nan_guard.guard(value, st.span, *guarded)

        def let(f):
            v = value(f)
            f.locals[name] = v if vtype in RAW_LET_TYPES else broadcast(v, f.n, vtype)
        return self.lowering.statement(self, st, let, built, let_guard=guarded)

    def visit_AssignStmt(self, st: ast.AssignStmt, kind, status: str):
        return self._assign(st, (kind.name, status))

    def visit_WhenStmt(self, st: ast.WhenStmt, kind, status: str):
        return self._when(st, kind, status)

    def visit_ActionStmt(self, st: ast.ActionStmt, kind, status: str):
        from swarmdsl.compiler.actions import ACTIONS

        return ACTIONS[st.name].compile(self, st, kind)

    def _assign(self, st: ast.AssignStmt, where):
        res = self.facts.name_of(st)
        col = res[1]
        value, built = self.recorded(st.value)
        vtype = self.type_of(st.value)
        target_type = VEC if col == "vel" else self.info.kind(where[0]).vars[col].type
        op = {"=": None, "+=": np.add, "-=": np.subtract, "*=": np.multiply,
              "/=": np.true_divide}[st.op]
        span = st.span

        def nonfinite(f, new, bad):
            """The located error for the non-finite values `new` at running rows `bad`."""
            row = int(f.idx[np.flatnonzero(bad)[0]])
            agent_id = int(f.sim.agents.cols["id"][row])
            return SwarmRuntimeError(
                f"`{st.target}` became {_badness(new, bad)} for agent {agent_id} "
                f"(kind `{where[0]}`, status `{where[1]}`) at tick {f.tick}",
                span, "guard the division or square root that produced it")

        def assign(f):
            cur = f.state(col)
            v = value(f)
            if op is None:
                new = broadcast(v, f.n, target_type)
            elif target_type == VEC and vtype == NUM:
                new = op(cur, _col(v))
            else:
                new = op(cur, v)
            new = np.asarray(new, dtype=cur.dtype) if target_type != BOOL else new
            mask = f.active
            if target_type in (NUM, VEC):
                bad = ~np.isfinite(new)
                if bad.ndim == 2:
                    bad = bad.any(axis=1)
                bad &= mask
                if bad.any():
                    raise nonfinite(f, new, bad)
            f.overlay[col] = np.where(_col(mask) if target_type == VEC else mask, new, cur)

        return self.lowering.statement(self, st, assign, built, target_type, nonfinite)

    def _when(self, st: ast.WhenStmt, kind, status):
        self._nan_guarded = nan_guard.guarded_compares(st.cond)
        try:
            cond = self.expr(st.cond)
        finally:
            self._nan_guarded = NodeTable()
        code = self.program.status_code(kind.name, st.target)
        body = self.stmts(st.body, kind, status)

        def when(f):
            fire = np.logical_and(broadcast(cond(f), f.n, BOOL), f.active)
            if not fire.any():
                return
            f.next_status[fire] = code
            rest = f.active & ~fire
            f.active = fire
            for s in body:
                s(f)
            f.active = rest
        return when

    def status_body(self, kind, decl: ast.StatusDecl):
        body = list(zip(self.stmts(decl.body, kind, decl.name), decl.body, strict=True))

        def run(f):
            for s, st in body:
                try:
                    s(f)
                except SwarmError:
                    raise
                except Exception as exc:    # a fault of a kernel: name the statement
                    raise SwarmRuntimeError(
                        f"status `{decl.name}` of `{kind.name}` failed at tick {f.tick}: "
                        f"{exc}", st.span) from exc
                if not f.active.any():
                    break
        return run

    def init_value(self, expr: ast.Expr, vtype: str, what: str = "the initial value",
                   inf_ok: bool = False):
        """An initialiser evaluated per agent when placing; NaN (and an infinity, unless
        `inf_ok`: `max_speed`'s "no limit") is refused there, not left to do harm later."""
        fn = self.expr(expr)

        def value(f):
            return np.array(broadcast(fn(f), f.n, vtype))
        if vtype in (NUM, VEC):
            guard = nan_guard.guard if inf_ok else nan_guard.finite_guard
            value = guard(value, expr.span, what, LET_NAN_HINT)
        return value


def _sited(kernel, args, site: str):
    """A random call draws from its own sub-stream, so other calls never shift its draws;
    `site` is its place in the program's structure (`stream_places.py`), so comments and
    layout never shift them either."""
    def call(f):
        values = [a(f) for a in args]
        rng = f.rng
        f.rng = rng.at(site)
        try:
            return kernel(f, *values)
        finally:
            f.rng = rng
    return call


def _badness(new, bad) -> str:
    """What the first bad row (the agent the message names) holds: NaN or infinite."""
    first = np.asarray(new)[np.flatnonzero(bad)[0]]
    return "NaN" if np.isnan(first).any() else "infinite"

