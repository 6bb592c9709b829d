"""An explicit initial swarm: which agents exist (their ids), where, and with what values.

A `Layout` replaces part of a kind's placement: the kind starts with the listed agents
(at most its `count`), they get the listed ids (not 0..N-1) and, when given, their
`index` within the kind (a subset of a swarm keeps the indexes the agents have in the
whole swarm), and an agent with a position or variable values of its own starts with
them; everything else (velocity, heading, other variables, the initial status) comes
from the program as usual. Because every random draw is keyed by agent id (`randomness.py`), an
agent of a layout draws exactly what it would draw in the full swarm, so deleting one
agent from a layout leaves every other agent's draws unchanged. `swarmdsl test` draws
layouts as hypothesis data and shrinks them; `swarmdsl run --example` replays one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.compiler.errors import SwarmOptionError


@dataclass(frozen=True)
class AgentSpec:
    """One agent of a layout: its kind, id, and optional start position, variables and
    index within the kind (None: its row among the kind's agents)."""

    kind: str
    id: int
    pos: tuple[float, float] | None = None
    values: tuple[tuple[str, object], ...] = ()
    index: int | None = None

    def to_json(self) -> dict:
        out: dict = {"kind": self.kind, "id": self.id}
        if self.index is not None:
            out["index"] = self.index
        if self.pos is not None:
            out["pos"] = [float(self.pos[0]), float(self.pos[1])]
        if self.values:
            out["vars"] = {k: _json_value(v) for k, v in self.values}
        return out


def _json_value(v):
    if isinstance(v, tuple | list | np.ndarray):
        return [float(x) for x in v]
    if isinstance(v, bool | np.bool_):
        return bool(v)
    return float(v)


@dataclass(frozen=True)
class Layout:
    """Every agent at tick 0, of every kind that the layout covers (`kinds`)."""

    agents: tuple[AgentSpec, ...]
    kinds: tuple[str, ...]

    def of(self, kind: str) -> list[AgentSpec]:
        return [a for a in self.agents if a.kind == kind]

    def counts(self) -> dict[str, int]:
        return {k: len(self.of(k)) for k in self.kinds}

    def to_json(self) -> dict:
        return {"kinds": list(self.kinds), "agents": [a.to_json() for a in self.agents]}

    @classmethod
    def from_json(cls, data, where: str = "layout") -> Layout:
        """A Layout from `to_json()`'s form; a malformed one is an option error."""
        try:
            kinds = tuple(str(k) for k in data["kinds"])
            agents = []
            for a in data["agents"]:
                pos = a.get("pos")
                if pos is not None:
                    pos = (float(pos[0]), float(pos[1]))
                values = tuple((str(k), tuple(float(x) for x in v) if isinstance(v, list)
                                else v if isinstance(v, bool) else float(v))
                               for k, v in (a.get("vars") or {}).items())
                index = a.get("index")
                index = int(index) if index is not None else None
                agents.append(AgentSpec(str(a["kind"]), int(a["id"]), pos, values, index))
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
            raise SwarmOptionError(f"{where}: not a swarm layout ({exc!r})") from None
        ids = [a.id for a in agents]
        if len(set(ids)) != len(ids) or any(i < 0 for i in ids):
            raise SwarmOptionError(f"{where}: agent ids must be distinct and 0 or more")
        if any(a.index is not None and a.index < 0 for a in agents):
            raise SwarmOptionError(f"{where}: agent indexes must be 0 or more")
        return cls(tuple(agents), kinds)


def place_count(layout: Layout | None, kind) -> int:
    """How many agents of `kind` start: the layout's (at most the program's count), or
    the program's count."""
    if layout is None or kind.name not in layout.kinds:
        return kind.count
    n = len(layout.of(kind.name))
    if n > kind.count:
        raise SwarmOptionError(f"the layout has {n} agents of `{kind.name}`, the program "
                               f"places at most {kind.count}")
    return n


def place_ids(layout: Layout | None, kind, rows: np.ndarray) -> np.ndarray:
    """The ids of a kind's new agents: the layout's, or their rows."""
    if layout is None or kind.name not in layout.kinds:
        return rows
    return np.asarray([a.id for a in layout.of(kind.name)], dtype=np.int64)


def place_indexes(layout: Layout | None, kind, index: np.ndarray) -> np.ndarray:
    """The `index` of a kind's new agents: the layout's where it gives one, else their
    row among the kind's agents (`index`)."""
    if layout is None or kind.name not in layout.kinds:
        return index
    return np.asarray([i if a.index is None else a.index
                       for i, a in zip(index.tolist(), layout.of(kind.name), strict=True)],
                      dtype=np.int64)


def place_positions(layout: Layout | None, kind, pos: np.ndarray) -> np.ndarray:
    """`pos` ((n, 2), the program's placement) with the layout's own positions put in."""
    if layout is None or kind.name not in layout.kinds:
        return pos
    pos = np.array(pos, dtype=np.float64)
    for row, a in enumerate(layout.of(kind.name)):
        if a.pos is not None:
            pos[row] = a.pos
    return pos


def place_values(layout: Layout | None, kind, cols: dict, rows: np.ndarray) -> None:
    """Write the layout's variable values over the program's initial ones."""
    if layout is None or kind.name not in layout.kinds:
        return
    for row, a in zip(rows, layout.of(kind.name), strict=True):
        for name, value in a.values:
            if name not in cols:
                raise SwarmOptionError(f"the layout sets `{name}`, which `{kind.name}` "
                                       "does not declare")
            cols[name][row] = value
