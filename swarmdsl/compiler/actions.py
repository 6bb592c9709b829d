"""Action statements `name(args)`: effects that are not assignments (deposit, remember,
broadcast, ...). Each action is one row, registered by the module that adds it: its
checker rule, its codegen rule and what every other target does with it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from swarmdsl.ops.targets import Refused


@dataclass(frozen=True)
class ActionSpec:
    """`check(checker, stmt, scope, kind)` reports misuse; `compile(codegen, stmt, kind)`
    returns a closure `run(frame)` that applies the effect for `frame.active` agents
    (the numpy reference; the numba backend runs the same closure inside its fused
    status when it has no statement kernel for it).

    `batch`: whether R replicas in one store run the effect bit-identical to their solo
    runs (`compiler/batching.py`): an effect on agent columns or on each replica's own
    grid is; a `Refused` sends the program solo. `kilobot`: True when the exporter
    writes its C (`export/kilobot_c.py` `KindC.action`: an effect on the robot's own
    state, motors, LED or outgoing message), else a `Refused` saying why a Kilobot
    cannot run it (the located error's hint). Both are keywords without a default on
    purpose: a new action says what each target does (`tests/test_rows_complete.py`)."""

    name: str
    check: Callable
    compile: Callable
    doc: str
    batch: bool | Refused | None = None
    kilobot: bool | Refused | None = None


ACTIONS: dict[str, ActionSpec] = {}


def register(spec: ActionSpec) -> ActionSpec:
    ACTIONS[spec.name] = spec
    return spec
