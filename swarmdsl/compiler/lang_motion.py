"""Robot-relative motion: `stop()`, `forward(SPEED)`, `turn_left(RATE)`,
`turn_right(RATE)`, the motions a robot without a compass commands (a Kilobot's
`set_motors`), for every robot profile.

They move an agent relative to its own heading, which a stopped agent keeps, so a
robot can stop and go again (the zero velocity rotated stays zero: `rotate(velocity,
A)` cannot restart it). A turn is the Kilobot's: one motor running, the body pivoting
about a rear leg half a body from its centre, so its centre goes round a circle of
that radius; each tick the heading turns by RATE and the centre moves `body / 2 *
RATE` along the new heading. Each action sets `velocity` for the tick it runs in, as
an assignment does; a robot profile's noise and speed limit apply as to any velocity.
"""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler import actions
from swarmdsl.compiler.builtins import NUM, TYPE_TEXT
from swarmdsl.compiler.codegen import broadcast
from swarmdsl.compiler.lang_robots import profile_of

MOTIONS = {"stop": 0, "forward": 1, "turn_left": 1, "turn_right": 1}   # name -> arguments
_USAGE = {"stop": "`stop()`", "forward": "`forward(SPEED)`, SPEED in units a tick",
          "turn_left": "`turn_left(RATE)`, RATE in radians a tick",
          "turn_right": "`turn_right(RATE)`, RATE in radians a tick"}


def _check(chk, st, scope, kind) -> None:
    want = MOTIONS[st.name]
    if len(st.args) != want:
        for a in st.args:
            chk.expr(a, scope)
        chk.fail(f"`{st.name}` takes {want or 'no'} argument{'s' * (want != 1)}: "
                 f"{_USAGE[st.name]}", st.span)
        return
    for a in st.args:
        t = chk.expr(a, scope)
        if t not in (NUM, "error"):
            chk.fail(f"the argument of `{st.name}` must be a number, got "
                     f"{TYPE_TEXT.get(t, t)}", a.span)
    chk.extra["motion_actions"] = True


def _compile(gen, st, kind):
    name = st.name
    value = gen.expr(st.args[0]) if st.args else None
    pivot = profile_of(gen.info, kind).body / 2
    turn = {"turn_left": 1.0, "turn_right": -1.0}.get(name, 0.0)

    def run(f):
        mask = f.active
        heading = f.state("heading")
        if value is None:
            vel = np.zeros((f.n, 2))
        else:
            amount = np.asarray(broadcast(value(f), f.n, NUM), dtype=float)
            if turn:
                heading = heading + turn * amount
                step = pivot * np.abs(amount)
            else:
                step = np.maximum(amount, 0.0)      # forward only: a Kilobot has no reverse
            vel = np.stack([np.cos(heading), np.sin(heading)], axis=1) * step[:, None]
        bad = mask & ~np.isfinite(vel).all(axis=1)
        if bad.any():
            from swarmdsl.errors import SwarmRuntimeError

            row = int(f.idx[np.flatnonzero(bad)[0]])
            raise SwarmRuntimeError(f"`{name}` of agent {row} is not a finite number",
                                    st.args[0].span)
        f.overlay["vel"] = np.where(mask[:, None], vel, f.state("vel"))
    return run


for _name in MOTIONS:
    actions.register(actions.ActionSpec(
        _name, _check, _compile,
        f"{_USAGE[_name]}: robot-relative motion for this tick (see language-robots.md)",
        batch=actions.Refused("robot-relative motion is not laid out per replica yet"),
        kilobot=True))
