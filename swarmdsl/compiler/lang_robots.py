"""Robot profiles in the language: `robot NAME { ... }` declarations, the per-kind
capability check (a sense the profile lacks is a located error), and `world { origin }`.

A profile is checked against what a kind's statuses *read*: the checker has already
resolved every name, so this module maps resolutions to senses after each kind's body
(`checker.KIND_HOOKS`). Agent options and variable initialisers are the experimenter's
set-up (placing and labelling robots) and may read the truth.
"""

from __future__ import annotations

import math

from swarmdsl.compiler import ast, checker, options
from swarmdsl.compiler.profiles import (
    ABOVE_MIN,
    NUMERIC_OPTIONS,
    PROFILES,
    SENSES,
    WARN_AT_MAX,
    Profile,
)
from swarmdsl.errors import did_you_mean

# Extra sense rules for extensions: fn(checker, node, resolution) -> (sense, text) | None.
SENSE_RULES: list = []
# Extra `robot { }` options: name -> fn(checker, option) -> dict of Profile changes | None.
ROBOT_OPTIONS: dict = {}

_HINT_POSITION = ("a kilobot knows where it is only as `believed`, set by `believe(...)` "
                  "or `trilaterate(...)` and kept up to date by odometry")
_HINT_NEIGHBOUR = ("it knows a neighbour only by its distance `dist` and by what it "
                   "broadcasts: `msg.NAME` over `heard()`")


def robots(chk) -> dict[str, Profile]:
    """Every profile the program can use (built in and declared), by name."""
    return chk.extra.setdefault("robots", dict(PROFILES))


def profile_of(chk, kind) -> Profile:
    """The profile of an agent kind (KindInfo), from a checker or a ProgramInfo."""
    table = chk.extra.get("robots") or PROFILES
    return table.get(kind.robot, PROFILES["generic"])


# ---- robot declarations ----

def _declare_robots(chk) -> None:
    table = robots(chk)
    for decl in chk.tree.decls_of(ast.RobotDecl):
        if decl.name in PROFILES:
            chk.fail(f"robot `{decl.name}` is built in; declare yours under another name",
                     decl.name_span, f"e.g. `robot my{decl.name} {{ like {decl.name} }}`")
            continue
        base = PROFILES["generic"]
        changes: dict = {}
        seen: set[str] = set()
        for opt in decl.options:
            if opt.name in seen:
                chk.fail(f"option `{opt.name}` is already set for robot `{decl.name}`",
                         opt.name_span)
                continue
            seen.add(opt.name)
            if opt.name == "like":
                got = _like(chk, opt, table)
                base = got or base
            elif opt.name == "senses":
                senses = _senses(chk, opt)
                if senses is not None:
                    changes["senses"] = senses
            elif opt.name in NUMERIC_OPTIONS:
                field, lo, hi = NUMERIC_OPTIONS[opt.name]
                value = _number(chk, opt, lo, hi)
                if value is not None:
                    changes[field] = value
                    if value == hi and opt.name in WARN_AT_MAX:
                        chk.warn(WARN_AT_MAX[opt.name], opt.span)
            elif opt.name in ROBOT_OPTIONS:
                changes.update(ROBOT_OPTIONS[opt.name](chk, opt) or {})
            else:
                known = ["like", "senses", *NUMERIC_OPTIONS, *ROBOT_OPTIONS]
                chk.fail(f"unknown robot option `{opt.name}`", opt.name_span,
                         did_you_mean(opt.name, known))
        table[decl.name] = base.derive(decl.name, **changes)


def _like(chk, opt, table):
    if len(opt.args) != 1 or not isinstance(opt.args[0], ast.Name):
        chk.fail("`like` takes a robot name: `like kilobot`", opt.span)
        return None
    name = opt.args[0].id
    if name not in table:
        chk.fail(f"unknown robot profile `{name}`", opt.args[0].span,
                 did_you_mean(name, list(table)) or "declare it before this robot")
        return None
    return table[name]


def _senses(chk, opt):
    out = set()
    if not opt.args:
        chk.fail("`senses` lists sense names: `senses distance message`", opt.span)
        return None
    for a in opt.args:
        if not isinstance(a, ast.Name):
            chk.fail("`senses` lists sense names, separated by spaces", a.span)
            return None
        if a.id == "all":
            return None if len(opt.args) == 1 else out
        if a.id not in SENSES:
            chk.fail(f"unknown sense `{a.id}`", a.span,
                     did_you_mean(a.id, SENSES) or f"senses: {', '.join(SENSES)}")
            continue
        out.add(a.id)
    return frozenset(out)


def _number(chk, opt, lo: float, hi: float):
    if len(opt.args) != 1:
        chk.fail(f"`{opt.name}` takes one number", opt.span)
        return None
    v = chk._const(opt.args[0], f"`{opt.name}`")
    if v is None:
        return None
    above = opt.name in ABOVE_MIN
    if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi \
            or (above and v == lo):
        rng = f"{'above' if above else 'at least'} {lo:g}" if hi == math.inf \
            else f"between {lo:g} and {hi:g}"
        chk.fail(f"`{opt.name}` must be a number {rng}, got {v}", opt.args[0].span,
                 ABOVE_MIN.get(opt.name))
        return None
    return float(v)


# ---- capabilities ----

def _sense_of(chk, node):
    """(sense, text) a node needs, or None."""
    res = chk.facts.name_of(node)
    if res is None:
        return None
    if isinstance(node, ast.Name) and res[0] == "state":
        if res[1] == "pos":
            return "position", "pos"
        if res[1] == "heading":
            return "heading", "heading"
    elif isinstance(node, ast.Name) and res == ("pair", "dist"):
        return "distance", "dist"
    elif isinstance(node, ast.Attr) and res[0] == "other_state":
        text = f"other.{node.name}"
        if res[1] == "pos":
            return "bearing", text
        if res[1] in ("vel", "heading", "speed"):
            return "motion", text
        return "state", text
    elif isinstance(node, ast.Attr) and res[0] == "other_var":
        return "state", f"other.{node.name}"
    elif isinstance(node, ast.Call) and res == ("neighbors",):
        return "distance", f"{node.name}()"
    for rule in SENSE_RULES:
        got = rule(chk, node, res)
        if got is not None:
            return got
    return None


def _check_senses(chk, kind) -> None:
    prof = profile_of(chk, kind)
    if prof.senses is None:
        return
    for decl in kind.status_decls.values():
        for node in ast.walk(decl):
            need = _sense_of(chk, node)
            if need is None or prof.allows(need[0]):
                continue
            sense, text = need
            hint = _HINT_POSITION if sense in ("position", "heading") else _HINT_NEIGHBOUR
            chk.fail(f"`{text}` needs the sense `{sense}`, which robot `{prof.name}` lacks",
                     node.span, hint)


def _check_hearing(chk, kind) -> None:
    """A `comm_range` left at "two body diameters" follows `body`, so `body 0` would
    silently make a talking kind deaf (`heard()` always empty); `comm_range 0` itself is
    refused, and so is this, at the kind's `message` layout."""
    prof = profile_of(chk, kind)
    layout = kind.options.get("message")
    if layout is None or prof.comm_range is not None or prof.range > 0:
        return
    chk.fail(f"agents of `{kind.name}` would hear no message: robot `{prof.name}` hears "
             "two body diameters away, and its body is 0", layout.span,
             f"give robot `{prof.name}` a range of its own, e.g. `comm_range 66`")


def require_sense(chk, kind, sense: str, text: str, node) -> bool:
    """Report `text` (an action or call) if the kind's profile lacks `sense`."""
    if kind is None:
        return True
    prof = profile_of(chk, kind)
    if prof.allows(sense):
        return True
    chk.fail(f"`{text}` needs the sense `{sense}`, which robot `{prof.name}` lacks",
             node.span)
    return False


# ---- world { origin X Y } ----

def _origin(chk, opt, world):
    if len(opt.args) != 2:
        chk.fail("`origin` takes x and y: `origin 120 120`", opt.span)
        return
    xy = [chk._const(a, "the origin") for a in opt.args]
    if any(v is None for v in xy):
        return
    chk.extra["origin"] = (float(xy[0]), float(xy[1]))


checker.DECL_HOOKS.append(_declare_robots)
checker.KIND_HOOKS.append(_check_senses)
checker.KIND_HOOKS.append(_check_hearing)
options.WORLD_OPTIONS["origin"] = _origin
