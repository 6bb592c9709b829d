"""The C of one Kilobot kind: its statuses, statements and expressions, from the checked
AST and the checker's facts (`ProgramInfo.facts`: each node's type and resolution).

Nothing of the program's text reaches the C as such: identifiers are the checked names
(each matched against C's identifier syntax again here, prefixed so none can be a C
keyword or a library name), numbers are the checked constants printed by Python, and
every construct is written from a fixed template. What has no template is a `Refusal`
located at the construct, so no `.swarm` can put its own C into the output.

The templates of the language's rows live on the rows, beside their other forms: a
function's C function (`ops/functions.py`, `kilobot=`), an operator's and a
comparison's (`ops/operators.py`), an aggregate's loop step and result
(`compiler/builtins.AGGREGATES`), and a row's declared `Refused` becomes the located
refusal's hint. What stays here is how the program's structure maps to C: statuses,
statements, names, the neighbour table's loop.
"""

from __future__ import annotations

import math
import re

from swarmdsl.compiler import ast
from swarmdsl.compiler.actions import ACTIONS, STATEMENTS
from swarmdsl.compiler.builtins import (
    AGGREGATES,
    BOOL,
    CALLS,
    NUM,
    SET,
    STATUS,
    TYPE_TEXT,
    VEC,
)
from swarmdsl.compiler.visit import Visitor
from swarmdsl.errors import Span, SwarmError
from swarmdsl.ops.functions import FUNCTIONS
from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS, NEGATE
from swarmdsl.ops.targets import Refused

TARGET = "kilobot"
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,200}\Z")

FIX = "fix"            # the checker's type of a trilateration result (lang_beliefs.FIX)
# Why some names cannot be read on a Kilobot (the kinds of `AGENT_STATE`'s columns).
_NO_SENSE = {
    "pos": "global position (a Kilobot knows none)",
    "heading": "global heading (a Kilobot has no compass)",
    "vel": "its velocity vector (a Kilobot only knows its motor settings)",
    "speed": "its speed (a Kilobot only knows its motor settings)",
    "sense": "a sensing radius (a Kilobot senses through messages)",
    "max_speed": "a speed limit (a Kilobot's speed is its calibration)",
    "kind": "a kind as a value (not translated yet)",
}
# Robot-relative motion (`lang_motion`): the motors' command; its size is the robot's
# calibration (kilo_straight_*, kilo_turn_*), only its sign is translated.
_MOTION_C = {"stop": "KB_STOP", "forward": "({}) > 0 ? KB_STRAIGHT : KB_STOP",
             "turn_left": "kb_side({})", "turn_right": "kb_side(-({}))"}
# Kilombo's Kilobot in the kilobot profile's units (the exported C's KB_SPEED and
# KB_TURN_RATE defaults): 7 mm/s and 13 degrees/s, a tick being 0.1 s.
CALIBRATED = {"forward": (0.7, "7 mm/s"), "turn_left": (0.0227, "13 degrees/s"),
              "turn_right": (0.0227, "13 degrees/s")}


class Refusal(SwarmError):
    """A construct the Kilobot target cannot run, located and named."""

    phase = "check"

    def __init__(self, what: str, span: Span | None, hint: str | None = None):
        super().__init__(f"{what} cannot run on a Kilobot (target {TARGET})", span, hint)


def ident(name: str, span: Span | None) -> str:
    """A checked name as a C identifier part; anything else is refused (the grammar
    already allows only these, so this is a second lock, not a translation)."""
    if not _IDENT.match(name):
        raise Refusal(f"the name `{name[:20]}`", span, "use letters, digits and `_`")
    return name


def number(value, span: Span | None) -> str:
    """A checked constant as a C float literal (`inf` as INFINITY; NaN refused)."""
    if isinstance(value, bool):
        return "1" if value else "0"
    v = float(value)
    if math.isnan(v):
        raise Refusal("a NaN constant", span)
    if math.isinf(v):
        return "INFINITY" if v > 0 else "(-INFINITY)"
    text = repr(v)
    return f"({text}f)" if v < 0 else f"{text}f"


class KindC(Visitor):
    """Translates one kind's statuses. A robot runs one kind: the kinds' variables are
    `v<k>_NAME` (k the kind's index) and its status functions `kb_k<k>_STATUS`; the
    robots of a kind have the ids `first` to `first + count - 1`. With `steer` (a program
    with beliefs) `velocity = V` is a displacement in the believed frame the robot's
    motors carry it along; without, only a stop or a turn of its own way.

    Its expressions are walked on the visitor base: what a Kilobot cannot compute (a
    field, a string, a neighbour filter, a tree's state) is refused at its place."""

    REFUSED = frozenset({"FieldAt", "StrLit", "Where", "Forever", "TreeResult"})

    def __init__(self, info, kind, first: int, steer: bool = False,
                 networks: dict | None = None):
        self.info = info
        self.networks = {} if networks is None else networks   # model path -> (index, span)
        self.steer = steer         # the program has beliefs: `velocity` is steered to
        self.kind = kind
        self.k = kind.index
        self.first = first
        self.sets: dict[str, ast.Expr] = {}      # `let` names of neighbour sets
        self.temp = 0
        self.refusals: list[Refusal] = []
        self.moves = False         # a status sets the robot's motion
        self.warnings: list[SwarmError] = []     # what runs, but not as in swarmdsl

    # ---- resolutions ----
    def res(self, node) -> tuple:
        return self.info.facts.name_of(node, ("",))

    def type_of(self, node) -> str:
        return self.info.facts.type_of(node, "")

    def _temp(self) -> str:
        self.temp += 1
        return f"t{self.temp}"

    # ---- statuses ----
    def status_function(self, name: str) -> str:
        decl = self.kind.status_decls[name]
        self.sets = {}
        body = self.block(decl.body, 1)
        return (f"/* status `{ident(name, decl.name_span)}` */\n"
                f"static void kb_k{self.k}_{name}(void)\n{{\n{body}}}\n")

    def block(self, stmts, depth: int) -> str:
        """The statements' C; each refused one is kept in `refusals`, so one export
        reports every construct it cannot translate."""
        out = []
        for st in stmts:
            try:
                out.append(self.stmt(st, depth))
            except Refusal as refusal:
                self.refusals.append(refusal)
        return "".join(out)

    def stmt(self, st: ast.Stmt, depth: int) -> str:
        """A statement's C: its kind's form in `STATEMENT_C` when its row
        (`actions.STATEMENTS`) says the exporter writes one, else the row's refusal."""
        row = STATEMENTS.get(type(st))
        form = STATEMENT_C.get(type(st)) if row is not None and row.kilobot is True else None
        if form is None:
            raise Refusal(_construct(st), st.span, _why(row.kilobot if row else None))
        return form(self, st, "    " * depth, depth)

    def _let(self, st: ast.LetStmt, pad: str, depth: int) -> str:
        t = self.type_of(st.value)
        if t == SET:
            self.sets[st.name] = st.value
            return ""
        ctype = self._ctype(t, st.value.span)
        return f"{pad}{ctype} l_{ident(st.name, st.name_span)} = {self.expr(st.value)};\n"

    def _when(self, st: ast.WhenStmt, pad: str, depth: int) -> str:
        target = ident(st.target, st.target_span)
        inner = self.block(st.body, depth + 1)
        return (f"{pad}if ({self.expr(st.cond)}) {{\n{inner}"
                f"{pad}    mydata->status = ST_{target};\n{pad}    return;\n{pad}}}\n")

    def assign(self, st: ast.AssignStmt, pad: str) -> str:
        res = self.res(st)
        if res[0] == "var":
            self._ctype(self.kind.vars[st.target].type, st.target_span)
            target = f"mydata->v{self.k}_{ident(st.target, st.target_span)}"
            op = st.op if st.op in ("=", "+=", "-=", "*=", "/=") else None
            if op is None:
                raise Refusal(f"the assignment `{st.op}`", st.span)
            if self.kind.vars[st.target].type == VEC and op != "=":
                value = self.arith(op[0], target, VEC, self.expr(st.value),
                                   self.type_of(st.value), st)[0]
                return f"{pad}{target} = {value};\n"
            return f"{pad}{target} {op} {self.expr(st.value)};\n"
        if res == ("state", "vel"):
            self.moves = True
        if res == ("state", "vel") and self.steer:
            value = self.expr(st.value)
            if st.op in ("+=", "-="):
                value = f"kb_v{'add' if st.op == '+=' else 'sub'}(mydata->vel, {value})"
            elif st.op != "=":
                raise Refusal(f"the assignment `{st.op}` to `velocity`", st.span)
            return f"{pad}mydata->vel = {value};\n"
        if res == ("state", "vel") and st.op == "=" and _zero_vector(st.value, self.info):
            return f"{pad}mydata->moving = 0;\n"
        if res == ("state", "vel") and st.op == "=" and self._turn(st.value):
            return f"{pad}kb_turn({self.expr(st.value.args[1])});\n"
        if res == ("state", "vel"):
            raise Refusal("steering by a global velocity", st.span,
                          "a Kilobot has no compass: it can stop (`velocity = (0, 0)`) "
                          "or turn its own way (`velocity = rotate(velocity, ANGLE)`), "
                          "not head for a direction of the world")
        raise Refusal(f"assigning `{st.target}`", st.target_span)

    def _calibration(self, st) -> None:
        """A warning where a motion's size is not the robot's: a Kilobot goes and turns
        at its calibration, whatever size the program gives."""
        from swarmdsl.compiler.consteval import NotConstant, const_value

        want, words = CALIBRATED[st.name]
        try:
            size = abs(float(const_value(st.args[0], self.info.params)))
        except (NotConstant, ArithmeticError, ValueError, TypeError):
            size = None
        if size is not None and (size == 0 or abs(size - want) <= 0.1 * want):
            return
        given = "a size computed as it runs" if size is None else f"{size:g} a tick"
        self.warnings.append(SwarmError(
            f"`{st.name}` moves a Kilobot at its calibrated {words} ({want:g} a tick in "
            f"swarmdsl's units), not {given} (target kilobot)", st.args[0].span,
            f"give {want:g} so swarmdsl moves as the robot does, or calibrate the robots "
            "(KiloGUI) to what you mean", severity="warning"))

    def _turn(self, value) -> bool:
        """`rotate(velocity, ANGLE)`: a turn relative to the robot's own motion."""
        return (isinstance(value, ast.Call) and self.res(value) == ("func", "rotate")
                and isinstance(value.args[0], ast.Name)
                and self.res(value.args[0]) == ("state", "vel"))

    def action(self, st: ast.ActionStmt) -> str:
        """An action's C: its form in `ACTION_C` when its row (`ActionSpec.kilobot`)
        says the exporter writes one, else the row's refusal, located."""
        spec = ACTIONS.get(st.name)
        form = ACTION_C.get(st.name) if spec is not None and spec.kilobot is True else None
        out = form(self, st) if form is not None else None
        if out is None:
            raise Refusal(f"the action `{st.name}(...)`", st.name_span,
                          _why(spec.kilobot if spec is not None else None))
        return out

    def _broadcast(self, st: ast.ActionStmt) -> str:
        name = ident(st.args[0].id, st.args[0].span)
        value = self.expr(st.args[1])
        return (f"mydata->out_{name} = {value}; mydata->sent_tick = mydata->tick; "
                "mydata->sent = 1;")

    def _led(self, st: ast.ActionStmt) -> str:
        if len(st.args) == 1:
            return f"set_color({_led_constant(st.args[0].id)});"
        r, g, b = (self.expr(a) for a in st.args)
        return f"set_color(kb_rgb({r}, {g}, {b}));"

    def _motion(self, st: ast.ActionStmt) -> str:
        if self.steer:
            raise Refusal(f"`{st.name}(...)` in a program with beliefs", st.name_span,
                          "a robot steered to its beliefs moves by `velocity = V`")
        self.moves = True
        if st.args:
            self._calibration(st)
        size = self.expr(st.args[0]) if st.args else "0"
        return f"kb_command({_MOTION_C[st.name].format(size)});"

    def _believe(self, st: ast.ActionStmt) -> str | None:
        if len(st.args) != 1:
            return None     # another arity is a check error already; refused here too
        # A new belief is a measurement of where the robot is: its body estimate
        # and its motors' goal start from it too.
        return (f"{{ kb_vec_t b = {self.expr(st.args[0])}; mydata->believed = b; "
                "mydata->located = 1; mydata->body = b; mydata->goal = b; }")

    # ---- expressions ----
    def _ctype(self, t: str, span) -> str:
        if t == NUM:
            return "float"
        if t == BOOL:
            return "uint8_t"
        if t == VEC:
            return "kb_vec_t"
        if t == FIX:
            return "kb_fix_t"
        raise Refusal(TYPE_TEXT.get(t, f"a value of type {t}"), span,
                      "the Kilobot export handles numbers, booleans and vectors")

    def expr(self, e: ast.Expr, pair: str | None = None) -> str:
        """C for `e`; `pair` names the neighbour-table entry inside an aggregate."""
        return self.visit(e, pair)

    def refuse(self, e: ast.Expr, pair: str | None = None) -> str:
        raise Refusal(_construct(e), e.span)

    def visit_Num(self, e: ast.Num, pair: str | None) -> str:
        return number(e.value, e.span)

    def visit_BoolLit(self, e: ast.BoolLit, pair: str | None) -> str:
        return "1" if e.value else "0"

    def visit_Name(self, e: ast.Name, pair: str | None) -> str:
        return self.name(e, pair)

    def visit_Vec(self, e: ast.Vec, pair: str | None) -> str:
        return f"kb_v({self.expr(e.x, pair)}, {self.expr(e.y, pair)})"

    def visit_Attr(self, e: ast.Attr, pair: str | None) -> str:
        res = self.res(e)
        if res[0] == "msg_value" and pair is not None:
            return f"{pair}->m_{ident(res[1], e.name_span)}"
        if res[0] == "component":
            return f"({self.expr(e.obj, pair)}).{'x' if res[1] == 0 else 'y'}"
        if res[0] == "fix_part":
            return f"({self.expr(e.obj, pair)}).{'pos' if res[1] == 'pos' else 'ok'}"
        raise Refusal(_attr_construct(e, res), e.span)

    def visit_BinOp(self, e: ast.BinOp, pair: str | None) -> str:
        return self.arith(e.op, self.expr(e.left, pair), self.type_of(e.left),
                          self.expr(e.right, pair), self.type_of(e.right), e)[0]

    def visit_Chain(self, e: ast.Chain, pair: str | None) -> str:
        out, t = self.expr(e.first, pair), self.type_of(e.first)
        for op, term in e.rest:
            out, t = self.arith(op, out, t, self.expr(term, pair), self.type_of(term), term)
        return out

    def visit_Neg(self, e: ast.Neg, pair: str | None) -> str:
        if self.type_of(e.operand) == VEC:
            return NEGATE.kilobot_vec[(VEC,)].format(self.expr(e.operand, pair))
        return NEGATE.kilobot.format(self.expr(e.operand, pair))

    def visit_Compare(self, e: ast.Compare, pair: str | None) -> str:
        form = _form(COMPARISONS.get(e.op))
        if not isinstance(form, str):
            raise Refusal(f"the comparison `{e.op}`", e.span, _why(form))
        for side in (e.left, e.right):
            if self.type_of(side) not in (NUM, BOOL, STATUS):
                raise Refusal(f"comparing values of type {self.type_of(side)}", side.span)
        return form.format(self.expr(e.left, pair), self.expr(e.right, pair))

    def visit_AndOp(self, e: ast.AndOp, pair: str | None) -> str:
        return f"({self.expr(e.left, pair)} && {self.expr(e.right, pair)})"

    def visit_OrOp(self, e: ast.OrOp, pair: str | None) -> str:
        return f"({self.expr(e.left, pair)} || {self.expr(e.right, pair)})"

    def visit_NotOp(self, e: ast.NotOp, pair: str | None) -> str:
        return f"(!{self.expr(e.operand, pair)})"

    def visit_Cond(self, e: ast.Cond, pair: str | None) -> str:
        self._ctype(self.type_of(e), e.span)
        return (f"({self.expr(e.test, pair)} ? {self.expr(e.then, pair)} : "
                f"{self.expr(e.orelse, pair)})")

    def visit_Call(self, e: ast.Call, pair: str | None) -> str:
        return self.call(e, pair)

    def arith(self, op: str, left: str, lt: str, right: str, rt: str, node):
        """`left op right` and its type: vector arithmetic by the kb_v* helpers, numbers'
        by C's operators (both the operator row's `kilobot` forms)."""
        if VEC in (lt, rt):
            row = ARITHMETIC.get(op)
            form = row.kilobot_vec.get((lt, rt)) if row is not None else None
            if form is None:
                raise Refusal(f"`{op}` of a vector", node.span)
            return form.format(left, right), VEC
        return self.binop(op, left, right, node), lt

    def binop(self, op: str, left: str, right: str, node) -> str:
        form = _form(ARITHMETIC.get(op))
        if isinstance(form, str):
            return form.format(left, right)
        if op == "and":
            return f"({left} && {right})"
        if op == "or":
            return f"({left} || {right})"
        raise Refusal(f"the operator `{op}`", node.span, _why(form))

    def name(self, e: ast.Name, pair: str | None) -> str:
        res = self.res(e)
        what = res[0]
        if what == "var":
            return f"mydata->v{self.k}_{ident(e.id, e.span)}"
        if what == "local":
            if e.id in self.sets:
                raise Refusal("a neighbour set used as a value", e.span)
            return f"l_{ident(e.id, e.span)}"
        if what == "const":
            return number(res[1], e.span)
        if what == "global" and e.id == "tick":
            return "((float)mydata->tick)"
        if what == "status":
            return f"ST_{ident(res[1], e.span)}"
        if what == "belief":
            return f"mydata->{'believed' if res[1] == 'believed' else 'located'}"
        if what == "pair" and e.id == "dist" and pair is not None:
            return f"((float){pair}->dist)"
        if what == "state":
            column = res[1]
            if column == "id":
                return "((float)kilo_uid)"
            if column == "index":
                return f"((float)(kilo_uid - {self.first}))"
            if column == "status":
                return "mydata->status"
            if column == "vel" and self.steer:
                return "mydata->vel"
            raise Refusal(f"`{e.id}`: {_NO_SENSE.get(column, column)}", e.span)
        raise Refusal(f"`{e.id}`", e.span)

    def call(self, e: ast.Call, pair: str | None) -> str:
        res = self.res(e)
        if res[0] == "agg":
            if pair is not None:
                raise Refusal("an aggregate inside an aggregate", e.span)
            return self.aggregate(e)
        form = _form(FUNCTIONS.get(e.name)) if res[0] == "func" else None
        if isinstance(form, str):
            if FUNCTIONS[e.name].random and pair is not None:
                raise Refusal(f"`{e.name}` inside an aggregate", e.span)
            args = [self.expr(a, pair) for a in e.args]
            return _call_form(form, args)
        if isinstance(form, Refused):
            raise Refusal(f"the function `{e.name}`", e.name_span, form.why)
        if res[0] == "nn":
            return self.network(e, res[1], pair)
        if res[0] == "trilaterate":
            if pair is not None:
                raise Refusal("`trilaterate` inside an aggregate", e.span)
            if res[1] == "three":
                return f"kb_solve3({', '.join(self.expr(a) for a in e.args)})"
            return self.aggregate(e)
        if res[0] in ("heard", "neighbors"):
            raise Refusal(f"`{e.name}()` outside an aggregate", e.span)
        row = CALLS.get(e.name)
        raise Refusal(f"the function `{e.name}`", e.name_span,
                      _why(row.kilobot if row is not None else None))

    def network(self, e: ast.Call, path, pair: str | None) -> str:
        """`nn(MODEL, inputs...)`: the inputs in order (a vector as x then y) through the
        network's C function (`kilobot_nn.py`), a number or a vector out."""
        index = self.networks.setdefault(path, (len(self.networks), e.span))[0]
        x, y = self._temp(), self._temp()
        fill, k = [], 0
        for arg in e.args[1:]:
            value = self.expr(arg, pair)
            if self.type_of(arg) == VEC:
                fill.append(f"{{ kb_vec_t v = {value}; {x}[{k}] = v.x; {x}[{k + 1}] = v.y; }}")
                k += 2
            else:
                fill.append(f"{x}[{k}] = {value};")
                k += 1
        result = f"kb_v({y}[0], {y}[1])" if self.type_of(e) == VEC else f"{y}[0]"
        return (f"({{ float {x}[{k}], {y}[2]; {' '.join(fill)} kb_nn{index}({x}, {y}); "
                f"{result}; }})")

    def aggregate(self, e: ast.Call) -> str:
        """An aggregate over the table of recently heard neighbours, as a GNU C
        statement expression (avr-gcc and gcc both take them)."""
        conds = []
        source = e.args[0]
        for _ in range(64):
            if isinstance(source, ast.Where):
                conds.append(source.cond)
                source = source.source
            elif isinstance(source, ast.Name) and source.id in self.sets:
                source = self.sets[source.id]
            else:
                break
        res = self.res(source)
        if res[0] == "neighbors":
            raise Refusal("`neighbors()`", source.span, _why(CALLS["neighbors"].kilobot))
        if res[0] != "heard":
            raise Refusal("this neighbour set", source.span)
        nb = "nb" + self._temp()
        keep = " && ".join(f"{self.expr(c, nb)}" for c in reversed(conds)) or "1"
        acc, n, i = self._temp(), self._temp(), self._temp()
        each = self.expr(e.each, nb) if e.each is not None else "0"
        row = AGGREGATES.get(e.name)
        form = _form(row)
        loop = (f"for (uint8_t {i} = 0; {i} < KB_TABLE; {i}++) {{ "
                f"const kb_neighbor_t *{nb} = &mydata->table[{i}]; "
                f"if (!{nb}->used || !({keep})) continue; ")
        if self.res(e)[0] == "trilaterate":
            return (f"({{ kb_vec_t p{acc}[KB_TABLE]; float r{acc}[KB_TABLE]; uint8_t {n} = 0; "
                    f"{loop}p{acc}[{n}] = {each}; r{acc}[{n}] = (float){nb}->dist; {n}++; }} "
                    f"kb_trilaterate(p{acc}, r{acc}, {n}); }})")
        vector = e.each is not None and self.type_of(e.each) == VEC
        if e.each is not None:
            self._ctype(self.type_of(e.each), e.each.span)
        default = (self.expr(e.default) if e.default is not None
                   else "kb_v(0.0f, 0.0f)" if vector else "0")
        if not isinstance(form, tuple) or (vector and form.step_vec is None):
            raise Refusal(f"the aggregate `{e.name}`", e.name_span, _why(form))
        parts = {"acc": acc, "n": n, "nb": nb, "each": each, "default": default}
        step = (form.step_vec if vector else form.step).format(**parts)
        result = (form.result_vec if vector else form.result).format(**parts)
        ctype = "kb_vec_t" if vector else form.ctype
        start = "kb_v(0.0f, 0.0f)" if vector else form.start
        best = form.setup.format(**parts)
        declare = "" if form.ctype is None else f"{ctype} {acc} = {start}; "
        return f"({{ {declare}uint8_t {n} = 0;{best} {loop}{step} {n}++; }} {result}; }})"

    # ---- variable initial values (setup) ----
    def initial(self, var) -> str:
        decl = var.decl
        for node in ast.walk(decl.value):
            if isinstance(node, ast.Name) and self.res(node)[0] == "var":
                raise Refusal("an initial value that reads another variable", node.span,
                              "give it from constants, params, `id` or `index`")
        self._ctype(var.type, decl.name_span)
        return (f"        mydata->v{self.k}_{ident(var.name, decl.name_span)} = "
                f"{self.expr(decl.value)};\n")


# The statement kinds whose rows say the exporter writes their C (`StatementRow.kilobot`
# True): each method is given the statement, its indentation and its depth.
STATEMENT_C = {ast.LetStmt: KindC._let, ast.WhenStmt: KindC._when,
               ast.AssignStmt: lambda self, st, pad, depth: self.assign(st, pad),
               ast.ActionStmt: lambda self, st, pad, depth: pad + self.action(st) + "\n"}
# The actions whose rows say the exporter writes their C (`ActionSpec.kilobot` True):
# each method returns the statement's C, or None for a use it refuses.
ACTION_C = {"broadcast": KindC._broadcast, "led": KindC._led, "believe": KindC._believe,
            **dict.fromkeys(_MOTION_C, KindC._motion)}


def _call_form(form: str, args: list[str]) -> str:
    """A function row's C: a template of its arguments (`{0}`, `{1}`, as an operator's)
    or the name of a C function called with them."""
    return form.format(*args) if "{" in form else f"{form}({', '.join(args)})"


def _form(row):
    """A row's Kilobot form: its C template, its `Refused`, or None (no row)."""
    return None if row is None else row.kilobot


def _why(form) -> str | None:
    """The hint of a refusal a row declared."""
    return form.why if isinstance(form, Refused) else None


def _zero_vector(e, info) -> bool:
    from swarmdsl.compiler.consteval import NotConstant, const_value

    try:
        v = const_value(e, info.params)
    except (NotConstant, ArithmeticError, ValueError, TypeError):
        return False
    return isinstance(v, tuple) and all(float(x) == 0 for x in v)


def _led_constant(colour: str) -> str:
    """A named LED colour as kilolib's 2-bit-per-channel RGB (`off` is dark)."""
    from swarmdsl.compiler.lang_messaging import LED_COLOURS

    if colour == "off":
        return "RGB(0, 0, 0)"
    packed = LED_COLOURS[colour]
    r, g, b = ((packed >> s) & 0xFF for s in (16, 8, 0))
    return "RGB({}, {}, {})".format(*(round(c / 255 * 3) for c in (r, g, b)))


def _attr_construct(e: ast.Attr, res) -> str:
    if res[0] in ("other_state", "other_var"):
        return f"`other.{e.name}` (a Kilobot knows a neighbour only by its messages)"
    if res[0] == "component":
        return "a vector's component"
    return f"`.{e.name}`"


_NAMES = {"FieldAt": "reading a field (`at`)", "Vec": "a vector",
          "Where": "a filtered set outside an aggregate"}


def _construct(node) -> str:
    """A node's construct in the user's words, for a refusal."""
    name = type(node).__name__
    if name in _NAMES:
        return _NAMES[name]
    words = re.sub(r"(?<!^)(?=[A-Z])", " ", name).lower()
    return f"the {words.removesuffix(' stmt').removesuffix(' decl')}"
