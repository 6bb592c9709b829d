"""A Kilobot program's RAM: what the exporter counts against the ATmega328P's 2048
bytes before it writes any C, refusing, located, what would not fit.

Three things share the RAM: the program's globals (the robot's state struct, its
`bss` byte for byte, and the per-robot tables, `.data`), kilolib's own globals, and the
stack at its deepest: main, kilo_start, loop and the status function's frames, the
status's locals (its `let`s, each aggregate's accumulators, a trilateration's table
of references, a network call's inputs), the deepest function it calls (a network's
activations, two floats a unit of its widest layer; trilateration's search and
solve), and on top of that an interrupt (kilolib's receive interrupt calling the
program's `kb_message_rx`). The state alone is kept within STATE_BUDGET (refused at the
variable that takes it over); the whole within the 2048 bytes (refused at the status,
or the network call, of the deepest chain).

The frame sizes are upper estimates for avr-gcc `-Os` (a return address and the
call-saved registers a function may push); `tests/test_export_kilobot_memory.py` holds
them above what avr-gcc's `-fstack-usage` reports for the shipped programs.
"""

from __future__ import annotations

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import NUM, SET, VEC
from swarmdsl.export.kilobot_c import FIX, Refusal

RAM = 2048                # the ATmega328P's
STATE_BUDGET = 1536       # of it, the program's state at most; the rest kilolib's and the stack's
KILOLIB_RAM = 128         # kilolib's own globals: about 50 in kilolib.c, with a margin
TABLE = 8                 # neighbours remembered (the exporter's KB_TABLE)
FRAME = 20                # a call: return address and the call-saved registers pushed
INTERRUPT = 35 + FRAME + 16   # an interrupt's saved registers and SREG, then kb_message_rx
_BASE = 4 * FRAME + 16    # main, kilo_start, loop, kb_step_status frames and their locals
_STEERING = 176           # a program with beliefs: odometry and steering, inlined in loop()
_TRILATERATE = FRAME + 32 + FRAME + 48   # kb_trilaterate's search, then kb_solve3
_SOLVE = FRAME + 48
_AGGREGATE = 16           # an aggregate's accumulator, count and nearest's best

# The robot's state struct (`kb_state_t`, packed), less its variables and message
# values: kind, status, tick, moving, motion, motors, last_step, sent, sent_tick,
# started, rng, the two messages the transmit interrupt is handed in turn, tx_front, tx_on.
_FIXED_BYTES = 1 + 1 + 4 + 1 + 1 + 1 + 4 + 1 + 4 + 1 + 4 + 2 * 12 + 1 + 1
# With beliefs: vel, believed, located, body, goal, head, moved_at.
_STEER_BYTES = 8 + 8 + 1 + 8 + 8 + 4 + 4
_ENTRY_BYTES = 1 + 2 + 1 + 4         # a neighbour: used, uid, dist, heard_at
_LOCAL_BYTES = {NUM: 4, VEC: 8, FIX: 9}


def channels(layouts: dict[str, dict[str, str]]) -> dict[str, str]:
    """Every message value of every kind (a neighbour table entry holds them all)."""
    out: dict[str, str] = {}
    for layout in layouts.values():
        out.update(layout)
    return out


def _value_bytes(t: str) -> int:
    return {NUM: 4, VEC: 8}.get(t, 1)        # a float, two floats, a uint8_t


def state_bytes(info, layouts: dict[str, dict[str, str]]) -> int:
    """The bytes of the robot's state struct as the exported C declares it (packed):
    `avr-size` shows it as the program's `bss`."""
    per_value = sum(_value_bytes(t) for t in channels(layouts).values())
    variables = sum(_value_bytes(v.type) for k in info.kinds for v in k.vars.values())
    steer = _STEER_BYTES if info.extra.get("beliefs") else 0
    return (_FIXED_BYTES + steer + variables + per_value
            + TABLE * (_ENTRY_BYTES + per_value))


def state_refusals(info, layouts) -> list[Refusal]:
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


def status_stack(info, decl, networks: dict) -> tuple[int, object, str]:
    """The stack a status takes beyond loop()'s frames: its frame and locals and its
    deepest call; with the span to blame and what that call is. `networks`: each model
    path's activation bytes."""
    local, deepest, where, what = FRAME, 0, decl.name_span, ""
    for node in ast.walk(decl):
        if isinstance(node, ast.LetStmt):
            local += _LOCAL_BYTES.get(info.facts.type_of(node.value, NUM), 1) \
                if info.facts.type_of(node.value) != SET else 0
        elif isinstance(node, ast.Call):
            res = info.facts.name_of(node, ("",))
            call, callee, name = 0, 0, ""
            if res[0] == "agg":
                call = _AGGREGATE
            elif res[0] == "trilaterate" and res[1] == "three":
                call, callee, name = 9, _SOLVE, f"trilateration {_SOLVE}"
            elif res[0] == "trilaterate":
                call, callee = TABLE * 12 + 9 + _AGGREGATE, _TRILATERATE
                name = f"trilateration {_TRILATERATE}"
            elif res[0] == "nn":
                inputs = sum(2 if info.facts.type_of(a) == VEC else 1 for a in node.args[1:])
                call = 4 * inputs + 8
                callee = FRAME + networks.get(res[1], 0)
                name = f"the network `{getattr(res[1], 'name', res[1])}` {callee}"
            local += call
            if callee > deepest:
                deepest, where, what = callee, node.span, name
    return local + deepest, where, what


def base(info) -> int:
    """The stack under a status: main, kilo_start, loop (with steering's locals in a
    program with beliefs) and kb_step_status."""
    return _BASE + (_STEERING if info.extra.get("beliefs") else 0)


def ram_refusals(info, layouts, networks: dict, tables: int) -> list[Refusal]:
    """The program's RAM at its deepest beyond the ATmega328P's 2048 bytes, refused at
    the status (or its call) of the deepest chain."""
    globals_ = state_bytes(info, layouts) + tables
    worst, where, what = 0, info.kinds[0].decl.name_span, ""
    for kind in info.kinds:
        for decl in kind.status_decls.values():
            stack, span, name = status_stack(info, decl, networks)
            if stack > worst:
                worst, where = stack, span
                what = f"status `{decl.name}` {stack}" + (f" (calling {name})" if name else "")
    stack = base(info) + worst + INTERRUPT
    total = globals_ + KILOLIB_RAM + stack
    if total <= RAM:
        return []
    return [Refusal(
        f"a robot needing {total} bytes of RAM (state and tables {globals_}, kilolib's "
        f"{KILOLIB_RAM}, the stack at its deepest {stack}, of which {what})",
        where, f"the ATmega328P has {RAM} bytes of RAM; a network takes two floats a "
        "unit of its widest layer on the stack: make it narrower")]
