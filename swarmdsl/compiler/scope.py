"""`Scope`: where the checker evaluates an expression. Its own module because the type
rules and the language extensions build scopes too, and the checker imports them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from swarmdsl.compiler.info import KindInfo


@dataclass
class Scope:
    """Where an expression is evaluated: which kind, which lets, pair or agent frame."""

    kind: KindInfo | None
    locals: dict[str, str] = field(default_factory=dict)
    pair: bool = False
    init: bool = False        # while agents are being placed: no neighbours, no lets
    used: set = field(default_factory=set)
    later: dict = field(default_factory=dict)   # name -> a `let` further down the body
