"""`swarmdsl export kilobot`: a checked program as a Kilobot program in C for kilolib.

Every robot runs one program and plays the kind its id gives it (ids are numbered kind
by kind, as `swarmdsl run` numbers agents): its variables, status and outgoing message
become a struct (`mydata`, as Kilombo and kilolib programs keep their state), its
statuses a state machine stepped from `loop()` once per program tick (0.1 s, about 3 of kilolib's 31
ticks a second). `broadcast` sets the values the transmit callback packs into the
message's 9-byte payload; received messages fill a table of recently heard neighbours
(sender id, measured distance, values), which `heard()` aggregates read. Motion is
what a robot without a compass commands: stop, or turn left or right of its own way
(`rotate(velocity, ANGLE)`), with kilolib's calibrated motor values. Alongside the
C: `kilolib_api.h` (the AVR build's declarations), a Makefile (Kilombo headless, the
AVR `.hex`, `avr-size`) and Kilombo's parameter and placement files.

`translate` refuses, located, whatever it cannot translate; `check --target kilobot`
runs it without writing anything.
"""

from __future__ import annotations

import json
import re

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import BOOL, NUM
from swarmdsl.compiler.lang_robots import profile_of
from swarmdsl.errors import SwarmCheckError
from swarmdsl.export.kilobot_c import KindC, Refusal, ident
from swarmdsl.export.kilolib_api import HEADER
from swarmdsl.export.placement import start

KILOBOT_SENSES = frozenset({"distance", "message", "led"})
PAYLOAD_BYTES = 9
SENDER_BYTES = 2          # the sender's id, which the neighbour table is keyed on
TABLE = 8                 # neighbours remembered (each about 5 + 4 bytes a value)
STEP_TICKS = 3            # kilo_ticks per program tick (31 a second, a tick is 0.1 s)
HEARD_TICKS = 40          # a neighbour unheard this long (1.3 s) leaves the table
SEND_WINDOW = 5           # a broadcast is transmitted for 5 program ticks (0.5 s)
KILOMBO_STEP = 0.02       # seconds of Kilombo time per simulation step
TICK_SECONDS = 0.1        # a program tick on a Kilobot (the profile's units)
_OPTIONS = ("count", "place", "robot", "message", "velocity")
_OBSERVERS = (ast.InvariantDecl, ast.EventuallyDecl, ast.ResponseDecl, ast.MetricDecl)
_TOP = (ast.ParamDecl, ast.WorldDecl, ast.RobotDecl, ast.AgentDecl, *_OBSERVERS)


def translate(program, seed: int = 0) -> dict[str, str]:
    """The C source of `program` (a compiled Program), its header and Makefile, and
    Kilombo's files, by file name (robots placed as `swarmdsl run --seed SEED` places
    them); a `SwarmCheckError` of every refusal when something cannot be translated."""
    info = program.info
    refusals: list[Refusal] = []
    for decl in info.tree.decls:
        if not isinstance(decl, _TOP):
            refusals.append(Refusal(_decl_words(decl), getattr(decl, "span", None)))
    placed = start(program, seed)
    firsts = _first_ids(info, placed, refusals)
    layouts = {}
    functions, inits = [], {}
    for kind in info.kinds:
        refusals += _kind_refusals(info, kind)
        layouts[kind.name] = _layout(info, kind, refusals)
        gen = KindC(info, kind, firsts[kind.index])
        functions += [gen.status_function(s) for s in kind.statuses]
        inits[kind.index] = []
        for var in kind.vars.values():
            try:
                inits[kind.index].append(gen.initial(var))
            except Refusal as refusal:
                refusals.append(refusal)
        refusals += gen.refusals
    refusals += _memory_refusals(info, layouts)
    if refusals:
        refusals.sort(key=lambda r: (r.span.line, r.span.col) if r.span else (0, 0))
        raise SwarmCheckError(refusals).with_source(program.source)
    name = program_name(info.filename)
    c = _source(info, layouts, "\n".join(functions), inits, placed)
    return {f"{name}.c": c, "kilolib_api.h": HEADER, "Makefile": _makefile(name),
            **_kilombo_files(program, placed, seed)}


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


def _kind_refusals(info, kind) -> list[Refusal]:
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
        if isinstance(item, ast.Option) and item.name not in _OPTIONS:
            out.append(Refusal(f"the agent option `{item.name}`", item.name_span))
        elif not isinstance(item, (ast.Option, ast.VarDecl, ast.AttrDecl,
                                   ast.StatusDecl, *_OBSERVERS)):
            out.append(Refusal(_decl_words(item), item.span))
    return out


def _layout(info, kind, refusals: list) -> dict[str, str]:
    """The kind's message values in payload order, refused at the `message` line when
    a value has no packing or they do not fit the 9 bytes with the sender's id (and
    kind, when there are several)."""
    layout, opt = info.extra.get("layouts", {}).get(kind.name, ({}, None))
    if not layout:
        return {}
    for name, t in layout.items():
        if t not in (NUM, BOOL):
            refusals.append(Refusal(f"the vector message value `{name}`", opt.span,
                                    "send its components as two numbers"))
    header = _header_bytes(info)
    size = sum(_BYTES.get(t, 4) for t in layout.values()) + header
    if size > PAYLOAD_BYTES:
        parts = ", ".join(f"{n} {_BYTES.get(t, 4)}" for n, t in layout.items())
        who = f", sender id and kind {header}" if header else ""
        refusals.append(Refusal(f"a message of {size} bytes ({parts}{who})", opt.span,
                                f"a Kilobot message carries {PAYLOAD_BYTES} bytes"))
    return dict(layout)


_BYTES = {NUM: 2, BOOL: 1}


def _header_bytes(info) -> int:
    """The payload's bytes before the values: the sender's id when someone listens,
    and its kind when there are several (the values' layout is its kind's)."""
    if not info.extra.get("heard"):
        return 0
    return SENDER_BYTES + (len(info.kinds) > 1)


def _channels(layouts: dict[str, dict[str, str]]) -> dict[str, str]:
    """Every message value of every kind (a neighbour table entry holds them all)."""
    out: dict[str, str] = {}
    for layout in layouts.values():
        out.update(layout)
    return out


# ---- memory ----

# The robot's state struct (`kb_state_t`, packed), less its variables and message
# values: kind, status, tick, moving, motion, motors, last_step, sent, sent_tick,
# message_t.
_FIXED_BYTES = 1 + 1 + 4 + 1 + 1 + 1 + 4 + 1 + 4 + 12
_ENTRY_BYTES = 1 + 2 + 1 + 4         # a neighbour: used, uid, dist, heard_at
STATE_BUDGET = 1536   # of the ATmega328P's 2048 bytes of RAM; the rest is kilolib's and the stack's


def _value_bytes(t: str) -> int:
    return 4 if t == NUM else 1        # a float, a uint8_t


def state_bytes(info, layouts: dict[str, dict[str, str]]) -> int:
    """The bytes of the robot's state struct as the exported C declares it (packed):
    `avr-size` shows it as the program's `bss`."""
    per_value = sum(_value_bytes(t) for t in _channels(layouts).values())
    variables = sum(_value_bytes(v.type) for k in info.kinds for v in k.vars.values())
    return _FIXED_BYTES + variables + per_value + TABLE * (_ENTRY_BYTES + per_value)


def _memory_refusals(info, layouts) -> list[Refusal]:
    """A state larger than the robot's RAM leaves for it, refused at the variable that
    takes it over the budget (or the message line, whose values the table holds 8 times)."""
    total = state_bytes(info, layouts)
    if total <= STATE_BUDGET:
        return []
    variables = [v for k in info.kinds for v in k.vars.values()]
    used = total - sum(_value_bytes(v.type) for v in variables)
    where = next(iter(_message_spans(info.kinds)), info.kinds[0].decl.name_span)
    for var in variables:
        used += _value_bytes(var.type)
        if used > STATE_BUDGET:
            where = var.decl.name_span
            break
    return [Refusal(f"a robot state of {total} bytes", where,
                    f"a Kilobot program keeps its state within {STATE_BUDGET} of the "
                    "ATmega328P's 2048 bytes of RAM (the rest is kilolib's and the stack's)")]


def _message_spans(kinds):
    """The spans of the kinds' `message` options."""
    return [o.span for k in kinds for o in k.decl.items_of(ast.Option) if o.name == "message"]


# ---- the C file ----

_PREAMBLE = """\
#if defined(__AVR__) || defined(KILOLIB_API)   /* the robot, or a harness of its API */
#define KB_KILOLIB 1
#endif
#ifdef KB_KILOLIB
#include "kilolib_api.h"
#else
#include <kilombo.h>
#include <jansson.h>
#endif
#include <math.h>
#include <stdint.h>

#define KB_TABLE {table}          /* neighbours remembered */
#define KB_STEP_TICKS {step}     /* kilo_ticks per program tick (0.1 s) */
#define KB_HEARD_TICKS {heard}   /* a neighbour unheard this long is forgotten */
#define KB_SEND_WINDOW {window}   /* program ticks a broadcast keeps being sent */

static inline float kb_mod(float a, float b) {{ return a - b * floorf(a / b); }}
static inline float kb_sign(float x) {{ return (float)((x > 0) - (x < 0)); }}
static inline float kb_clamp(float x, float lo, float hi) {{ return fminf(fmaxf(x, lo), hi); }}
static inline float kb_round(float x) {{   /* half to even, as the language rounds */
    float r = floorf(x + 0.5f);
    if (r - x == 0.5f && kb_mod(r, 2.0f) != 0.0f) r -= 1.0f;
    return r;
}}
static inline float kb_random(void) {{ return rand_soft() / 256.0f; }}
static inline float kb_uniform(float lo, float hi) {{ return lo + kb_random() * (hi - lo); }}
static inline uint8_t kb_chance(float p) {{ return kb_random() < p; }}
static inline uint8_t kb_channel(float c) {{   /* 0..1 -> kilolib's 0..3 */
    if (!(c > 0.0f)) return 0;
    if (c >= 1.0f) return 3;
    return (uint8_t)(c * 3.0f + 0.5f);
}}
static inline uint8_t kb_rgb(float r, float g, float b) {{
    return RGB(kb_channel(r), kb_channel(g), kb_channel(b));
}}
static inline void kb_pack(uint8_t *p, float v) {{   /* a number: a rounded int16 */
    int16_t w = v >= 32767.0f ? 32767 : v <= -32768.0f ? -32768 : (int16_t)lroundf(v);
    p[0] = (uint8_t)(w & 0xFF);
    p[1] = (uint8_t)(((uint16_t)w >> 8) & 0xFF);
}}
static inline float kb_unpack(const uint8_t *p) {{
    return (float)(int16_t)((uint16_t)p[0] | ((uint16_t)p[1] << 8));
}}
"""


def _source(info, layouts, functions: str, inits: dict[int, list[str]], placed) -> str:
    kinds = info.kinds
    span = kinds[0].decl.name_span
    heard = bool(info.extra.get("heard"))
    channels = _channels(layouts)
    values = [(ident(n, span), "float" if t == NUM else "uint8_t") for n, t in channels.items()]
    fields = "".join(f"    {c} m_{n};\n" for n, c in values)
    out_fields = "".join(f"    {c} out_{n};\n" for n, c in values)
    var_fields = "".join(
        f"    {'float' if v.type == NUM else 'uint8_t'} v{k.index}_{ident(v.name, span)};\n"
        for k in kinds for v in k.vars.values())
    enum = ", ".join(f"ST_{ident(s, span)} = {i}" for i, s in enumerate(info.status_names))
    names = ", ".join(f"`{ident(k.name, span)}`" for k in kinds)
    steps = "".join(
        f"    case {k.index}:\n        switch (mydata->status) {{\n"
        + "".join(f"        case ST_{s}: kb_k{k.index}_{s}(); break;\n" for s in k.statuses)
        + "        }\n        break;\n" for k in kinds)
    starts = "".join(
        f"    case {k.index}:\n        mydata->status = ST_{k.statuses[0]};\n"
        + "".join(inits[k.index]) + "        break;\n" for k in kinds)
    parts = [f"/* {program_name(info.filename)}.c: agent kind{'s' * (len(kinds) > 1)} {names}, "
             "exported by swarmdsl for the Kilobot (kilolib). */\n",
             _PREAMBLE.format(table=TABLE, step=STEP_TICKS, heard=HEARD_TICKS,
                              window=SEND_WINDOW),
             f"\nenum {{ {enum} }};\n\n",
             "typedef struct {\n    uint8_t used;\n    uint16_t uid;\n    uint8_t dist;   "
             "/* estimate_distance, mm */\n    uint32_t heard_at;\n" + fields +
             "} kb_neighbor_t;\n\n",
             "typedef struct {\n    uint8_t kind;\n    uint8_t status;\n    uint32_t tick;\n"
             "    uint8_t moving;   /* the commanded velocity is not (0, 0) */\n"
             "    uint8_t motion;   /* this tick's KB_STOP, KB_STRAIGHT, KB_LEFT, KB_RIGHT */\n"
             "    uint8_t motors;   /* the motion the motors run */\n"
             "    uint32_t last_step;\n    uint8_t sent;\n    uint32_t sent_tick;\n"
             "    message_t msg;\n" + var_fields + out_fields +
             "    kb_neighbor_t table[KB_TABLE];\n} kb_state_t;\n\n",
             "#ifdef KB_KILOLIB\nstatic kb_state_t kb_state;\n"
             "static kb_state_t *const mydata = &kb_state;\n#else\n"
             "REGISTER_USERDATA(kb_state_t)\n#endif\n\n",
             _MOTION, _per_robot("kb_moving_at_start", [int(m) for _p, _d, m, _k in placed]),
             _per_robot("kb_kind_of_robot", [k for _p, _d, _m, k in placed]),
             functions, "\n",
             _messages(info, layouts, heard),
             "\nvoid setup(void)\n{\n"
             "    mydata->kind = kb_kind_of_robot();\n    mydata->tick = 0;\n"
             "    mydata->last_step = kilo_ticks;\n    mydata->sent = 0;\n"
             "    for (uint8_t i = 0; i < KB_TABLE; i++) mydata->table[i].used = 0;\n"
             "    mydata->moving = kb_moving_at_start();\n    mydata->motors = KB_STOP;\n"
             + "".join(f"    mydata->out_{n} = 0;\n" for n, _ in values) +
             "    switch (mydata->kind) {\n" + starts + "    }\n"
             "    set_motors(0, 0);\n}\n\n",
             "void loop(void)\n{\n"
             "    if ((uint32_t)(kilo_ticks - mydata->last_step) < KB_STEP_TICKS) return;\n"
             "    mydata->last_step += KB_STEP_TICKS;\n",
             "    kb_forget();\n" if heard else "",
             "    mydata->motion = mydata->moving ? KB_STRAIGHT : KB_STOP;\n"
             "    switch (mydata->kind) {\n" + steps + "    }\n"
             "    if (!mydata->moving) mydata->motion = KB_STOP;\n"
             "    kb_motors(mydata->motion);\n    mydata->tick++;\n}\n\n",
             _json_state(info, span),
             "int main(void)\n{\n    kilo_init();\n",
             "    kilo_message_rx = kb_message_rx;\n" if heard else "",
             "    kilo_message_tx = kb_message_tx;\n" if channels else "",
             "    kilo_start(setup, loop);\n#ifndef KB_KILOLIB\n"
             "    SET_CALLBACK(json_state, kb_json_state);\n    SET_CALLBACK(reset, setup);\n"
             "#endif\n    return 0;\n}\n"]
    return "".join(parts)


_MOTION = """\
enum { KB_STOP, KB_STRAIGHT, KB_LEFT, KB_RIGHT };

/* A turn relative to the robot's own motion: left for a positive angle, right for a
 * negative one, straight for 0 (the angle's size is the robot's calibrated turn). */
static inline void kb_turn(float angle)
{
    if (!mydata->moving) return;
    mydata->motion = angle > 0 ? KB_LEFT : angle < 0 ? KB_RIGHT : KB_STRAIGHT;
}

/* The motors for a motion, with kilolib's calibrated duty cycles; a start from rest
 * spins the motors up first, as kilolib asks. */
static void kb_motors(uint8_t motion)
{
    if (motion == mydata->motors) return;
    if (mydata->motors == KB_STOP && motion != KB_STOP) spinup_motors();
    mydata->motors = motion;
    switch (motion) {
    case KB_STRAIGHT: set_motors(kilo_straight_left, kilo_straight_right); break;
    case KB_LEFT: set_motors(kilo_turn_left, 0); break;
    case KB_RIGHT: set_motors(0, kilo_turn_right); break;
    default: set_motors(0, 0);
    }
}

"""


def _per_robot(function: str, values: list[int]) -> str:
    """A function of the robot's id giving its entry of `values` (0 beyond them): which
    robots start moving and each robot's kind, the experimenter's set-up as `swarmdsl
    run` places them."""
    if not any(values):
        return f"static uint8_t {function}(void) {{ return 0; }}\n\n"
    rows = ", ".join(str(v) for v in values)
    return (f"static uint8_t {function}(void)\n{{\n"
            f"    static const uint8_t of[{len(values)}] = {{ {rows} }};\n"
            f"    return kilo_uid < {len(values)} ? of[kilo_uid] : 0;\n}}\n\n")


def _messages(info, layouts, heard: bool) -> str:
    """The transmit callback (pack the latest broadcast values of the robot's kind),
    the receive callback (a table entry per sender, oldest replaced; values the sender's
    kind does not send read 0) and the table's ageing."""
    if not _channels(layouts):
        return ""
    header = _header_bytes(info)
    several = len(info.kinds) > 1
    pack, unpack = [], []
    for kind in info.kinds:
        offset = header
        packs, unpacks = [], []
        for name, t in layouts[kind.name].items():
            if t == NUM:
                packs.append(f"        kb_pack(&mydata->msg.data[{offset}], mydata->out_{name});\n")
                unpacks.append(f"        e->m_{name} = kb_unpack(&m->data[{offset}]);\n")
                offset += 2
            else:
                packs.append(f"        mydata->msg.data[{offset}] = mydata->out_{name} ? 1 : 0;\n")
                unpacks.append(f"        e->m_{name} = m->data[{offset}] ? 1 : 0;\n")
                offset += 1
        pack.append(f"    case {kind.index}:\n" + "".join(packs) + "        break;\n")
        unpack.append(f"    case {kind.index}:\n" + "".join(unpacks) + "        break;\n")
    sender = ("    mydata->msg.data[0] = (uint8_t)(kilo_uid & 0xFF);\n"
              "    mydata->msg.data[1] = (uint8_t)(kilo_uid >> 8);\n") if heard else ""
    if heard and several:
        sender += "    mydata->msg.data[2] = mydata->kind;\n"
    tx = ("static message_t *kb_message_tx(void)\n{\n"
          "    if (!mydata->sent || mydata->tick - mydata->sent_tick > KB_SEND_WINDOW) "
          "return 0;\n"
          "    for (uint8_t i = 0; i < 9; i++) mydata->msg.data[i] = 0;\n"
          "    mydata->msg.type = NORMAL;\n" + sender +
          "    switch (mydata->kind) {\n" + "".join(pack) + "    }\n"
          "    mydata->msg.crc = message_crc(&mydata->msg);\n    return &mydata->msg;\n}\n")
    if not heard:
        return tx
    clear = "".join(f"    e->m_{n} = 0;\n" for n in _channels(layouts))
    rx = ("\nstatic void kb_message_rx(message_t *m, distance_measurement_t *d)\n{\n"
          "    if (m->type != NORMAL) return;\n"
          "    uint16_t uid = (uint16_t)m->data[0] | ((uint16_t)m->data[1] << 8);\n"
          "    kb_neighbor_t *e = 0;\n"
          "    for (uint8_t i = 0; i < KB_TABLE; i++) {   /* its entry, a free one, "
          "or the oldest */\n"
          "        kb_neighbor_t *c = &mydata->table[i];\n"
          "        if (c->used && c->uid == uid) { e = c; break; }\n"
          "        if (!e || (e->used && (!c->used || c->heard_at < e->heard_at))) e = c;\n"
          "    }\n"
          "    e->used = 1;\n    e->uid = uid;\n    e->dist = estimate_distance(d);\n"
          "    e->heard_at = kilo_ticks;\n" + clear +
          f"    switch ({'m->data[2]' if several else '0'}) {{\n" + "".join(unpack) +
          "    }\n}\n\n"
          "static void kb_forget(void)\n{\n"
          "    for (uint8_t i = 0; i < KB_TABLE; i++)\n"
          "        if (mydata->table[i].used &&\n"
          "            kilo_ticks - mydata->table[i].heard_at > KB_HEARD_TICKS)\n"
          "            mydata->table[i].used = 0;\n}\n")
    return tx + rx


def _json_state(info, span) -> str:
    """Kilombo's per-robot state (its state file): kind, status name, tick, variables."""
    names = ", ".join(f'"{ident(s, span)}"' for s in info.status_names)
    kinds = ", ".join(f'"{ident(k.name, span)}"' for k in info.kinds)
    sets = "".join(
        f"    case {k.index}:\n" + "".join(
            f'        json_object_set_new(s, "{ident(v.name, span)}", '
            f"json_real(mydata->v{k.index}_{ident(v.name, span)}));\n"
            for v in k.vars.values()) + "        break;\n" for k in info.kinds)
    return ("#ifndef KB_KILOLIB\n"
            f"static const char *const kb_status_names[] = {{ {names} }};\n"
            f"static const char *const kb_kind_names[] = {{ {kinds} }};\n"
            "json_t *kb_json_state(void)\n{\n    json_t *s = json_object();\n"
            '    json_object_set_new(s, "kind", json_string(kb_kind_names[mydata->kind]));\n'
            '    json_object_set_new(s, "status", '
            "json_string(kb_status_names[mydata->status]));\n"
            '    json_object_set_new(s, "tick", json_integer(mydata->tick));\n'
            "    switch (mydata->kind) {\n" + sets + "    }\n    return s;\n}\n#endif\n\n")


# ---- Makefile and Kilombo's files ----

_MAKEFILE = """\
# Build {name}.c, exported by swarmdsl for the Kilobot.
#   make kilombo KILOMBO=PREFIX     headless Kilombo (PREFIX/include/kilombo.h,
#                                   PREFIX/lib/libheadless.a), then: make run
#   make hex KILOLIB=.../kilolib.a  the real robot's program ({name}.hex)
#   make size                       flash and RAM of the program on the ATmega328P
#                                   (kilolib's own code not counted)
KILOMBO ?= /usr/local
KILOLIB ?=
AVR_CFLAGS = -mmcu=atmega328p -Os -std=gnu99 -DF_CPU=8000000 -Wall \\
	-funsigned-char -funsigned-bitfields -fpack-struct -fshort-enums

kilombo: {name}
{name}: {name}.c
	gcc -std=gnu99 -O2 -Wall -fcommon -I$(KILOMBO)/include $< \\
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
        "botName": program_name(program.info.filename), "randSeed": seed,
        "nBots": len(bots), "formation": "random", "timeStep": KILOMBO_STEP,
        "simulationTime": program.info.world.steps * TICK_SECONDS,
        "commsRadius": round(profile_of(program.info, kind).range),
        "distributePercent": 0.8, "displayWidth": 800, "displayHeight": 600,
        "stateFileName": "states.json", "stateFileSteps": round(1 / KILOMBO_STEP),
        "storeHistory": 0, "GUI": 0,
    }
    return {"kilombo.json": json.dumps(params, indent=2) + "\n",
            "bots.json": json.dumps({"bot_states": bots, "ticks": 0}, indent=2) + "\n"}
