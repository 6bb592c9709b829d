"""Well-typed, runnable swarm programs drawn by hypothesis, for fuzzing the runtime.

A grammar alone almost never reaches the runtime: nearly every program it draws is
refused by the checker. These programs are built the way the checker reads them: each
expression is drawn for the type its place wants (number, boolean, vector, neighbour
set), from names that exist there (the kind's variables, the `let`s above it, `other`
and `dist` inside an aggregate, only what is known while placing in an initial value),
and they compose declarations (params, world, fields, regions, kinds with maps, path
memories and objectives), statuses with lets, assignments, aggregates and transitions,
and behaviour trees with every node kind. Divisions, roots and logarithms are mostly written so that they stay finite, so
most programs run; the few that fault must fault with a located `SwarmError`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hypothesis import strategies as st

NUMBERS = ("0", "1", "2", "0.5", "3", "10", "0.25", "-1.5")


@dataclass
class Ctx:
    """What an expression may read where it is drawn."""

    init: bool = False                  # an initial value: no lets, neighbours, fields
    pair: bool = False                  # inside an aggregate or filter: other, dist
    lets: dict = field(default_factory=dict)      # name -> "num" | "bool" | "vec" | "set"
    vars_: tuple = ("u", "w", "v", "b")           # variables declared so far
    fields: tuple = ()
    regions: tuple = ()
    extras: bool = False                # the kind's map `seen`, memory `path`, objective `goal`


class Gen:
    """Draws typed expressions, statements and trees with hypothesis' `draw`."""

    def __init__(self, draw):
        self.draw = draw

    def pick(self, options):
        return self.draw(st.sampled_from(list(options)))

    def chance(self, p: float = 0.5) -> bool:
        return self.draw(st.floats(0, 1)) < p

    # ---- expressions ----
    def num(self, c: Ctx, depth: int = 2) -> str:
        leaves = [*NUMBERS, "index", "id", "k", "random()", "uniform(0, 2)"]
        leaves += [v for v in ("u", "w") if v in c.vars_]
        if not c.init:
            leaves += ["tick", "pos.x", "pos.y", "velocity.x", "speed", "heading"]
            leaves += [n for n, t in c.lets.items() if t == "num"]
        if c.pair:
            leaves += ["dist", "other.u", "other.pos.x", "other.w"]
        if depth <= 0 or self.chance(0.3):
            return self.pick(leaves)
        d = depth - 1
        forms = ["bin", "bin", "fun", "if", "vec"]
        if not c.init and not c.pair:
            forms += ["agg", "agg"]
            forms += ["field"] if c.fields else []
            forms += ["region"] if c.regions else []
            forms += ["extra"] if c.extras else []
        form = self.pick(forms)
        if form == "bin":
            a, b = self.num(c, d), self.num(c, d)
            op = self.pick(["+", "-", "*", "/", "%", "^", "min", "max"])
            if op == "/":    # now and then one that may fault (`0 * index`: not folded)
                return f"({a} / ({b} + 0 * index))" if self.chance(0.1) else \
                    f"({a} / (abs({b}) + 1))"
            if op == "%":
                return f"({a} % 3)"
            if op == "^":
                return f"(clamp({a}, -10, 10) ^ 2)"
            if op in ("min", "max"):
                return f"{op}({a}, {b})"
            return f"({a} {op} {b})"
        if form == "fun":
            a = self.num(c, d)
            if self.chance(0.05):    # may fault, located
                return self.pick([f"sqrt({a} + 0 * index)", f"log({a} + 0 * index)"])
            return self.pick([f"abs({a})", f"sqrt(abs({a}))", f"sin({a})", f"cos({a})",
                              f"floor({a})", f"log(abs({a}) + 1)", f"clamp({a}, 0, 5)",
                              f"exp(clamp({a}, -5, 5))", f"atan2({a}, 1)", f"sign({a})"])
        if form == "if":
            return f"(if {self.boolean(c, d)} then {self.num(c, d)} else {self.num(c, d)})"
        if form == "vec":
            v = self.vec(c, d)
            return self.pick([f"length({v})", f"{v}.x", f"dot({v}, {self.vec(c, d)})",
                              f"angle({v})"])
        if form == "field":
            f = self.pick(c.fields)
            return self.pick([f"sample({f})", f"{f} at pos", f"ahead({f}, 2)",
                              f"cone({f}, 5, 0.5)"])
        if form == "region":
            return f"distance_to({self.pick(c.regions)})"
        if form == "extra":
            return self.pick(["recall(seen)", "age(seen)", "age(seen, (50, 40))",
                              "len(path)", "length(target(goal))"])
        s = self.nset(c)
        pc = Ctx(pair=True, vars_=c.vars_, lets=c.lets)
        return self.pick([f"count({s})", f"sum({s} : {self.num(pc, d)})",
                          f"mean({s} : {self.num(pc, d)} else 0)",
                          f"min({s} : {self.num(pc, d)} else 0)",
                          f"max({s} : {self.num(pc, d)} else 0)"])

    def boolean(self, c: Ctx, depth: int = 2) -> str:
        leaves = ["true", "false", "chance(0.3)"] + (["b"] if "b" in c.vars_ else [])
        if not c.init:
            leaves += [n for n, t in c.lets.items() if t == "bool"]
            leaves += [f"inside({r})" for r in c.regions if not c.pair]
            leaves += ["known(seen)", "arrived(goal, 2)"] if c.extras and not c.pair else []
        if c.pair:
            leaves += ["other.b"]
        if depth <= 0 or self.chance(0.25):
            return self.pick(leaves)
        d = depth - 1
        forms = ["cmp", "cmp", "and", "or", "not"]
        if not c.init and not c.pair:
            forms.append("agg")
        form = self.pick(forms)
        if form == "cmp":
            op = self.pick(["<", "<=", ">", ">=", "==", "!="])
            return f"({self.num(c, d)} {op} {self.num(c, d)})"
        if form in ("and", "or"):
            return f"({self.boolean(c, d)} {form} {self.boolean(c, d)})"
        if form == "not":
            return f"(not {self.boolean(c, d)})"
        pc = Ctx(pair=True, vars_=c.vars_, lets=c.lets)
        return f"{self.pick(['any', 'all'])}({self.nset(c)} : {self.boolean(pc, d)})"

    def vec(self, c: Ctx, depth: int = 2) -> str:
        leaves = ["(1, 0)", "(0, -1)"] + (["v"] if "v" in c.vars_ else [])
        if not c.init:
            leaves += ["pos", "velocity"] + [n for n, t in c.lets.items() if t == "vec"]
        if c.pair:
            leaves += ["(other.pos - pos)", "other.v"]
        if depth <= 0 or self.chance(0.3):
            return self.pick(leaves)
        d = depth - 1
        forms = ["pair", "add", "scale", "fun"]
        if not c.init and not c.pair:
            forms += ["agg"] + (["grad"] if c.fields else []) + (["extra"] if c.extras else [])
        form = self.pick(forms)
        if form == "pair":
            return f"({self.num(c, d)}, {self.num(c, d)})"
        if form == "add":
            return f"({self.vec(c, d)} {self.pick(['+', '-'])} {self.vec(c, d)})"
        if form == "scale":
            return f"({self.vec(c, d)} * {self.num(c, d)})"
        if form == "fun":
            return self.pick([f"normalize({self.vec(c, d)})", f"unit({self.num(c, d)})",
                              f"rotate({self.vec(c, d)}, {self.num(c, d)})",
                              "random_direction()"])
        if form == "grad":
            return f"gradient({self.pick(c.fields)})"
        if form == "extra":
            return self.pick(["best(seen)", "toward(goal)", "approach(goal, 2)",
                              "target(goal)"])
        pc = Ctx(pair=True, vars_=c.vars_, lets=c.lets)
        s = self.nset(c)
        return self.pick([f"sum({s} : {self.vec(pc, d)})",
                          f"mean({s} : {self.vec(pc, d)} else (0, 0))"])

    def nset(self, c: Ctx) -> str:
        sets = [n for n, t in c.lets.items() if t == "set"]
        if sets and self.chance(0.5):
            return self.pick(sets)
        base = self.pick(["neighbors(5)", "neighbors(12)", "neighbors()"])
        if self.chance(0.4):
            pc = Ctx(pair=True, vars_=c.vars_, lets=c.lets)
            return f"{base} where {self.boolean(pc, 1)}"
        return base

    def typed(self, t: str, c: Ctx, depth: int = 2) -> str:
        return {"num": self.num, "bool": self.boolean, "vec": self.vec}[t](c, depth)

    # ---- statements ----
    def status_body(self, c: Ctx, statuses: list[str]) -> list[str]:
        out: list[str] = []
        tree = False
        for i in range(self.draw(st.integers(1, 5))):
            kind = self.pick(["let", "let", "assign", "assign", "when", "tree", "deposit",
                              "extra"])
            if kind == "let":
                t = self.pick(["num", "vec", "bool", "set"])
                name = f"l{i}"
                value = self.nset(c) if t == "set" else self.typed(t, c)
                out.append(f"let {name} = {value}")
                c.lets[name] = t
            elif kind == "assign":
                out.append(self.assignment(c))
            elif kind == "when":
                target = self.pick(statuses)
                body = f" {{ {self.assignment(c)} }}" if self.chance(0.3) else ""
                out.append(f"when {self.boolean(c)} -> {target}{body}")
            elif kind == "tree" and not tree:
                tree = True
                out.append(f"tree {self.tree(c, 3)}")
            elif kind == "deposit" and c.fields:
                out.append(f"deposit({self.pick(c.fields)}, clamp({self.num(c, 1)}, 0, 5))")
            elif kind == "extra" and c.extras:
                out.append(self.pick([f"note(seen, {self.num(c, 1)})", "remember(path)",
                                      "note(seen, 1, pos + (3, 0))"]))
        return out

    def assignment(self, c: Ctx) -> str:
        target = self.pick(["u", "w", "v", "b", "velocity"])
        if target in ("u", "w"):
            return f"{target} {self.pick(['=', '+=', '-=', '*='])} {self.num(c)}"
        if target == "b":
            return f"b = {self.boolean(c)}"
        return f"{target} {self.pick(['=', '+='])} {self.vec(c)}"

    def tree(self, c: Ctx, depth: int) -> str:
        if depth <= 0 or self.chance(0.3):
            leaves = [lambda: self.boolean(c, 1), lambda: self.assignment(c),
                      lambda: f"wait({self.pick(['0', '1', '2', 'floor(abs(u)) % 4'])})",
                      lambda: f"move_to({self.vec(c, 1)}, 1, 2)"]
            if c.regions:
                leaves.append(lambda: f"move_to({self.pick(c.regions)}, 0.5)")
            if c.extras:
                leaves.append(lambda: "retrace(path)")
            return leaves[self.draw(st.integers(0, len(leaves) - 1))]()
        d = depth - 1
        form = self.pick(["seq", "seq", "dec"])
        if form == "seq":
            kids = [self.tree(c, d) for _ in range(self.draw(st.integers(1, 3)))]
            word = self.pick(["sequence", "fallback", "reactive sequence",
                              "reactive fallback", f"parallel {1}", "reactive parallel 1"])
            return f"{word} {{ {'; '.join(kids)} }}"
        word = self.pick(["invert", "force success", "force failure", "repeat 2",
                          "retry 3", "repeat forever", "retry forever", "timeout 3",
                          "cooldown 2", "repeat k"])
        return f"{word} {self.tree(c, d)}"


@st.composite
def programs(draw) -> str:
    """One well-typed program: params, world, maybe a field and regions, 1-2 kinds."""
    g = Gen(draw)
    edges = g.pick(["wall", "wrap", "repel 1"])
    fields = ("heat",) if g.chance(0.4) else ()
    regions = tuple(r for r in ("home", "rock") if g.chance(0.3))
    lines = ["param k = 2 in 0..4", "world { size 100 x 80; grid 10; edges " + edges + " }"]
    if fields:
        lines.append("field heat { decay 0.1; diffuse 0.1 }")
    if "home" in regions:
        lines.append("nest home = circle(50, 40, 10)")
    if "rock" in regions:
        lines.append("obstacle rock = rect(70, 10, 80, 20)")
    for kind in ("a", "z")[: draw(st.integers(1, 2))]:
        init = Ctx(init=True, vars_=())
        items = [f"count {draw(st.integers(1, 12))}", "sense 15"]
        decls = []
        for name, t in (("u", "num"), ("w", "num"), ("v", "vec"), ("b", "bool")):
            decls.append(f"var {name} = {g.typed(t, init, 1)}")
            init.vars_ = (*init.vars_, name)
        items += decls
        if g.chance(0.5):   # an option reading a variable: computed after it
            items.append(g.pick(["place uniform", "place (5 + 9 * index, 20 + u % 40)",
                                 "place (10, 10 + 6 * index)"]))
        if g.chance(0.5):
            items.append(f"velocity ({g.num(init, 1)}, {g.num(init, 1)})")
        if g.chance(0.5):
            items.append("max_speed 3")
        extras = g.chance(0.3)
        if extras:
            items += ["map seen 5 20", "memory path 8", "objective goal = " + g.pick(
                ["(50, 40)", "(u, 40)", "home" if "home" in regions else "(10, 10)"])]
        statuses = [f"{kind}{i}" for i in range(draw(st.integers(1, 3)))]
        for s in statuses:
            c = Ctx(fields=fields, regions=tuple(r for r in regions if r == "home"),
                    extras=extras)
            body = g.status_body(c, statuses)
            items.append(f"status {s} {{\n    " + "\n    ".join(body) + "\n  }")
        lines.append(f"agent {kind} {{\n  " + "\n  ".join(items) + "\n}")
    return "\n".join(lines) + "\n"
