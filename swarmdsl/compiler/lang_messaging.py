"""Messages in the language: a kind's `message NAME TYPE ...` layout, the actions
`broadcast(NAME, value)` and `led(...)`, the neighbour set `heard()` and `msg.NAME` over it.

A broadcast lands in the sender's outbox at the end of the tick; receivers within their
profile's `comm_range` hear it at the next tick (`runtime/messaging.py`). Each sender's
message is its latest value on every channel of its layout, one message per tick, lost
as a whole with the receiver's `loss` chance. The layout's size (2 bytes a number, 1 a
boolean, 4 a vector) must fit the profile's `message_bytes` (9 for a Kilobot).
"""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler import (
    actions,
    ast,
    checker,
    codegen,
    columns,
    nan_guard,
    options,
    program,
    typing_rules,
)
from swarmdsl.compiler.batching import per_replica
from swarmdsl.compiler.builtins import BOOL, NUM, SET, TYPE_TEXT, VEC, declare_calls
from swarmdsl.compiler.codegen import broadcast
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.compiler.info import BUILTIN_NAMES
from swarmdsl.compiler.lang_robots import profile_of, require_sense
from swarmdsl.compiler.profiles import VALUE_BYTES
from swarmdsl.errors import SwarmRuntimeError, did_you_mean

MSG = "message"
TYPE_TEXT[MSG] = "a message"
BUILTIN_NAMES.add("msg")
# Per-agent values kept (and recorded) for the receivers: each message value's latest
# broadcast, and the tick of the latest broadcast.
SENT_TICK = "msg_tick"
columns.RUNTIME_VALUES[SENT_TICK] = (NUM, "the tick the agent last broadcast")


def sent_column(name: str) -> str:
    """The per-agent value holding a sender's latest broadcast of message value `name`."""
    return "msg_" + name


def _sent_values(chk) -> dict:
    return {sent_column(n): (t, f"the agent's last broadcast of message value `{n}`")
            for n, t in _channels(chk).items()}


columns.RUNTIME_VALUE_HOOKS.append(_sent_values)

_TYPE_WORDS = {"num": NUM, "number": NUM, "bool": BOOL, "vec": VEC}
LED_COLOURS = {
    "off": 0x505050, "red": 0xFF2020, "green": 0x20D040, "blue": 0x3060FF,
    "yellow": 0xFFE020, "cyan": 0x20E0E0, "magenta": 0xF040F0, "white": 0xFFFFFF,
    "orange": 0xFF9020, "purple": 0x9040E0,
}


def _layouts(chk) -> dict:
    return chk.extra.setdefault("layouts", {})


def _channels(chk) -> dict:
    return chk.extra.setdefault("channels", {})


# ---- agent option `message NAME TYPE ...` ----

def _message_option(chk, opt, kind):
    args = opt.args
    if not args or len(args) % 2:
        chk.fail("`message` lists names and types: `message x num seen bool at vec`",
                 opt.span)
        return
    layout: dict[str, str] = {}
    channels = _channels(chk)
    for name_node, type_node in zip(args[::2], args[1::2], strict=True):
        if not isinstance(name_node, ast.Name):
            chk.fail("a message value needs a name", name_node.span)
            return
        word = getattr(type_node, "id", None)
        if word not in _TYPE_WORDS:
            chk.fail("a message value is `num`, `bool` or `vec`", type_node.span,
                     did_you_mean(str(word), _TYPE_WORDS))
            return
        t = _TYPE_WORDS[word]
        name = name_node.id
        if name in layout:
            chk.fail(f"`{name}` is already in the message of `{kind.name}`", name_node.span)
            continue
        if sent_column(name) in columns.RUNTIME_VALUES:   # still declared: uses check
            what = columns.RUNTIME_VALUES[sent_column(name)][1]
            chk.fail(f"message value `{name}` would be kept as `{sent_column(name)}`, which "
                     f"holds {what}", name_node.span, "choose another name")
        if name in channels and channels[name] != t:
            chk.fail(f"message value `{name}` is {TYPE_TEXT[channels[name]]} in another "
                     f"kind's message, here {TYPE_TEXT[t]}", type_node.span)
            continue
        layout[name] = t
        channels[name] = t
    _layouts(chk)[kind.name] = (layout, opt)


def _refused_layout(chk, kinds) -> bool:
    """Whether the `message` line of one of `kinds` was refused: a value it meant to
    declare is then not also "not in the message" wherever it is sent or read."""
    return any(chk.reported_within(opt.span) for k in kinds
               for opt in k.decl.items_of(ast.Option) if opt.name == "message")


options.AGENT_OPTIONS["message"] = options.OptionSpec(
    _message_option, doc="the kind's message layout: `message NAME TYPE ...`")


def _check_payload(chk, kind) -> None:
    entry = _layouts(chk).get(kind.name)
    if entry is None:
        return
    layout, opt = entry
    prof = profile_of(chk, kind)
    if not require_sense(chk, kind, "message", "message", opt):
        return
    size = sum(VALUE_BYTES[t] for t in layout.values())
    if size > prof.message_bytes:
        parts = ", ".join(f"{n} {VALUE_BYTES[t]}" for n, t in layout.items())
        chk.fail(f"the message of `{kind.name}` takes {size} bytes ({parts}); robot "
                 f"`{prof.name}` sends {prof.message_bytes:g}", opt.span)


checker.KIND_HOOKS.append(_check_payload)


# ---- broadcast(NAME, value) ----

def _check_broadcast(chk, st: ast.ActionStmt, scope, kind):
    if len(st.args) != 2 or not isinstance(st.args[0], ast.Name):
        for a in st.args:
            chk.expr(a, scope)
        chk.fail("`broadcast` takes a message value's name and its value: "
                 "`broadcast(x, believed.x)`", st.span)
        return
    name_node, value = st.args
    chk.extra["broadcasts"] = True
    t = chk.expr(value, scope)
    if not require_sense(chk, kind, "message", "broadcast", st):
        return
    layout = _layouts(chk).get(kind.name, ({}, None))[0]
    if name_node.id not in layout and _refused_layout(chk, [kind]):
        return   # the `message` line's error is the mistake
    if name_node.id not in layout:
        chk.fail(f"`{name_node.id}` is not in the message of `{kind.name}`", name_node.span,
                 did_you_mean(name_node.id, layout) or
                 f"declare it: `message {name_node.id} num` in agent `{kind.name}`")
        return
    want = layout[name_node.id]
    if t not in (want, "error"):
        chk.fail(f"message value `{name_node.id}` holds {TYPE_TEXT[want]}, got "
                 f"{TYPE_TEXT.get(t, t)}", value.span)


def _compile_broadcast(gen, st: ast.ActionStmt, kind):
    column = sent_column(st.args[0].id)
    value = gen.expr(st.args[1])
    vtype = gen.type_of(st.args[1])
    if vtype in (NUM, VEC):  # a message is recorded (msg_NAME) and read by neighbours
        value = nan_guard.guard(value, st.args[1].span, f"the broadcast `{st.args[0].id}`",
                                "guard the division, square root or log that produced it")

    def run(f):
        mask = f.active
        if not mask.any():
            return
        rows = f.idx[mask]
        values = np.array(broadcast(value(f), f.n, vtype))[mask]
        tick = float(f.tick)

        def send():
            cols = f.sim.agents.cols
            cols[column][rows] = values
            cols[SENT_TICK][rows] = tick
        f.effects.append(send)
    return run


actions.register(actions.ActionSpec(
    "broadcast", _check_broadcast, _compile_broadcast,
    "broadcast(NAME, value): send a value of the kind's message; heard next tick",
    batch=True, kilobot=True))


# ---- heard() and msg.NAME ----

def _check_heard(chk, e: ast.Call, scope):
    if scope.init or scope.pair:
        return chk.fail("`heard()` is only available in a status body", e.span)
    if e.args or e.each is not None or e.default is not None:
        return chk.fail("`heard` takes no arguments: `heard()`", e.span)
    require_sense(chk, scope.kind, "message", "heard()", e)
    chk.extra["heard"] = True
    chk.extra.setdefault("heard_calls", []).append((scope.kind, e))
    chk.facts.set_name(e, ("heard",))
    return SET


typing_rules.CALL_RULES["heard"] = _check_heard
declare_calls(("heard",), batch=True, kilobot=True)   # messages: agent columns, pairs


def _check_someone_sends(chk) -> None:
    """A program that listens but never broadcasts hears nothing, ever: every aggregate
    over `heard()` is its empty value (`count` 0) and the run looks valid while it
    measures nothing. Only a `broadcast` fills `heard()` (of any kind: messages cross
    kinds), so without one the listening is a mistake, reported at the first `heard()`."""
    calls = chk.extra.get("heard_calls")
    if not calls or chk.extra.get("broadcasts"):
        return
    kind, call = calls[0]
    who = f"agent `{kind.name}`" if kind is not None else "the agent"
    layouts = _layouts(chk)
    if layouts:
        sender, (layout, _opt) = next(iter(layouts.items()))
        hint = (f"send what it should hear: `broadcast({next(iter(layout))}, VALUE)` in a "
                f"status of `{sender}`")
    else:
        name = kind.name if kind is not None else "NAME"
        hint = (f"declare a message and send it, e.g. `message x num` in agent `{name}` "
                "and `broadcast(x, VALUE)` in a status")
    chk.fail(f"`heard()` is always empty: no kind in the program broadcasts a message, so "
             f"{who} never hears one", call.span, hint)


checker.PROGRAM_CHECK_HOOKS.append(_check_someone_sends)


def _compile_heard(gen, e: ast.Call):
    from swarmdsl.runtime.messaging import messenger_of

    return lambda f: messenger_of(f.sim).heard(f)


codegen.CALL_CODEGEN["heard"] = _compile_heard


def _resolve_msg(chk, e: ast.Name, scope):
    if e.id != "msg":
        return None
    if not scope.pair:
        return chk.fail("`msg` is only defined inside a filter or aggregate over "
                        "`heard()`", e.span, "e.g. `max(heard() : msg.x)`")
    chk.facts.set_name(e, ("msg",))
    return MSG


def _msg_attr(chk, e: ast.Attr, scope):
    channels = _channels(chk)
    if e.name not in channels and _refused_layout(chk, chk.kinds):
        return "error"   # a `message` line's error is the mistake
    if e.name not in channels:
        return chk.fail(f"no kind's message has a value `{e.name}`", e.name_span,
                        did_you_mean(e.name, channels) or
                        "declare it in the sender: `message NAME TYPE`")
    chk.facts.set_name(e, ("msg_value", e.name))
    return channels[e.name]


def _compile_msg_value(gen, e, res):
    column = sent_column(res[1])
    span = e.span

    def read(f):
        if not getattr(getattr(f, "pairs", None), "heard", False):
            raise SwarmRuntimeError(f"`msg.{res[1]}` reads a message: use it over "
                                    "`heard()`, not `neighbors()`", span)
        return f.sim.agents.cols[column][f.j]
    return read


def _source_root(chk, expr, lets: dict):
    """The call a neighbour set comes from, through `where` and `let` names."""
    for _ in range(len(lets) + 64):
        if isinstance(expr, ast.Where):
            expr = expr.source
        elif isinstance(expr, ast.Name) and chk.facts.category(expr) == "local":
            expr = lets.get(expr.id)
        else:
            return expr
    return None


def _check_msg_sources(chk, kind) -> None:
    """`msg.NAME` over `neighbors()` reads no message: report it where it is written."""
    for decl in kind.status_decls.values():
        lets = {st.name: st.value for st in decl.body if isinstance(st, ast.LetStmt)}
        for node in ast.walk(decl):
            if isinstance(node, ast.Where):
                source, inner = node.source, [node.cond]
            elif isinstance(node, ast.Call) and node.args and (
                    node.each is not None or chk.facts.name_of(node) == ("agg", "count")):
                source, inner = node.args[0], [node.each] if node.each is not None else []
            else:
                continue
            root = _source_root(chk, source, lets)
            if not (isinstance(root, ast.Call) and chk.facts.name_of(root) == ("neighbors",)):
                continue
            for part in inner:
                for n in ast.walk(part):
                    if isinstance(n, ast.Attr) and chk.facts.category(n) == "msg_value":
                        chk.fail(f"`msg.{n.name}` reads a message, but these neighbours come "
                                 f"from `{root.name}()`", n.span,
                                 "filter or aggregate over `heard()`")


checker.KIND_HOOKS.append(_check_msg_sources)
typing_rules.NAME_RESOLVERS.append(_resolve_msg)
typing_rules.ATTR_RULES[MSG] = _msg_attr
codegen.NAME_CODEGEN["msg_value"] = _compile_msg_value


# ---- led(colour) / led(r, g, b) ----

def _check_led(chk, st: ast.ActionStmt, scope, kind):
    if len(st.args) == 1 and isinstance(st.args[0], ast.Name):
        if st.args[0].id not in LED_COLOURS:
            chk.fail(f"unknown LED colour `{st.args[0].id}`", st.args[0].span,
                     did_you_mean(st.args[0].id, LED_COLOURS)
                     or f"colours: {', '.join(LED_COLOURS)}")
            return
    elif len(st.args) == 3:
        for a, name in zip(st.args, ("red", "green", "blue"), strict=True):
            if chk.expect(a, NUM, scope, "an LED channel (0 to 1)") != NUM:
                continue
            try:
                value = const_value(a, chk.params)
            except (NotConstant, ArithmeticError, ValueError, TypeError):
                continue
            if isinstance(value, int | float) and not 0 <= value <= 1:
                chk.fail(f"the {name} channel of `led` must be from 0 to 1, got {value:g}",
                         a.span, "a channel is a fraction of full brightness: "
                         "`led(1, 0.5, 0)` is a full red with half the green")
    else:
        chk.fail("`led` takes a colour name or red, green, blue in 0..1: `led(red)`",
                 st.span)
        return
    require_sense(chk, kind, "led", "led", st)
    chk.extra["led"] = True


def _compile_led(gen, st: ast.ActionStmt, kind):
    if len(st.args) == 1:
        packed = float(LED_COLOURS[st.args[0].id])
        colour = lambda f: packed  # noqa: E731
    else:
        channels = [(gen.expr(a), a.span, name)
                    for a, name in zip(st.args, ("red", "green", "blue"), strict=True)]

        def colour(f):
            def byte(fn, span, name):
                v = np.asarray(fn(f), float)
                rows = nan_guard.nan_rows(v, f)
                if rows is not None:
                    raise nan_guard.nan_error(
                        f, int(rows[0]), span, f"the {name} channel of `led`",
                        "guard the division, square root or log that produced it")
                return np.round(np.clip(v, 0.0, 1.0) * 255)
            r, g, b = (byte(*c) for c in channels)
            return r * 65536 + g * 256 + b

    def run(f):
        new = broadcast(colour(f), f.n, NUM)
        f.overlay["led"] = np.where(f.active, new, f.state("led"))
    return run


actions.register(actions.ActionSpec(
    "led", _check_led, _compile_led, "led(colour) or led(r, g, b): the LED colour",
    batch=True, kilobot=True))


# ---- runtime ----

def _messaging_runtime(info, prog, gen) -> None:
    layouts = info.extra.get("layouts", {})
    if not layouts and not info.extra.get("heard"):
        return
    from swarmdsl.runtime.messaging import NEVER, MessageSpec, Messenger

    channels = info.extra.get("channels", {})
    for name, t in channels.items():
        tail, dtype = ((2,), np.float64) if t == VEC else ((), np.bool_ if t == BOOL
                                                         else np.float64)
        prog.var_specs[sent_column(name)] = (tail, dtype, (0.0, 0.0) if t == VEC else
                                             (False if t == BOOL else 0.0))
        prog.var_types[sent_column(name)] = t
    prog.var_specs[SENT_TICK] = ((), np.float64, NEVER)
    prog.var_types[SENT_TICK] = NUM
    profs = [profile_of(info, k) for k in info.kinds]
    spec = MessageSpec(np.array([p.range for p in profs], float),
                       np.array([p.loss for p in profs], float),
                       np.array([p.distance_noise for p in profs], float))
    senders = {k.index: set(layouts[k.name][0]) for k in info.kinds if k.name in layouts}

    senders_of = {sent_column(name): [k for k, chans in senders.items() if name in chans]
                  for name in channels}
    senders_of[SENT_TICK] = list(senders)

    def make(sim):
        return Messenger(sim, spec, senders_of)
    prog.extensions.append(per_replica(make, "its messages run"))


program.PROGRAM_HOOKS.append(_messaging_runtime)
