"""Whether a program's whole tick can run as one compiled call, and the steps it takes.

`plan_tick(program)` lowers every status body of a checked program into a list of
steps over one agent (`tick_kernel.py` composes them into one jitted function that
runs several ticks): its statements in source order, with the values they read and
compute in the columns of a per-agent scratch table `S`.

Steps (tuples, the first item names the step):

- `("tree", col, tree)`: `S[i, col]` = scalar tree `tree` (the trees of `plan.Planner`
  and `stmt_plan.StatementPlanner`) over `S` and the agent's row of the state table,
  whose leaves `("o", c)` read column `c`: the agent's own state as it is at that
  point of its body (its writes this tick included, as `AgentFrame.state` reads them),
  or a constant (the table's last columns hold the program's numbers, params and
  `tick`, the same in every row, so a plan's shape holds no numbers).
- `("agg", name, two, cond, each, out, default)`: a neighbour aggregate over the
  cells around the agent, in the cell list's order, finished as the reference closure
  finishes it, into `S[i, out...]`: a sum (`count`, `sum`, `mean`, `any`, `all`;
  `siblings` joins several into one loop) or a pick (`min`, `max`: the extreme value,
  `nearest`: the value at the nearest pair, the lowest row among equally near ones),
  with the `else` (`default`, its columns) when no pair counts.
- `("draw", name, site, args, out)`: a counter-based draw from draw site `site`'s
  stream (keyed as `randomness.RandomSource.call_key` keys it), its arguments checked
  as `compiler/draws.py` checks them.
- `("nan", cols)` / `("finite", cols)`: a `let`'s NaN guard, a `when` comparison's
  guard / an assignment's check: a failing value stops the kernel before the tick
  commits, and the tick runs again on the reference path, which raises the located
  error.
- `("write", tcol, width, op, cols)`: an assignment to state-table column `tcol`.
- `("when", col, code, body)`: a transition; the agent's next status becomes `code`,
  `body` runs, and the rest of the status body is skipped for it (first match wins).

A `let` of a neighbour set (`neighbors(r)`, or such a set `where COND`) is no step:
its limit and its filters' condition are and-ed into each aggregate over it, the
filters' owner values worked out where the `let` stands. So is a robot's field of
view (`sensing.view_tree`), when the program's sensing only selects neighbours by
place (no noise, dropout or resolution): the sums over one set test it once a pair.

- `("bt", ...)`: a `tree` statement, walked per agent (`tree_plan.py`); its leaves'
  steps run when the walk reaches them, and `TickPlan.settles` forgets its stamp for
  the agents that leave the status. `inside` and `distance_to` of declared circles
  are trees.
- `("fread", what, row, x, y, out)`: a field read at the point in S columns x, y
  (`sample`, `F at P`, `ahead`: the bilinear reading; `gradient`);
  `("deposit", on, amount)`: a deposit, added to the grid once the agents' steps are
  done (`tick_fields.py`, with decay and diffusion after the move, and the twins
  whose formula reads `tick`: `TickPlan.twins`).

Anything else (other actions, path memories, messages, `nn()`, extensions, neighbour sets
from anything but `neighbors(r)`, a draw per pair) raises
`Unsupported` naming the construct and its line: the run keeps the per-tick path,
and `-v` says why. Planning imports no numba.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import BOOL, FUNCTIONS, NUM, STATUS, VEC
from swarmdsl.compiler.nan_guard import guarded_compares
from swarmdsl.compiler.tree_ast import TreeResult, TreeStmt
from swarmdsl.runtime import sensing
from swarmdsl.runtime.agents import BUILTIN_COLUMNS
from swarmdsl.runtime.compiled import tree_plan
from swarmdsl.runtime.compiled.plan import Planner, Unsupported
from swarmdsl.runtime.compiled.stmt_plan import StatementPlanner, _power, _share
from swarmdsl.runtime.environment import kernel_blockers
from swarmdsl.runtime.trees import LEAF_COLUMN, RESULT_COLUMN, RESULT_KEY, TreeMemory

RECORDED = (LEAF_COLUMN, RESULT_COLUMN)   # agent columns a run may not have

SUMS = ("count", "sum", "mean", "any", "all")
PICKS = ("min", "max", "nearest")   # one pair's value (or the else) per agent
DRAWS = ("random", "uniform", "normal", "chance", "random_direction")
# Columns of the state table worked out at the start of every tick from the others:
# `speed` (the length of `vel`, as `vec_length`) and the status's name id (what
# `status` and `other.status` read).
DERIVED = ("speed", "status_name")


class TableLayout:
    """Where each agent column sits in the (N, C) float64 state table."""

    def __init__(self, program):
        self.cols: dict[str, tuple[int, int]] = {}   # name -> (first column, width)
        c = 0
        for name, (tail, _dtype) in BUILTIN_COLUMNS.items():
            w = 2 if tail else 1
            self.cols[name] = (c, w)
            c += w
        for name in DERIVED:
            self.cols[name] = (c, 1)
            c += 1
        self.vars: list[str] = []
        for name, (tail, _dtype, _fill) in program.var_specs.items():
            w = 2 if tail else 1
            self.cols[name] = (c, w)
            self.vars.append(name)
            c += w
        # the trees' memory (`trees.Layout`): stamps, kept children, counts, deadlines;
        # then each agent's active leaf and tree result, which a run has only while
        # something records them (`trees.record_active_leaf`), zeroed every tick
        self.memory: list[str] = []
        tree_layout = getattr(program, "tree_layout", None)
        if tree_layout is not None:
            for name in (*(n for n, _d, _f in tree_layout.columns), *RECORDED):
                self.cols[name] = (c, 1)
                self.memory.append(name)
                c += 1
        self.width = c

    def at(self, name: str) -> int:
        return self.cols[name][0]


@dataclass
class TickPlan:
    """Every status body as steps, and what the kernel needs besides."""

    layout: TableLayout
    bodies: dict[int, list]                 # global status code -> its steps
    s_width: int                            # columns of the scratch table S
    consts: list = field(default_factory=list)   # from column layout.width: floats,
    #   "tick" (set every tick), or ("derived", tree): the tree over the agent's own
    #   columns, worked out in the sorted table every tick
    sites: list = field(default_factory=list)    # draw streams, one per draw site
    radius: float = 0.0                     # the tick's pair table radius
    next_status: int = 0                    # the S column holding the next status
    # after the agents' steps, per tree that keeps memory: (S[0, flag]: the statement
    # ran this tick, S column: the agent took a transition, status code, stamp column):
    # its stamp is forgotten for the agents of that status that left (`Tree._left`)
    settles: list = field(default_factory=list)
    # the environment's grids the kernel holds (`tick_fields.py`): their names, one row
    # each of its values (a vector twin's components as `NAME.x`, `NAME.y`), and the
    # deposits in the order the reference applies them: (row, S column set when the
    # agent deposited this tick, S column of its amount)
    field_rows: list = field(default_factory=list)
    deposits: list = field(default_factory=list)
    # twins whose formula reads `tick`, worked out for every node after the move for
    # the next tick: (row, scalar tree over the node's position, S columns 0 and 1,
    # and `twin_consts`, read as row 0 of a table: floats, or "tick", the next tick)
    twins: list = field(default_factory=list)
    twin_consts: list = field(default_factory=list)


def _line(node) -> str:
    span = getattr(node, "span", None)
    return f" at line {span.line}" if span is not None else ""


class _Body:
    """The steps of one status body being planned, and the columns they use."""

    def __init__(self, tick: _TickBuilder, kind, status: str):
        self.tick, self.kind, self.status = tick, kind, status
        self.steps: list = []
        self.locals: dict[str, tuple] = {}   # let name -> its value trees
        self.left: int | None = None   # S column: the agent took a transition (trees)
        self.in_tree = False           # a tree leaf's steps (`tree_plan.py`)
        # let name of a neighbour set -> (its limit column, its filters' pair condition
        # over S and T columns, or None): `let near = neighbors(r) where COND`
        self.sets: dict[str, tuple] = {}

    # ---- columns ----
    def column(self, width: int = 1) -> int:
        return self.tick.column(width)

    def store(self, trees: tuple, boolean: bool = False) -> tuple:
        """Trees stored into fresh columns (shared subtrees once, `_share`): the
        leaves that read them back."""
        first = self.tick.s_width
        stages, trees = _share(trees, first)
        self.tick.s_width += len(stages)
        for col, tree in stages:
            self.steps.append(("tree", col, tree))
        out = []
        for tree in trees:
            if tree[0] in ("s", "sb"):
                out.append(tree)
                continue
            col = self.column()
            self.steps.append(("tree", col, tree))
            out.append(("sb" if boolean else "s", col))
        return tuple(out)


class _TickBuilder:
    def __init__(self, program):
        from swarmdsl.compiler.codegen import CodeGen

        self.program = program
        self.info = program.info
        self.cg = CodeGen(program.info, program)   # types and names only: builds nothing
        self.layout = TableLayout(program)
        self.wraps = program.world.edges == "wrap"
        self.s_width = 1        # column 0: the agent's next status
        self.consts: list = []
        self.settles: list = []
        # the program's regions, when its environment holds nothing else (static)
        self.regions = next((make.regions for make in program.extensions
                             if getattr(make, "regions", None) is not None), None)
        # its fields and twins (`environment.kernel_blockers`: none), one row each
        self.env = next((make.fields for make in program.extensions
                         if getattr(make, "fields", None) is not None), None)
        self.field_rows: list[str] = [] if self.env is None else [
            *(f.name for f in self.env.fields),
            *(f"{t.name}.{a}" for t in self.env.twins if t.vector for a in "xy")]
        self.vector_fields = set() if self.env is None else {
            t.name for t in self.env.twins if t.vector}
        self.deposits: list = []
        self.twins: list = []
        self.twin_consts: list = []
        self.sites: list = []
        # the robots' fields of view (`sensing.SensingSpec`), tested in the pair loops
        self.views = next((make.views for make in program.extensions
                           if getattr(make, "views", None) is not None), None)

    def constant(self, tree) -> bool:
        """Whether scalar tree `tree` reads constants only (no agent's value)."""
        if tree[0] in ("o", "ob"):
            return tree[1] >= self.layout.width
        if tree[0] in ("s", "sb", "d", "dx", "dy"):
            return False
        return all(self.constant(t) for t in tree[1:] if isinstance(t, tuple))

    def neighbour_columns(self, others, e) -> dict:
        """Where an aggregate plan's neighbour columns are in the state table (the
        sorted copy `T` the pairs read): `other.X` at X's own columns, a derived
        column (`plan.py`: a subexpression of the neighbour alone) at a column of its
        own, worked out for every agent once a tick."""
        omap = {}
        c = 0
        for cat, col, vt in others:
            w = 2 if vt == VEC else 1
            if cat == "derived":
                tree, base = col
                inner = self.neighbour_columns(base, e)
                omap[c] = self.const(("derived", _remap(tree, {}, inner)))
                c += 1
                continue
            name = {"status": "status_name"}.get(col, col)
            if cat not in ("other_state", "other_var") or name not in self.layout.cols:
                what = f"`{e.name}(...)`" if isinstance(e, ast.Call) else "`where`"
                raise Unsupported(f"{what} reads `other.{col}`{_line(e)}")
            first = self.layout.at(name)
            for k in range(w):
                omap[c + k] = first + k
            c += w
        return omap

    def column(self, width: int = 1) -> int:
        c = self.s_width
        self.s_width += width
        return c

    def const(self, value) -> int:
        """The state-table column of constant `value` (a float, or "tick")."""
        self.consts.append(value)
        return self.layout.width + len(self.consts) - 1

    def plan(self) -> TickPlan:
        self.changing_twins()
        bodies = {}
        for k in self.info.kinds:
            for s in k.statuses:
                body = _Body(self, k, s)
                if tree_plan.memory_trees(self.program, k.name, s):
                    body.left = body.column()
                    body.steps.append(("tree", body.left, ("o", self.const(0.0))))
                self.statements(body, k.status_decls[s].body)
                bodies[self.program.status_code(k.name, s)] = siblings(body.steps)
        return TickPlan(self.layout, bodies, self.s_width, self.consts, self.sites,
                        float(self.program.pair_radius), 0, self.settles,
                        self.field_rows, self.deposits, self.twins, self.twin_consts)

    def changing_twins(self) -> None:
        """Every twin whose formula reads `tick`, as scalar trees (`stmt_plan`'s) over
        the node's position and constants, one per component: the kernel works them out
        at every node after the move, for the next tick (`Environment._update_twins`).
        A formula that reads anything else per node (a random draw: per node and tick
        from the run's streams) is refused with its line."""
        if self.env is None:
            return
        formulas = self.info.extra["env"].twins
        for t in self.env.twins:
            if t.static:
                continue
            formula = formulas[t.name].formula
            planner = StatementPlanner(self.cg)
            try:
                trees = planner.value(formula)
            except Unsupported as exc:
                raise Unsupported(f"the formula of twin `{t.name}`{_line(formula)}: {exc}") \
                    from None
            if any(self.cg.facts.name_of(e, None) != ("state", "pos")
                   for e, _t in planner.columns):
                raise Unsupported(f"the formula of twin `{t.name}`{_line(formula)} draws "
                                  "random numbers or reads what the kernel does not hold")
            base = len(self.twin_consts)
            for v in planner.consts:
                if not isinstance(v, float) and getattr(v, "id", None) != "tick":
                    raise Unsupported(f"the formula of twin `{t.name}`{_line(formula)}")
                self.twin_consts.append(v if isinstance(v, float) else "tick")
            rows = (f"{t.name}.x", f"{t.name}.y") if t.vector else (t.name,)
            for row, tree in zip(rows, trees, strict=True):
                self.twins.append((self.field_row(row, formula), _shifted(tree, base)))

    def tree_flag(self, body: _Body, stamp: int) -> int:
        """The scratch cell `S[0, flag]` of a tree that keeps memory (its stamp in
        state-table column `stamp`): set when its statement runs, so the agents of its
        status that left forget the stamp."""
        flag = self.column()
        code = self.program.status_code(body.kind.name, body.status)
        self.settles.append((flag, body.left, code, stamp))
        return flag

    def inner_body(self, body: _Body) -> _Body:
        """A body of its own for steps run under a condition (a `when`'s, a tree
        leaf's), with `body`'s lets and neighbour sets in scope."""
        inner = _Body(self, body.kind, body.status)
        inner.locals, inner.sets = dict(body.locals), dict(body.sets)
        inner.left, inner.in_tree = body.left, body.in_tree
        return inner

    # ---- statements ----
    def statements(self, body: _Body, stmts) -> None:
        for st in stmts:
            self.statement(body, st)

    def statement(self, body: _Body, st) -> None:
        if isinstance(st, ast.LetStmt):
            self.let(body, st)
        elif isinstance(st, ast.AssignStmt):
            self.assign(body, st)
        elif isinstance(st, ast.WhenStmt):
            self.when(body, st)
        elif isinstance(st, TreeStmt):
            step = tree_plan.TreePlanner(self, body).step(st)
            body.steps.append(step)
            body.locals[RESULT_KEY] = (("s", step[4]),)   # what `tree succeeded` reads
        elif isinstance(st, ast.ActionStmt) and st.name == "deposit":
            self.deposit(body, st)
        elif isinstance(st, ast.ActionStmt):
            raise Unsupported(f"the action `{st.name}`{_line(st)}")
        else:
            raise Unsupported(f"a {type(st).__name__}{_line(st)}")

    def deposit(self, body: _Body, st: ast.ActionStmt) -> None:
        """`deposit(F, amount)`: the amount kept per agent, added to the grid after the
        agents' steps (`Simulation._run_frames` runs the effects after the commit), at
        the agent's position at the start of the tick, deposits in source order."""
        from swarmdsl.compiler.consteval import const_value

        if len(st.args) == 3 and float(const_value(st.args[2], self.info.params)) != 0.0:
            raise Unsupported(f"a deposit with a radius{_line(st)}")
        row = self.field_row(st.args[0].id, st)
        amount, = body.store(self.lower(body, st.args[1]))
        on = body.column()
        self.deposits.append((row, on, amount[1]))
        body.steps.append(("deposit", on, amount[1]))

    def field_row(self, name: str, node) -> int:
        if name not in self.field_rows:
            raise Unsupported(f"the field `{name}` of a changing environment{_line(node)}")
        return self.field_rows.index(name)

    def let(self, body: _Body, st: ast.LetStmt) -> None:
        t = self.cg.type_of(st.value)
        value = st.value
        if t not in (NUM, VEC, BOOL):
            got = self.neighbour_set(body, value)
            if got is None:
                raise Unsupported(f"`let {st.name}` of a {t}{_line(st)}")
            body.sets[st.name] = got
            return
        trees = self.lower(body, value)
        got = body.store(trees, boolean=t == BOOL)
        if t in (NUM, VEC):
            body.steps.append(("nan", tuple(leaf[1] for leaf in got)))
        body.locals[st.name] = got

    def neighbour_set(self, body: _Body, value) -> tuple | None:
        """(limit column, pair condition or None) of a neighbour set a `let` names:
        `neighbors(r)`, or a set of those (or of another such `let`) `where COND`, its
        filters' owner values worked out here, where the `let` stands (the reference
        filters the pairs at this point), the neighbour's from the start of the tick;
        None for any other set."""
        conds = []
        while isinstance(value, ast.Where):
            conds.append(value)
            value = value.source
        if isinstance(value, ast.Call) and \
                self.cg.facts.name_of(value, ())[:1] == ("neighbors",):
            limit = self.limit(body, value)
            cond = self.view(body, limit)
        elif isinstance(value, ast.Name) and value.id in body.sets and \
                self.cg.facts.name_of(value, ())[:1] == ("local",):
            limit, cond = body.sets[value.id]
        else:
            return None
        for where in reversed(conds):   # innermost first, as the reference filters
            try:
                plan = Planner(self.cg, self.wraps).filter(where)
            except Unsupported as exc:
                raise Unsupported(f"a neighbour set `where`{_line(where)}: {exc}") from None
            tree, = _TickPlanner(self, body).pair_trees(plan, (plan.cond,), where)
            cond = tree if cond is None else ("and", cond, tree)
        return limit, cond

    def limit(self, body: _Body, call: ast.Call) -> int:
        """The column of `neighbors(r)`'s limit per agent: its sense radius, or the
        smaller of it and `r` (`AgentFrame.neighbors`, `np.minimum`)."""
        col = body.column()
        sense = self.load(body, "sense")
        if call.args:
            r = self.lower(body, call.args[0])
            body.steps.append(("tree", col, ("min", sense, r[0])))
        else:
            body.steps.append(("tree", col, sense))
        return col

    def view(self, body: _Body, limit: int) -> tuple | None:
        """The pair condition of the agent's field of view and `neighbors(r)`'s limit
        (column `limit`), `sensing.view_tree` over the tick's tables; None when its
        kind's sensing lets every pair through (or it has none)."""
        if self.views is None:
            return None
        view = self.views.view(self.info.kinds.index(body.kind))
        if view.everything:
            return None
        heading, = body.store((self.load(body, "heading"),))
        smap = {}
        for c, value in enumerate(view.columns(limit, heading[1])):
            smap[c] = value if c < 2 else ("o", self.const(float(value)))
        return _remap(sensing.view_tree(view.fov), smap, {})

    def load(self, body: _Body, name: str) -> tuple:
        """The leaf (a vector: leaves) of the agent's own value of state column `name`,
        read when the step that holds it runs."""
        first, width = self.layout.cols[name]
        if width == 1:
            return ("o", first)
        return (("o", first), ("o", first + 1))

    def assign(self, body: _Body, st: ast.AssignStmt) -> None:
        res = self.cg.facts.name_of(st)
        col = res[1]
        kind = self.info.kind(body.kind.name)
        target = VEC if col == "vel" else kind.vars[col].type
        if target not in (NUM, VEC):
            raise Unsupported(f"an assignment to a {target}{_line(st)}")
        trees = self.lower(body, st.value)
        got = body.store(trees)
        width = 2 if target == VEC else 1
        body.steps.append(("write", self.layout.at(col), width, st.op,
                           tuple(leaf[1] for leaf in got)))

    def when(self, body: _Body, st: ast.WhenStmt) -> None:
        guarded = guarded_compares(st.cond)
        trees = self.lower(body, st.cond, guarded)
        got = body.store(trees, boolean=True)
        inner = self.inner_body(body)
        if body.left is not None:   # the agent leaves: its trees forget their stamps
            inner.steps.append(("tree", body.left, ("o", self.const(1.0))))
        self.statements(inner, st.body)
        code = self.program.status_code(body.kind.name, st.target)
        body.steps.append(("when", got[0][1], code, inner.steps))

    def lower(self, body: _Body, e, guarded=frozenset()) -> tuple:
        planner = _TickPlanner(self, body, guarded)
        return planner.value(e)


class _TickPlanner(StatementPlanner):
    """The statement planner with every leaf a column of the tick's scratch table:
    state reads are loads, `let`s their own columns, aggregates and draws steps of
    their own."""

    def __init__(self, tick: _TickBuilder, body: _Body, guarded=frozenset()):
        super().__init__(tick.cg)
        self.tick, self.body, self.guarded = tick, body, guarded

    def _agent_column(self, e, vtype: str, slot=None):
        res = self.res(e)
        cat = res[0] if res else None
        if cat == "local":
            got = self.body.locals.get(res[1])
            if got is None:
                raise Unsupported(f"`{e.id}` is not a number, vector or boolean let"
                                  f"{_line(e)}")
            return got if vtype == VEC else (got[0],)
        if cat in ("state", "var"):
            name = res[1]
            if name == "status":
                return (self.tick.load(self.body, "status_name"),)
            if name == "speed":
                v = self.tick.load(self.body, "vel")
                return (("sqrt", ("add", ("mul", v[0], v[0]), ("mul", v[1], v[1]))),)
            if name not in self.tick.layout.cols:
                raise Unsupported(f"`{name}`{_line(e)}")
            got = self.tick.load(self.body, name)
            if vtype == VEC:
                return got
            return ((("ob",) + got[1:]) if vtype == BOOL else got,)
        return self._opaque(e)

    def _const(self, value, vtype: str):
        c = self.tick.const("tick" if not isinstance(value, float) else value)
        return (("ob", c),) if vtype == BOOL else (("o", c),)

    def _opaque(self, e):
        if _power(e):
            return self.visit_BinOp(e)
        if isinstance(e, TreeResult):   # this tick's result code of the last tree
            from swarmdsl.runtime.trees import FAILURE, RUNNING, SUCCESS

            code = {"succeeded": SUCCESS, "failed": FAILURE, "running": RUNNING}[e.state]
            got = self.body.locals.get(RESULT_KEY)
            if got is None:
                raise Unsupported(f"a tree's result before its tree{_line(e)}")
            return (("eq", got[0], ("o", self.tick.const(float(code)))),)
        if isinstance(e, ast.Call):
            res = self.res(e)
            if res[:1] == ("agg",):
                return self.aggregate(e)
            if e.name in ("inside", "distance_to"):
                return self.region_distance(e)
            if res[:1] == ("env_call",) and e.name in ("sample", "gradient", "ahead"):
                return self.field_read(e)
            b = FUNCTIONS.get(e.name)
            if b is not None and b.random and not self.cg.extension_call(e.name):
                return self.draw(e)
            raise Unsupported(f"`{e.name}(...)`{_line(e)}")
        if isinstance(e, ast.FieldAt):
            return self.field_read(e)
        raise Unsupported(f"this expression{_line(e)}")

    def visit_Compare(self, e):
        if e not in self.guarded:
            return super().visit_Compare(e)
        sides = []
        for side in (e.left, e.right):   # a `when`'s own comparison: NaN is an error
            trees = self.body.store(self.value(side))
            self.body.steps.append(("nan", tuple(leaf[1] for leaf in trees)))
            sides.append(trees)
        a, b = sides
        from swarmdsl.ops.operators import COMPARISONS

        if len(a) == 2:
            if e.op == "==":
                return (("and", ("eq", a[0], b[0]), ("eq", a[1], b[1])),)
            return (("or", ("ne", a[0], b[0]), ("ne", a[1], b[1])),)
        return ((COMPARISONS[e.op].node, a[0], b[0]),)

    # ---- regions ----
    def region_distance(self, e: ast.Call):
        """`distance_to(R)` / `inside(R)` of regions that are all circles, as
        `Environment.distances` works them out: each circle's `hypot` of the offset
        to its centre (the short way round a wrap-around world) less its radius, at
        least 0; the least of them (none: infinity); inside where it is 0."""
        from swarmdsl.runtime.environment import _circle_table

        regions = self.tick.regions
        if regions is None:
            raise Unsupported(f"`{e.name}(...)` of a changing environment{_line(e)}")
        name = e.args[0].id
        chosen = [r for r in regions if r.name == name] or [r for r in regions
                                                           if r.kind == name]
        circles = _circle_table(chosen)
        if chosen and circles is False:
            raise Unsupported(f"`{e.name}(...)` of a region that is not a circle{_line(e)}")
        const = self.tick.const
        px, py = self.tick.load(self.body, "pos")
        box = self.tick.program.world
        dist = ("o", const(float("inf")))
        for k in range(len(chosen)):
            cx, cy, r = (float(a[k]) for a in circles)
            dx, dy = ("sub", px, ("o", const(cx))), ("sub", py, ("o", const(cy)))
            if self.tick.wraps:
                dx, dy = _short_way(dx, const(float(box.width))), _short_way(
                    dy, const(float(box.height)))
            d, = FUNCTIONS["hypot"].trees((dx,), (dy,))
            d, = FUNCTIONS["max"].trees((("sub", d, ("o", const(r))),),
                                        (("o", const(0.0)),))
            dist = d if k == 0 else FUNCTIONS["min"].trees((dist,), (d,))[0]
        if e.name == "distance_to":
            return (dist,)
        return (("le", dist, ("o", const(0.0))),)

    # ---- fields ----
    def field_read(self, e):
        """`sample(F [, P])`, `F at P`, `gradient(F)` or `ahead(F, d [, turn])`: a
        `("fread", what, row, x, y, out)` step per component read (0: the bilinear
        reading, 1: the gradient) at the point in S columns x, y, where `lang_fields`
        reads them: at the agent, at P, or `d` along `heading + turn` (`Field.
        sample_ahead`'s arithmetic)."""
        tick, body = self.tick, self.body
        if tick.views is not None:   # out of view a reading is 0 (`field_reading`)
            raise Unsupported(f"a field read through a robot's sensing model{_line(e)}")
        if isinstance(e, ast.FieldAt):
            name, point = e.field.id, e.point
            if self.cg.facts.name_of(point, ())[:1] == ("own_pos",):
                point = None
        else:
            name, point = e.args[0].id, (e.args[1] if len(e.args) == 2 else None)
        ahead = isinstance(e, ast.Call) and e.name == "ahead"
        if (point is not None or ahead) and body.in_tree:
            # the reference reads a leaf's point for every agent ticking the tree: one
            # that is not finite is an error even for an agent the walk never takes there
            raise Unsupported(f"a field read at a point in a tree leaf{_line(e)}")
        px, py = tick.load(body, "pos")
        if ahead:
            h = tick.load(body, "heading")
            d = self.value(e.args[1])[0]
            turn = self.value(e.args[2])[0] if len(e.args) == 3 else ("o", tick.const(0.0))
            h = ("add", h, turn)
            px, py = ("add", px, ("mul", d, ("cos", h))), ("add", py, ("mul", d, ("sin", h)))
        elif point is not None:
            px, py = self.value(point)
        (_s, x), (_t, y) = body.store((px, py))
        if name in tick.vector_fields:
            rows = (tick.field_row(f"{name}.x", e), tick.field_row(f"{name}.y", e))
        else:
            rows = (tick.field_row(name, e),)
        gradient = isinstance(e, ast.Call) and e.name == "gradient"
        out = body.column(2 if gradient or len(rows) == 2 else 1)
        for k, row in enumerate(rows):
            body.steps.append(("fread", 1 if gradient else 0, row, x, y, out + k))
        if gradient or len(rows) == 2:
            return (("s", out), ("s", out + 1))
        return (("s", out),)

    # ---- draws ----
    def draw(self, e: ast.Call):
        from swarmdsl.compiler import stream_places

        if e.name not in DRAWS:
            raise Unsupported(f"the draw `{e.name}()`{_line(e)}")
        values = [self.value(a) for a in e.args]
        if self.body.in_tree and not all(self.tick.constant(t) for v in values for t in v):
            # the reference checks a leaf's draw arguments for every agent ticking the
            # tree, not only those reaching the leaf
            raise Unsupported(f"a draw in a tree leaf whose arguments vary{_line(e)}")
        args = tuple(self.body.store(v)[0][1] for v in values)
        place = stream_places.place_of(self.cg.info, e)
        stream = f"{self.body.kind.name}/{self.body.status}@{place}"
        site = len(self.tick.sites)
        self.tick.sites.append(stream)
        two = e.name == "random_direction"
        out = self.body.column(2 if two else 1)
        self.body.steps.append(("draw", e.name, site, args, out))
        if two:
            return (("s", out), ("s", out + 1))
        return (("sb", out),) if e.name == "chance" else (("s", out),)

    # ---- aggregates ----
    def aggregate(self, e: ast.Call):
        if e.name not in SUMS + PICKS:
            raise Unsupported(f"`{e.name}(...)`{_line(e)}")
        if not self.tick.program.pair_radius > 0:
            raise Unsupported(f"`{e.name}(...)` with no pair table{_line(e)}")
        try:
            plan = Planner(self.cg, self.tick.wraps).aggregate(e)
        except Unsupported as exc:
            raise Unsupported(f"`{e.name}(...)`{_line(e)}: {exc}") from None
        body = self.body
        cond = plan.cond
        limit = extra = None
        if not plan.neighbors_call:
            name = getattr(plan.source, "id", None)
            got = body.sets.get(name)
            if got is None:
                raise Unsupported(f"`{e.name}(...)` over a neighbour set that is not "
                                  f"`neighbors(r)`{_line(e)}")
            limit, extra = got
            cond = ("and", ("le", ("d",), ("s", -1)), cond)   # -1: the set's limit
        else:   # the agent's field of view, if its robot has one
            extra = self.tick.view(body, self.tick.limit(body, plan.source))
        cond, *each = self.pair_trees(plan, (cond, *plan.each), e, limit)
        if extra is not None:   # the set's own filters and view, tested first
            cond = ("if", extra, cond, ("not", ("true",)))
        each = tuple(each)
        default = None
        if e.name == "mean" or e.name in PICKS:
            if e.default is not None:
                default = tuple(leaf[1] for leaf in body.store(self.value(e.default)))
            else:
                default = (body.column(),)
                body.steps.append(("tree", default[0], ("o", self.tick.const(0.0))))
        two = plan.width == 2
        out = body.column(2 if two else 1)
        body.steps.append(("agg", e.name, two, cond, each, out, default))
        if two:
            return (("s", out), ("s", out + 1))
        boolean = e.name in ("any", "all") or (e.name == "nearest"
                                                and plan.each_type == BOOL)
        return (("sb", out),) if boolean else (("s", out),)

    def pair_trees(self, plan, trees, e, limit=None) -> tuple:
        """Pair trees `trees` of `plan` (an aggregate's or a filter's) over the tick's
        tables: their owner values worked out now into S columns (the plan's hoisted
        values; `limit`: the S column of leaf `("s", -1)`), their neighbour values read
        from the sorted state table T (the plan's `others`)."""
        body = self.body
        smap = {}
        c = 0
        for key, vt in plan.hoisted:
            w = 2 if vt == VEC else 1
            if key == "limit":
                cols = (self.tick.limit(body, plan.source),)
            elif isinstance(key, str):   # the agent's own position (wrap-around)
                cols = tuple(leaf[1] for leaf in body.store(self.tick.load(body, "pos")))
            else:
                # once per agent, constants too (`0.4 * radius`): read from the
                # agent's own row of S on every pair, not worked out again from the
                # neighbour's row of T (boids: three products and a division a pair)
                got = body.store(self.value(key), boolean=vt == BOOL)
                cols = tuple(leaf[1] for leaf in got)
            for k in range(w):
                smap[c + k] = cols[k]
            c += w
        if limit is not None:
            smap[-1] = limit
        omap = self.tick.neighbour_columns(plan.others, e)
        return tuple(_pair_dist(_remap(t, smap, omap)) for t in trees)


MAX_SIBLINGS = 4   # sums one loop over an agent's pairs adds up (`kernels.MAX_SIBLINGS`)


def _s_reads(tree) -> set:
    """The scratch columns scalar tree `tree` reads."""
    if tree[0] in ("s", "sb"):
        return {tree[1]}
    out: set = set()
    for t in tree[1:]:
        if isinstance(t, tuple):
            out |= _s_reads(t)
    return out


def _reads(step) -> set:
    what = step[0]
    if what == "tree":
        return _s_reads(step[2])
    if what == "agg":
        got = _s_reads(step[3])
        for t in step[4]:
            got |= _s_reads(t)
        return got | set(step[6] or ())
    if what in ("draw",):
        return set(step[3])
    if what == "fread":
        return {step[3], step[4]}
    if what == "deposit":
        return {step[2]}
    return set()


def _writes(step) -> set:
    what = step[0]
    if what == "tree":
        return {step[1]}
    if what == "agg":
        return {step[5], step[5] + 1} if step[2] else {step[5]}
    if what == "draw":
        return {step[4], step[4] + 1}
    if what == "fread":
        return {step[5], step[5] + 1} if step[1] == 1 else {step[5]}
    if what == "deposit":
        return {step[1]}
    return set()


def siblings(steps: list) -> list:
    """`steps` with later sums joined to an earlier one's loop over the agent's pairs
    (a step `("aggs", members)`, at most MAX_SIBLINGS, each adding its terms in the
    order its own loop would: the same bits). A sum joins if no assignment, transition
    or draw stands between them, and the steps between that compute what it reads
    (pure trees) can move before the loop; they move with it. Picks (`min`, `max`,
    `nearest`) keep their own loop over the pairs (written once per agent)."""
    steps = [("when", *st[1:3], siblings(st[3])) if st[0] == "when" else st
             for st in steps]
    out: list = []
    k = 0
    while k < len(steps):
        st = steps[k]
        if not _is_sum(st):
            out.append(st)
            k += 1
            continue
        members, moved, rest = [st[1:]], [], []
        j = k + 1
        while j < len(steps) and len(members) < MAX_SIBLINGS:
            nxt = steps[j]
            if nxt[0] in ("write", "when", "draw", "bt"):   # a tree writes state too
                break
            if not _is_sum(nxt):
                rest.append(nxt)
                j += 1
                continue
            need, deps = _reads(nxt), []
            for prev in reversed(rest):   # what it reads among the steps in between
                if _writes(prev) & need:
                    if prev[0] != "tree":
                        deps = None
                        break
                    deps.append(prev)
                    need |= _reads(prev)
            if deps is None:
                break
            deps.reverse()
            moved += deps
            rest = [x for x in rest if not any(x is d for d in deps)]
            members.append(nxt[1:])
            j += 1
        out += moved
        out.append(("aggs", tuple(members)) if len(members) > 1 else st)
        out += rest
        k = j
    return out


_DX = (("dx",), ("sub", ("zero",), ("dx",)))   # `other.pos - pos`, `pos - other.pos`
_DY = (("dy",), ("sub", ("zero",), ("dy",)))


def _pair_dist(tree):
    """`tree` with the length of the pair's delta (`length(pos - other.pos)`, the
    length in `normalize(...)`) read as the pair's `dist`: the same operations on the
    same values, `sqrt(dx * dx + dy * dy)` (`(0 - dx) * (0 - dx)` is `dx * dx` to the
    bit, signed zeros included), which the pair loop has already taken."""
    if not isinstance(tree, tuple) or not tree:
        return tree
    if (tree[0] == "sqrt" and tree[1][0] == "add"
            and tree[1][1][0] == "mul" and tree[1][2][0] == "mul"):
        (_m, a, b), (_n, c, d) = tree[1][1], tree[1][2]
        if a == b and c == d and a in _DX and c in _DY:
            return ("d",)
    return (tree[0], *(_pair_dist(t) if isinstance(t, tuple) else t for t in tree[1:]))


def _short_way(d, period: int):
    """`world.short_way` of offset tree `d` along an axis whose period is in
    state-table column `period`: `d - period * round(d / period)`."""
    p = ("o", period)
    turns, = FUNCTIONS["round"].trees((("div", d, p),))
    return ("sub", d, ("mul", p, turns))


def _shifted(tree, base: int):
    """`tree` with its constants' leaves (`o`, `ob`) `base` entries further on."""
    if tree[0] in ("o", "ob"):
        return (tree[0], tree[1] + base)
    return (tree[0], *(_shifted(t, base) if isinstance(t, tuple) else t
                       for t in tree[1:]))


def _is_sum(step) -> bool:
    return step[0] == "agg" and step[1] in SUMS


def _remap(tree, smap: dict, omap: dict):
    """`tree` with its owner columns (`s`, `sb`) and neighbour columns (`o`, `ob`)
    renumbered to the tick's scratch table and state table; an owner column whose
    value is a tree of constants (`smap` holds the tree) becomes that tree, read from
    the neighbour's row of the state table (every row holds the constants)."""
    op = tree[0]
    if op in ("s", "sb"):
        got = smap[tree[1]]
        return got if isinstance(got, tuple) else (op, got)
    if op in ("o", "ob"):
        return (op, omap[tree[1]])
    return (op, *(_remap(t, smap, omap) if isinstance(t, tuple) else t for t in tree[1:]))


def refusal(sim, watch=None) -> str | None:
    """Why `sim`'s ticks cannot run whole in one compiled call apart from the program
    itself (extensions, a sensing model, too few agents), or None. An extension that
    only watches ticks (`run --check`'s property checks: `driver.Watch`) is no bar
    when the call's `watch` covers it: the kernel does its watching."""
    if type(sim).step is not _solo_step():
        return "a batch of replicas steps its own way"
    covered = () if watch is None else getattr(watch, "covers", ())
    views = sim.sensing if sim.sensing is not None and sim.sensing.views_only else None
    for ext in sim.extensions:
        if ext is sim.environment and not kernel_blockers(ext):
            continue   # regions, fields and static twins: the kernel holds them
        if isinstance(ext, TreeMemory):
            continue   # its columns are in the kernel's table
        if not any(ext is c for c in covered) and ext is not views:
            return f"{type(ext).__name__} runs in Python every tick"
    env = sim.environment
    if (sim.sensing is not None and views is None) \
            or (env is not None and kernel_blockers(env)) or sim.maps is not None:
        return "a sensing model or environment runs in Python"
    if sim.agents.n < 2:
        return "fewer than two agents"
    memory = getattr(sim.program, "tree_layout", None)
    memory = {*(n for n, _d, _f in memory.columns), *RECORDED} if memory is not None else ()
    if any(name not in memory for name in sim.agents.extra_specs):
        return "an extension keeps agent columns"
    return None


def _watches_only(make) -> bool:
    """Whether the extension `make` builds only watches ticks (it offers a
    `driver.Watch`: `run --check`'s checks): it changes nothing a tick reads, so the
    program's plan holds with it; a run still takes whole ticks only when the driver's
    watch covers it (`refusal`)."""
    return callable(getattr(make, "watch", None))


def _solo_step():
    from swarmdsl.runtime.simulation import Simulation

    return Simulation.step


def plan_tick(program) -> TickPlan:
    """The whole-tick plan of `program`, or `Unsupported` saying why there is none."""
    for make in program.extensions:
        if _watches_only(make) or getattr(make, "views", None) is not None \
                or getattr(make, "tree_memory", False) \
                or getattr(make, "regions", None) is not None:
            continue
        if getattr(make, "spec", None) is not None:
            raise Unsupported("a robot's sensing model draws in Python (its dropout, "
                              "noise or resolution)")
        raise Unsupported(f"{getattr(make, 'runs', 'an extension of the program runs')} "
                          "in Python every tick")
    for name, t in program.var_types.items():
        if t not in (NUM, BOOL, VEC, STATUS):
            raise Unsupported(f"the variable `{name}` holds a {t}")
    return _TickBuilder(program).plan()
