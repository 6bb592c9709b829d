"""Internal environment maps (the thesis' E) in the language: `map NAME CELL SIZE` per
agent kind, the `note` action and the `recall`, `age`, `known` and `best` readings.

A map is what the agent has perceived, kept in its own frame: a point is stored
relative to where the agent was placed, at the resolution of the map's cells, and only
within the map's extent. `note(M, value, point)` keeps a value only where the agent
could sense it: within its `sense` radius and its profile's range and field of view.
The runtime half is `runtime/internal_map.py`.
"""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler import ast, checker, codegen, comparisons, program, typing_rules
from swarmdsl.compiler.actions import ActionSpec, Refused, register
from swarmdsl.compiler.batching import per_replica
from swarmdsl.compiler.builtins import BOOL, NUM, TYPE_TEXT, VEC, declare_calls
from swarmdsl.compiler.lang_fields import arity, named_arg, refuse_bad_constant
from swarmdsl.compiler.lang_robots import require_sense
from swarmdsl.compiler.options import AGENT_OPTIONS, OptionSpec, _positive
from swarmdsl.ops import portable

ERR = "error"
MAP = "map"
TYPE_TEXT.setdefault(MAP, "an internal map")
MAX_MAP_CELLS = 256        # cells a side
_USAGE = "`map NAME CELL SIZE` (a SIZE x SIZE map of CELL-wide cells): `map seen 10 40`"


def _maps(chk) -> dict:
    """kind name -> {map name: (cell, size)}; `ProgramInfo.extra["maps"]`."""
    return chk.extra.setdefault("maps", {})


def _map_option(chk, opt: ast.Option, kind) -> None:
    if len(opt.args) != 3 or not isinstance(opt.args[0], ast.Name):
        chk.fail(f"`map` takes a name, a cell size and a size: {_USAGE}", opt.span)
        return
    cell = _positive(chk, opt.args[1], "the map's cell size", limit="size")
    size = _positive(chk, opt.args[2], "the map's size in cells", integer=True)
    if cell is None or size is None:
        return
    if size > MAX_MAP_CELLS:
        chk.fail(f"a map is at most {MAX_MAP_CELLS} cells a side, got {size}",
                 opt.args[2].span, "use bigger cells")
        return
    name = opt.args[0].id
    chk.name_taken(name, opt.args[0].span)
    for other, maps in _maps(chk).items():
        if maps.get(name, (cell, size)) != (cell, size):
            chk.fail(f"map `{name}` of `{other}` has other cells; a map shared by name "
                     "has one cell size and size", opt.span)
            return
    _maps(chk).setdefault(kind.name, {})[name] = (cell, size)


AGENT_OPTIONS["map"] = OptionSpec(_map_option, doc="an internal map: map NAME CELL SIZE",
                                  declares=True)


def _resolve(chk, e: ast.Name, scope):
    k = scope.kind
    if k is not None and e.id in _maps(chk).get(k.name, {}):
        chk.facts.set_name(e, ("map", e.id))
        return MAP
    return None


typing_rules.NAME_RESOLVERS.append(_resolve)
codegen.NAME_CODEGEN["map"] = lambda gen, e, res: (lambda f, _n=res[1]: _n)
_WHAT = "an internal map (declare it with `map NAME CELL SIZE`)"


def _reading(usage: str, lo: int, hi: int, result: str):
    def rule(chk, call, scope):
        if not arity(chk, call, scope, lo, hi, usage):
            return ERR
        if scope.kind is None:
            return chk.fail(f"`{call.name}` reads an agent's own map", call.span)
        named_arg(chk, call, 0, scope, MAP, _WHAT)
        if len(call.args) == 2 and chk.expect(call.args[1], VEC, scope, "the point") == VEC:
            refuse_bad_constant(chk, call.args[1], f"the point of `{call.name}`")
        require_sense(chk, scope.kind, "position", f"{call.name}(...)", call)
        chk.facts.set_name(call, ("map_call", call.name))
        return result
    return rule


typing_rules.CALL_RULES.update({
    "recall": _reading("recall(MAP [, point])", 1, 2, NUM),
    "age": _reading("age(MAP [, point])", 1, 2, NUM),
    "known": _reading("known(MAP [, point])", 1, 2, BOOL),
    "best": _reading("best(MAP)", 1, 1, VEC),
})
declare_calls(("recall", "age", "known", "best"), batch=True,   # maps: agent columns
              kilobot=Refused("internal maps are not translated to C yet"))


# `age` of a cell never noted: older than any cell a run can note (runs are at most
# 10^12 ticks, docs/limits.md), so `age(M) > N` holds for it as for a stale cell, and,
# unlike the infinity it was, a number a `var` can hold. `known(M)` tells them apart.
NEVER_AGE = 1e15


def _finite_age(chk, call):
    """`age(M, point)` is never infinite (a cell never seen is `NEVER_AGE` old): what a
    comparison with `inf` should test instead (`comparisons.py`)."""
    if chk.facts.name_of(call) != ("map_call", "age") or not call.args:
        return None
    name = call.args[0].id if isinstance(call.args[0], ast.Name) else "M"
    point = ""
    if len(call.args) == 2:
        point = f", {call.args[1].id}" if isinstance(call.args[1], ast.Name) else ", point"
    return ("the `age` of a cell never seen is 10^15",
            f"`known({name}{point})` tells whether the cell was seen: test `not "
            f"known({name}{point})` for a cell never seen")


comparisons.FINITE_READINGS["age"] = _finite_age


def _pos(f):
    return np.asarray(f.state("pos"), dtype=np.float64)


def _at(gen, call):
    if len(call.args) == 2:
        point = gen.expr(call.args[1])
        return lambda f: np.broadcast_to(np.asarray(point(f), np.float64), (f.n, 2))
    return _pos


def _cg_reading(gen, call):
    name, at, what = call.args[0].id, _at(gen, call), call.name

    def read(f):
        m = f.sim.maps.maps[name]
        cols, pos = f.sim.agents.cols, _pos(f)
        if what == "best":
            return m.best(cols, f.idx, pos)
        value, age = m.recall(cols, f.idx, pos, at(f), f.tick)
        if what == "age":
            return np.where(np.isfinite(age), age, NEVER_AGE)
        return value if what == "recall" else np.isfinite(age)
    return read


for _n in ("recall", "age", "known", "best"):
    codegen.CALL_CODEGEN[_n] = _cg_reading


# ---- note ----

def _check_note(chk, st, scope, kind):
    call = ast.Call(st.span, st.name, st.name_span, st.args, None, None)
    if not arity(chk, call, scope, 2, 3, "note(MAP, value [, point])"):
        return
    named_arg(chk, call, 0, scope, MAP, _WHAT)
    chk.expect(st.args[1], NUM, scope, "the noted value")
    if len(st.args) == 3 and chk.expect(st.args[2], VEC, scope,
                                        "the point where it was sensed") == VEC:
        refuse_bad_constant(chk, st.args[2], "the point of `note`")
    require_sense(chk, kind, "position", "note(...)", st)


def _compile_note(gen, st, kind):
    name, value = st.args[0].id, gen.expr(st.args[1])
    at = _at(gen, ast.Call(st.span, st.name, st.name_span, st.args[::2], None, None)) \
        if len(st.args) == 3 else _pos

    def note(f):
        act = f.active
        if not act.any():
            return
        pos, points = _pos(f), at(f)
        values = np.broadcast_to(np.asarray(value(f), np.float64), (f.n,))
        ok = act & _sensed(f, pos, points) & np.isfinite(values)
        m = f.sim.maps.maps[name]
        m.note(f.sim.agents.cols, f.idx[ok], pos[ok], points[ok], values[ok], f.tick)
    return note


def _sensed(f, pos, points) -> np.ndarray:
    """Which points the agents could sense: their own position, or within `sense` and
    within their profile's range and field of view."""
    from swarmdsl.runtime.sensing import in_view

    offset = points - pos
    dist = portable.hypot_array(offset[:, 0], offset[:, 1])
    ok = (dist == 0) | (dist <= f.state("sense"))
    sensing = getattr(f.sim, "sensing", None)
    k = getattr(f.kind, "index", None)
    if sensing is not None and k is not None:
        s = sensing.spec
        ok &= in_view(offset, f.state("heading"), int(s.fov[k]), float(s.fov_angle[k]),
                      float(s.fov_reach[k]), float(s.range[k]))
    return ok


register(ActionSpec("note", _check_note, _compile_note,
                    "write a sensed value into the agent's internal map", batch=True,
                    kilobot=Refused("internal maps are not translated to C yet")))


def _kind_clash(chk, kind) -> None:
    for n in _maps(chk).get(kind.name, {}):
        if n in kind.vars:
            chk.fail(f"`{n}` names both a map and a variable",
                     kind.options["map"].args[0].span, "choose another name")


checker.KIND_HOOKS.append(_kind_clash)


def _program_hook(info, prog, gen) -> None:
    spec: dict = {}
    for per_kind in info.extra.get("maps", {}).values():
        spec.update(per_kind)        # one cell size and size per name (checked)
    if spec:
        from swarmdsl.runtime.internal_map import MapRuntime

        prog.extensions.append(per_replica(lambda sim: MapRuntime(sim, spec),
                                           "its internal maps run"))


program.PROGRAM_HOOKS.append(_program_hook)
