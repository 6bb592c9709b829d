"""Action statements `name(args)`: effects that are not assignments (deposit, remember,
broadcast, ...). Each action is one entry: a checker rule and a codegen rule."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class ActionSpec:
    """`check(checker, stmt, scope, kind)` reports misuse; `compile(codegen, stmt, kind)`
    returns a closure `run(frame)` that applies the effect for `frame.active` agents."""

    name: str
    check: Callable
    compile: Callable
    doc: str


ACTIONS: dict[str, ActionSpec] = {}


def register(spec: ActionSpec) -> ActionSpec:
    ACTIONS[spec.name] = spec
    return spec
