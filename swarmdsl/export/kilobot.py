"""`swarmdsl export kilobot`: a checked program as a Kilobot program in C for kilolib.

Every robot runs one program and plays the kind its id gives it (ids are numbered kind
by kind, as `swarmdsl run` numbers agents): its variables, status and outgoing message
become a struct (`mydata`, as Kilombo and kilolib programs keep their state), its
statuses a state machine stepped from `loop()` once per program tick (0.1 s, about 3 of
kilolib's 31 ticks a second), the clock starting with the loop and never catching up.
Each robot draws from its own random stream, seeded from its hardware entropy and id.
`broadcast` sets the values `loop()` packs into the message's 9-byte payload at the end
of the tick and hands to the transmit interrupt whole; received messages fill a table
of recently heard neighbours (sender id, measured distance, values), which `heard()`
aggregates read. Motion is what a robot without a compass commands: stop, go forward,
turn left or right of its own way (`stop`, `forward`, `turn_left`, `turn_right`,
`rotate(velocity, ANGLE)`), with kilolib's calibrated motor values and a spin-up
whenever a motor starts. Alongside the C: `kilolib_api.h` (the AVR build's
declarations), a Makefile (Kilombo headless, the AVR `.hex`, `avr-size`) and Kilombo's
parameter and placement files; a walled world becomes Kilombo's arena
(`kilobot_arena.py`).

`translate` refuses, located, whatever it cannot translate; `check --target kilobot`
runs it without writing anything.
"""

from __future__ import annotations

import json
import re

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import BOOL, NUM, VEC
from swarmdsl.compiler.lang_robots import profile_of
from swarmdsl.errors import SwarmCheckError
from swarmdsl.export import kilobot_arena as arena
from swarmdsl.export.kilobot_c import KindC, Refusal, ident, number
from swarmdsl.export.kilobot_csrc import MOTION, RANDOM, STEERING, TRILATERATION, preamble
from swarmdsl.export.kilobot_memory import (  # noqa: F401  (re-exported)
    STATE_BUDGET,
    ram_refusals,
    state_bytes,
    state_refusals,
)
from swarmdsl.export.kilobot_memory import (
    channels as _channels,
)
from swarmdsl.export.kilobot_ranges import saturation_warnings
from swarmdsl.export.kilolib_api import HEADER
from swarmdsl.export.placement import beliefs_at_start, start

KILOBOT_SENSES = frozenset({"distance", "message", "led"})
PAYLOAD_BYTES = 9
SHORT_IDS = 256          # up to this many robots, the sender's id takes one byte
TABLE = 8                 # neighbours remembered (each about 5 + 4 bytes a value)
STEP_TICKS = 3            # kilo_ticks per program tick (31 a second, a tick is 0.1 s)
HEARD_TICKS = 40          # a neighbour unheard this long (1.3 s) leaves the table
SEND_WINDOW = 5           # a broadcast is transmitted for 5 program ticks (0.5 s)
KILOMBO_STEP = 0.02       # seconds of Kilombo time per simulation step
TICK_SECONDS = 0.1        # a program tick on a Kilobot (the profile's units)
_OPTIONS = ("count", "place", "robot", "message", "velocity")
_OBSERVERS = (ast.InvariantDecl, ast.EventuallyDecl, ast.ResponseDecl, ast.MetricDecl)
_TOP = (ast.ParamDecl, ast.WorldDecl, ast.RobotDecl, ast.AgentDecl, *_OBSERVERS)


def translate(program, seed: int = 0, warnings: list | None = None) -> dict[str, str]:
    """The C source of `program` (a compiled Program), its header and Makefile, and
    Kilombo's files, by file name (robots placed as `swarmdsl run --seed SEED` places
    them); `Refusals` (every refusal, each once) when something cannot be translated.
    What runs but differs on robots is appended to `warnings`, located."""
    info = program.info
    refusals: list[Refusal] = arena.refusals(info)
    moves = any(k.options.get("velocity") is not None for k in info.kinds)
    motions: list = []           # motion sizes that are not the robot's
    for decl in info.tree.decls:
        if not isinstance(decl, _TOP):
            refusals.append(Refusal(_decl_words(decl), getattr(decl, "span", None)))
    placed = start(program, seed)
    firsts = _first_ids(info, placed, refusals)
    steer = bool(info.extra.get("beliefs"))
    layouts, networks = {}, {}
    functions, inits = [], {}
    for kind in info.kinds:
        refusals += _kind_refusals(info, kind, steer)
        layouts[kind.name] = _layout(info, kind, len(placed), refusals)
        gen = KindC(info, kind, firsts[kind.index], steer, networks)
        functions += [gen.status_function(s) for s in kind.statuses]
        inits[kind.index] = []
        for var in kind.vars.values():
            try:
                inits[kind.index].append(gen.initial(var))
            except Refusal as refusal:
                refusals.append(refusal)
        refusals += gen.refusals
        moves = moves or gen.moves
        motions += gen.warnings
    refusals += state_refusals(info, layouts)
    stacks: dict = {}
    nets = _networks(networks, refusals, stacks) if networks and not refusals else ""
    if not refusals:
        tables = len(placed) * (any(k for *_, k in placed) + any(m for _p, _d, m, _k in placed))
        refusals += ram_refusals(info, layouts, stacks, tables)
    if refusals:
        raise Refusals(refusals).with_source(program.source)
    if warnings is not None:
        found = (arena.warnings(info, moves) + motions
                 + saturation_warnings(info, len(placed)))
        warnings += [w.with_source(program.source) for w in found]
    name = program_name(info.filename)
    believed = beliefs_at_start(program, seed) if steer else None
    c = _source(info, layouts, nets + "\n".join(functions), inits, placed, believed,
                arena.kilombo_arena(info))
    return {f"{name}.c": c, "kilolib_api.h": HEADER, "Makefile": _makefile(name),
            **_kilombo_files(program, placed, seed)}


class Refusals(SwarmCheckError):
    """Every refusal of a program, each construct once (a construct translated several
    times, as a `let` of a neighbour set inlined in each aggregate, is refused once),
    in source order, and their count."""

    def __init__(self, refusals: list[Refusal]):
        unique = {}
        for r in refusals:
            where = (r.span.line, r.span.col, r.span.end_line, r.span.end_col) if r.span \
                else (0, 0, 0, 0)
            unique.setdefault((where, r.message), r)
        super().__init__([unique[k] for k in sorted(unique, key=lambda k: k[0])])

    def render(self, source: str | None = None) -> str:
        n = len(self.diagnostics)
        return (super().render(source) +
                f"\n{n} error{'s' * (n != 1)}: what a Kilobot cannot run (target kilobot)")


def _networks(networks: dict, refusals: list, stacks: dict) -> str:
    """The C of the program's `nn` networks (weights in flash), refused at their first
    call when one cannot be read or they take more than their share of flash; `stacks`
    gets each network's activations (bytes of stack, by model path)."""
    from swarmdsl.export.kilobot_nn import FLASH_BUDGET, ROM, network_c

    parts, total = [ROM], 0
    for path, (index, span) in networks.items():
        try:
            c, size, stacks[path] = network_c(index, path, span)
        except Refusal as refusal:
            refusals.append(refusal)
            continue
        total += size
        if total > FLASH_BUDGET:
            refusals.append(Refusal(f"networks of {total} bytes", span,
                                    f"a Kilobot program keeps its networks within "
                                    f"{FLASH_BUDGET} bytes of flash"))
        parts.append(c)
    return "".join(parts)


def _first_ids(info, placed, refusals: list) -> list[int]:
    """Each kind's first id: a robot's kind is told by its id (`kilo_uid`), so each
    kind's robots must have consecutive ids, as `swarmdsl run` numbers them."""
    kinds = [k for _pos, _direction, _moving, k in placed]
    firsts = []
    for kind in info.kinds:
        ids = [i for i, k in enumerate(kinds) if k == kind.index]
        if ids and ids != list(range(ids[0], ids[0] + len(ids))):
            refusals.append(Refusal(f"agent `{kind.name}`, whose ids are not consecutive,",
                                    kind.decl.name_span))
        firsts.append(ids[0] if ids else 0)
    return firsts


def program_name(filename: str) -> str:
    """The exported files' stem: the program file's, reduced to C and make's safe
    characters (it names the `.c`, the executable and the Makefile's targets)."""
    stem = re.sub(r"\.swarm$", "", filename.replace("\\", "/").rsplit("/", 1)[-1])
    stem = re.sub(r"[^A-Za-z0-9_]", "_", stem)[:40]
    return stem if re.match(r"[A-Za-z]", stem) else f"program_{stem}"


def _decl_words(decl) -> str:
    words = {"FieldDecl": "a field", "RegionDecl": "a region"}
    name = type(decl).__name__
    return words.get(name, f"the declaration `{name.removesuffix('Decl').lower()}`")


def _kind_refusals(info, kind, steer: bool) -> list[Refusal]:
    out = []
    prof = profile_of(info, kind)
    if prof.senses is None or not prof.senses <= KILOBOT_SENSES:
        extra = "every sense" if prof.senses is None else ", ".join(
            sorted(prof.senses - KILOBOT_SENSES))
        opt = kind.options.get("robot")
        out.append(Refusal(f"agent `{kind.name}` on robot `{prof.name}`, which senses "
                           f"{extra},", opt.span if opt else kind.decl.name_span,
                           "declare `robot kilobot` (or a robot `like kilobot`) so the "
                           "checker keeps it to what a Kilobot senses"))
    for item in kind.decl.items:
        if isinstance(item, ast.Option) and item.name not in _OPTIONS + ("believe",) * steer:
            out.append(Refusal(f"the agent option `{item.name}`", item.name_span))
        elif isinstance(item, ast.Option) and item.name == "velocity" and steer:
            out.append(Refusal("a starting `velocity` with beliefs", item.name_span,
                               "a robot steered by its beliefs starts at rest: set "
                               "`velocity` in its first status"))
        elif not isinstance(item, (ast.Option, ast.VarDecl, ast.AttrDecl,
                                   ast.StatusDecl, *_OBSERVERS)):
            out.append(Refusal(_decl_words(item), item.span))
    return out


def _layout(info, kind, robots: int, refusals: list) -> dict[str, str]:
    """The kind's message values in payload order, refused at the `message` line when
    they do not fit the 9 bytes with the sender's id."""
    layout, opt = info.extra.get("layouts", {}).get(kind.name, ({}, None))
    if not layout:
        return {}
    header = _header_bytes(info, robots)
    size = sum(_BYTES[t] for t in layout.values()) + header
    if size > PAYLOAD_BYTES:
        parts = ", ".join(f"{n} {_BYTES[t]}" for n, t in layout.items())
        who = f", sender id {header}" if header else ""
        refusals.append(Refusal(f"a message of {size} bytes ({parts}{who})", opt.span,
                                f"a Kilobot message carries {PAYLOAD_BYTES} bytes"))
    return dict(layout)


_BYTES = {NUM: 2, BOOL: 1, VEC: 4}    # a number a rounded int16, a vector two


def _header_bytes(info, robots: int) -> int:
    """The payload's bytes before the values: the sender's id when someone listens
    (one byte for a swarm of up to 256 robots: a robot's id is its agent id). Its kind,
    which says the values' layout, is its id's: no byte."""
    if not info.extra.get("heard"):
        return 0
    return 1 if robots <= SHORT_IDS else 2


# ---- the C file ----

_CTYPES = {NUM: "float", BOOL: "uint8_t", VEC: "kb_vec_t"}


def _source(info, layouts, functions: str, inits: dict[int, list[str]], placed,
            believed, walls: str) -> str:
    """The program's C file. `believed` (a program with beliefs) is each robot's belief
    and heading as it is put down, else None; `walls` the Kilombo build's arena."""
    kinds = info.kinds
    span = kinds[0].decl.name_span
    heard = bool(info.extra.get("heard"))
    steer = believed is not None
    channels = _channels(layouts)
    values = [(ident(n, span), _CTYPES[t]) for n, t in channels.items()]
    fields = "".join(f"    {c} m_{n};\n" for n, c in values)
    out_fields = "".join(f"    {c} out_{n};\n" for n, c in values)
    var_fields = "".join(
        f"    {_CTYPES[v.type]} v{k.index}_{ident(v.name, span)};\n"
        for k in kinds for v in k.vars.values())
    steer_fields = ("    kb_vec_t vel;        /* the commanded velocity, believed frame */\n"
                    "    kb_vec_t believed;\n    uint8_t located;\n"
                    "    kb_vec_t body;       /* where dead reckoning puts the robot */\n"
                    "    kb_vec_t goal;       /* where its motors carry it */\n"
                    "    float head;          /* its heading, dead reckoned */\n"
                    "    uint32_t moved_at;\n") if steer else ""
    enum = ", ".join(f"ST_{ident(s, span)} = {i}" for i, s in enumerate(info.status_names))
    names = ", ".join(f"`{ident(k.name, span)}`" for k in kinds)
    steps = "".join(
        f"    case {k.index}:\n        switch (mydata->status) {{\n"
        + "".join(f"        case ST_{s}: kb_k{k.index}_{s}(); break;\n" for s in k.statuses)
        + "        }\n        break;\n" for k in kinds)
    starts = "".join(
        f"    case {k.index}:\n        mydata->status = ST_{k.statuses[0]};\n"
        + "".join(inits[k.index]) + "        break;\n" for k in kinds)
    zero = {"float": "0", "uint8_t": "0", "kb_vec_t": "kb_v(0.0f, 0.0f)"}
    parts = [f"/* {program_name(info.filename)}.c: agent kind{'s' * (len(kinds) > 1)} {names}, "
             "exported by swarmdsl for the Kilobot (kilolib). */\n",
             preamble(table=TABLE, step=STEP_TICKS, heard=HEARD_TICKS, window=SEND_WINDOW),
             TRILATERATION if _trilaterates(info) else "",
             f"\nenum {{ {enum} }};\n\n",
             "typedef struct {\n    uint8_t used;\n    uint16_t uid;\n    uint8_t dist;   "
             "/* estimate_distance, mm */\n    uint32_t heard_at;\n" + fields +
             "} kb_neighbor_t;\n\n",
             "typedef struct {\n    uint8_t kind;\n    uint8_t status;\n    uint32_t tick;\n"
             "    uint8_t moving;   /* the commanded velocity is not (0, 0) */\n"
             "    uint8_t motion;   /* this tick's KB_STOP, KB_STRAIGHT, KB_LEFT, KB_RIGHT */\n"
             "    uint8_t motors;   /* the motion the motors run */\n"
             "    uint32_t last_step;\n    uint8_t sent;\n    uint32_t sent_tick;\n"
             "    uint8_t started;  /* loop() has run: the program's time has begun */\n"
             "    uint32_t rng;     /* the robot's own random stream */\n"
             "    message_t tx[2];  /* the message being packed and the one handed out */\n"
             "    volatile uint8_t tx_front;   /* which tx the transmit interrupt sends */\n"
             "    volatile uint8_t tx_on;      /* whether it sends one */\n"
             + steer_fields + var_fields + out_fields +
             "    kb_neighbor_t table[KB_TABLE];\n} kb_state_t;\n\n",
             "#ifdef KB_KILOLIB\nstatic kb_state_t kb_state;\n"
             "static kb_state_t *const mydata = &kb_state;\n#else\n"
             "REGISTER_USERDATA(kb_state_t)\n#endif\n\n",
             RANDOM, MOTION, STEERING if steer else "",
             _per_robot("kb_moving_at_start", [int(m) for _p, _d, m, _k in placed]),
             _per_robot("kb_kind_of", [k for _p, _d, _m, k in placed]),
             _speeds(info) + _beliefs_at_start(believed) if steer else "",
             functions, "\nstatic void kb_step_status(void)\n{\n    switch (mydata->kind) {\n"
             + steps + "    }\n}\n\n",
             _messages(info, layouts, heard, len(placed)),
             "\nvoid setup(void)\n{\n"
             "    kb_seed(kilo_uid);\n"
             "    mydata->kind = kb_kind_of(kilo_uid);\n    mydata->tick = 0;\n"
             "    mydata->started = 0;\n    mydata->last_step = kilo_ticks;\n"
             "    mydata->sent = 0;\n    mydata->tx_on = 0;\n    mydata->tx_front = 0;\n"
             "    for (uint8_t i = 0; i < KB_TABLE; i++) mydata->table[i].used = 0;\n"
             "    mydata->moving = kb_moving_at_start(kilo_uid);\n    mydata->motors = KB_STOP;\n"
             + "".join(f"    mydata->out_{n} = {zero[c]};\n" for n, c in values)
             + ("    kb_start_believing();\n" if steer else "") +
             "    switch (mydata->kind) {\n" + starts + "    }\n"
             "    set_motors(0, 0);\n}\n\n",
             _loop(heard, steer, bool(channels)),
             _json_state(info, span, steer), walls,
             "int main(void)\n{\n    kilo_init();\n",
             "    kilo_message_rx = kb_message_rx;\n" if heard else "",
             "    kilo_message_tx = kb_message_tx;\n" if channels else "",
             "    kilo_start(setup, loop);\n#ifndef KB_KILOLIB\n"
             "    SET_CALLBACK(json_state, kb_json_state);\n    SET_CALLBACK(reset, setup);\n"
             + ("    SET_CALLBACK(obstacles, kb_arena);\n" if walls else "") +
             "#endif\n    return 0;\n}\n"]
    return "".join(parts)


def _trilaterates(info) -> bool:
    return any(res[0] == "trilaterate" for res in info.facts.resolutions())


def _loop(heard: bool, steer: bool, sends: bool) -> str:
    """`loop()`: a program tick every KB_STEP_TICKS kilo_ticks, the program's clock
    starting when loop() first runs (kilolib may call setup() long before, at power-on,
    and the program start only at Run): tick 0 runs a step later, as every tick after
    it. A tick that comes late is not caught up, so time never bursts. Without beliefs
    the status picks this tick's motion (go on, stop, turn); with them, the commanded
    velocity moves the belief and the goal and the motors steer the body to the goal.
    Last, the tick's message is packed and handed to the transmit interrupt."""
    head = ("void loop(void)\n{\n"
            "    uint32_t now = kilo_ticks;\n"
            "    if (!mydata->started) {   /* the program's time starts now */\n"
            "        mydata->started = 1;\n        mydata->last_step = now;\n"
            + ("        mydata->moved_at = now;\n" if steer else "") +
            "        return;\n    }\n"
            "    if ((uint32_t)(now - mydata->last_step) < KB_STEP_TICKS) return;\n"
            "    mydata->last_step = now;   /* a late tick is not caught up */\n"
            + ("    kb_forget();\n" if heard else ""))
    run = "    kb_step_status();\n"
    tail = "    mydata->tick++;\n" + ("    kb_post();\n" if sends else "") + "}\n\n"
    if steer:
        return (head + "    kb_odometry();\n" + run +
                "    mydata->vel = kb_limit(mydata->vel, kb_speed_of(mydata->kind));\n"
                "    mydata->goal = kb_vadd(mydata->goal, mydata->vel);\n"
                "    if (mydata->located) mydata->believed = kb_vadd(mydata->believed, "
                "mydata->vel);\n"
                "    kb_motors(kb_steer());\n" + tail)
    return (head + "    mydata->motion = mydata->moving ? KB_STRAIGHT : KB_STOP;\n" + run +
            "    if (!mydata->moving) mydata->motion = KB_STOP;\n"
            "    kb_motors(mydata->motion);\n" + tail)


def _speeds(info) -> str:
    """Each kind's speed limit (its robot profile's `speed`, units a tick)."""
    cases = "".join(f"    case {k.index}: return {number(profile_of(info, k).speed, None)};\n"
                    for k in info.kinds)
    return (f"static float kb_speed_of(uint8_t kind)\n{{\n    switch (kind) {{\n{cases}"
            "    }\n    return 0.0f;\n}\n\n")


def _beliefs_at_start(believed) -> str:
    """Each robot's belief and heading as the experimenter puts it down (`believe` and
    the placement of `swarmdsl run`), as code (in flash, not RAM): a located robot's
    body starts at its belief; an unlocated one's at (0, 0) of its own frame."""
    cases = []
    for uid, (belief, heading) in enumerate(believed):
        where = "" if belief is None else (
            f" mydata->believed = kb_v({number(belief[0], None)}, {number(belief[1], None)});"
            " mydata->located = 1;")
        cases.append(f"    case {uid}: mydata->head = {number(heading, None)};{where} break;\n")
    return ("static void kb_start_believing(void)\n{\n"
            "    mydata->vel = mydata->believed = kb_v(0.0f, 0.0f);\n"
            "    mydata->located = 0;\n    mydata->head = 0.0f;\n"
            "    mydata->moved_at = kilo_ticks;\n"
            "    switch (kilo_uid) {\n" + "".join(cases) + "    }\n"
            "    mydata->body = mydata->goal = mydata->believed;\n}\n\n")


def _per_robot(function: str, values: list[int]) -> str:
    """A function of a robot's id giving its entry of `values` (0 beyond them): which
    robots start moving and each robot's kind, the experimenter's set-up as `swarmdsl
    run` places them."""
    if not any(values):
        return f"static uint8_t {function}(uint16_t uid) {{ (void)uid; return 0; }}\n\n"
    rows = ", ".join(str(v) for v in values)
    return (f"static uint8_t {function}(uint16_t uid)\n{{\n"
            f"    static const uint8_t of[{len(values)}] = {{ {rows} }};\n"
            f"    return uid < {len(values)} ? of[uid] : 0;\n}}\n\n")


def _messages(info, layouts, heard: bool, robots: int) -> str:
    """The transmit callback (pack the latest broadcast values of the robot's kind),
    the receive callback (a table entry per sender, oldest replaced; the sender's kind,
    its id's, says its values; values it does not send read 0) and the table's ageing."""
    if not _channels(layouts):
        return ""
    header = _header_bytes(info, robots)
    pack, unpack = [], []
    for kind in info.kinds:
        offset = header
        packs, unpacks = [], []
        for name, t in layouts[kind.name].items():
            at = f"[{offset}]"
            if t == NUM:
                packs.append(f"        kb_pack(&m->data{at}, mydata->out_{name});\n")
                unpacks.append(f"        e->m_{name} = kb_unpack(&m->data{at});\n")
            elif t == VEC:
                packs.append(f"        kb_pack(&m->data{at}, mydata->out_{name}.x);\n"
                             f"        kb_pack(&m->data[{offset + 2}], "
                             f"mydata->out_{name}.y);\n")
                unpacks.append(f"        e->m_{name} = kb_v(kb_unpack(&m->data{at}), "
                               f"kb_unpack(&m->data[{offset + 2}]));\n")
            else:
                packs.append(f"        m->data{at} = mydata->out_{name} ? 1 : 0;\n")
                unpacks.append(f"        e->m_{name} = m->data{at} ? 1 : 0;\n")
            offset += _BYTES[t]
        pack.append(f"    case {kind.index}:\n" + "".join(packs) + "        break;\n")
        unpack.append(f"    case {kind.index}:\n" + "".join(unpacks) + "        break;\n")
    sender = ""
    if heard:
        sender = "    m->data[0] = (uint8_t)(kilo_uid & 0xFF);\n"
        if header == 2:
            sender += "    m->data[1] = (uint8_t)(kilo_uid >> 8);\n"
    # loop() packs the tick's message into the buffer the interrupt is not sending and
    # then hands it over whole (one byte written): the interrupt never reads a message
    # half packed, nor values loop() is half-way through writing.
    tx = ("static void kb_post(void)\n{\n"
          "    if (!mydata->sent || mydata->tick - mydata->sent_tick > KB_SEND_WINDOW) {\n"
          "        mydata->tx_on = 0;\n        return;\n    }\n"
          "    message_t *m = &mydata->tx[mydata->tx_front ^ 1];\n"
          "    for (uint8_t i = 0; i < 9; i++) m->data[i] = 0;\n"
          "    m->type = NORMAL;\n" + sender +
          "    switch (mydata->kind) {\n" + "".join(pack) + "    }\n"
          "    m->crc = message_crc(m);\n"
          "    __asm__ __volatile__(\"\" ::: \"memory\");   /* packed before handed over */\n"
          "    mydata->tx_front ^= 1;\n    mydata->tx_on = 1;\n}\n\n"
          "static message_t *kb_message_tx(void)   /* the transmit interrupt's */\n{\n"
          "    return mydata->tx_on ? &mydata->tx[mydata->tx_front] : 0;\n}\n")
    if not heard:
        return tx
    zero = {NUM: "0", BOOL: "0", VEC: "kb_v(0.0f, 0.0f)"}
    clear = "".join(f"    e->m_{n} = {zero[t]};\n" for n, t in _channels(layouts).items())
    uid = ("(uint16_t)m->data[0]" if header == 1 else
           "(uint16_t)m->data[0] | ((uint16_t)m->data[1] << 8)")
    rx = ("\nstatic void kb_message_rx(message_t *m, distance_measurement_t *d)\n{\n"
          "    if (m->type != NORMAL) return;\n"
          f"    uint16_t uid = {uid};\n"
          "    kb_neighbor_t *e = 0;\n"
          "    for (uint8_t i = 0; i < KB_TABLE; i++) {   /* its entry, a free one, "
          "or the oldest */\n"
          "        kb_neighbor_t *c = &mydata->table[i];\n"
          "        if (c->used && c->uid == uid) { e = c; break; }\n"
          "        if (!e || (e->used && (!c->used || c->heard_at < e->heard_at))) e = c;\n"
          "    }\n"
          "    e->used = 1;\n    e->uid = uid;\n    e->dist = estimate_distance(d);\n"
          "    e->heard_at = kilo_ticks;\n" + clear +
          f"    switch ({'kb_kind_of(uid)' if len(info.kinds) > 1 else '0'}) {{\n"
          + "".join(unpack) + "    }\n}\n\n"
          "static void kb_forget(void)\n{\n"
          "    for (uint8_t i = 0; i < KB_TABLE; i++)\n"
          "        if (mydata->table[i].used &&\n"
          "            kilo_ticks - mydata->table[i].heard_at > KB_HEARD_TICKS)\n"
          "            mydata->table[i].used = 0;\n}\n")
    return tx + rx


def _json_state(info, span, steer: bool) -> str:
    """Kilombo's per-robot state (its state file): kind, status name, tick, variables
    (a vector as [x, y]) and, with beliefs, `believed` and `located`."""
    names = ", ".join(f'"{ident(s, span)}"' for s in info.status_names)
    kinds = ", ".join(f'"{ident(k.name, span)}"' for k in info.kinds)

    def value(c: str, t: str) -> str:
        return f"kb_json_vec({c})" if t == VEC else f"json_real({c})"
    sets = "".join(
        f"    case {k.index}:\n" + "".join(
            f'        json_object_set_new(s, "{ident(v.name, span)}", '
            f"{value(f'mydata->v{k.index}_{ident(v.name, span)}', v.type)});\n"
            for v in k.vars.values()) + "        break;\n" for k in info.kinds)
    beliefs = ('    json_object_set_new(s, "believed", kb_json_vec(mydata->believed));\n'
               '    json_object_set_new(s, "located", json_integer(mydata->located));\n'
               if steer else "")
    return ("#ifndef KB_KILOLIB\n"
            f"static const char *const kb_status_names[] = {{ {names} }};\n"
            f"static const char *const kb_kind_names[] = {{ {kinds} }};\n"
            "static inline json_t *kb_json_vec(kb_vec_t v)\n{\n"
            "    json_t *a = json_array();\n    json_array_append_new(a, json_real(v.x));\n"
            "    json_array_append_new(a, json_real(v.y));\n    return a;\n}\n"
            "json_t *kb_json_state(void)\n{\n    json_t *s = json_object();\n"
            '    json_object_set_new(s, "kind", json_string(kb_kind_names[mydata->kind]));\n'
            '    json_object_set_new(s, "status", '
            "json_string(kb_status_names[mydata->status]));\n"
            '    json_object_set_new(s, "tick", json_integer(mydata->tick));\n' + beliefs +
            "    switch (mydata->kind) {\n" + sets + "    }\n    return s;\n}\n#endif\n\n")


# ---- Makefile and Kilombo's files ----

_MAKEFILE = """\
# Build {name}.c, exported by swarmdsl for the Kilobot.
#   make kilombo KILOMBO=PREFIX     headless Kilombo (PREFIX/include/kilombo.h,
#                                   PREFIX/lib/libheadless.a), then: make run
#   make hex KILOLIB=.../kilolib.a  the real robot's program ({name}.hex)
#   make size                       flash and RAM of the program on the ATmega328P
#                                   (kilolib's own code not counted)
#   CAL="-DKB_SPEED=7 -DKB_TURN_RATE=13"  a robot's measured straight speed (mm/s)
#                                   and turn rate (degrees/s), for steering by beliefs
KILOMBO ?= /usr/local
KILOLIB ?=
CAL ?=
AVR_CFLAGS = -mmcu=atmega328p -Os -std=gnu99 -DF_CPU=8000000 -Wall \\
	-funsigned-char -funsigned-bitfields -fpack-struct -fshort-enums $(CAL)

kilombo: {name}
{name}: {name}.c
	gcc -std=gnu99 -O2 -Wall -fcommon $(CAL) -I$(KILOMBO)/include $< \\
		-L$(KILOMBO)/lib -lheadless -ljansson -lm -o $@
run: {name}
	./{name} -p kilombo.json -b bots.json

{name}.elf: {name}.c kilolib_api.h
	@test -n "$(KILOLIB)" || (echo "give KILOLIB=path/to/kilolib.a"; exit 1)
	avr-gcc $(AVR_CFLAGS) -o $@ $< $(KILOLIB) -lm
hex: {name}.hex
{name}.hex: {name}.elf
	avr-objcopy -O ihex -R .eeprom -R .fuse -R .lock -R .signature $< $@

size: {name}.c kilolib_api.h
	avr-gcc $(AVR_CFLAGS) -Wl,--unresolved-symbols=ignore-all -o {name}-size.elf $< -lm
	avr-size {name}-size.elf

clean:
	rm -f {name} {name}.elf {name}.hex {name}-size.elf states.json

.PHONY: kilombo run hex size clean
"""


def _makefile(name: str) -> str:
    return _MAKEFILE.format(name=name)


def _kilombo_files(program, placed, seed: int) -> dict[str, str]:
    """Kilombo's parameter file (headless, the robots' hearing range, the world's
    `steps` as simulated time, states saved every second) and the robots' placement
    (Kilombo's `-b` file)."""
    kind = program.info.kinds[0]
    bots = [{"ID": i, "x_position": x, "y_position": y, "direction": direction,
             "state": {}} for i, ((x, y), direction, _moving, _kind) in enumerate(placed)]
    params = {
        # Kilombo's randSeed 0 seeds from the clock: seed + 1 keeps a run repeatable.
        "botName": program_name(program.info.filename), "randSeed": seed + 1,
        "nBots": len(bots), "formation": "random", "timeStep": KILOMBO_STEP,
        "simulationTime": program.info.world.steps * TICK_SECONDS,
        "commsRadius": round(profile_of(program.info, kind).range),
        "distributePercent": 0.8, "displayWidth": 800, "displayHeight": 600,
        "stateFileName": "states.json", "stateFileSteps": round(1 / KILOMBO_STEP),
        "storeHistory": 0, "GUI": 0,
    }
    return {"kilombo.json": json.dumps(params, indent=2) + "\n",
            "bots.json": json.dumps({"bot_states": bots, "ticks": 0}, indent=2) + "\n"}
