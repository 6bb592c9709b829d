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

A layout is checked here, whoever hands it in, so the API and `--example` refuse the
same mistakes in the same words: its shape when it is built (`Layout`, `from_json`),
its fit to a program before a `Simulation` places it (`check_fit`). An agent of a kind
the program lacks, say, would otherwise just not be placed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.errors import SwarmOptionError
from swarmdsl.ops.types import BOOL, NUM, VEC
from swarmdsl.runtime.json_checks import (MAX_WHOLE, Refuse, is_bool, known_keys, number,
                                          shown, whole)

_LAYOUT_ENTRIES = ("kinds", "agents")
_AGENT_ENTRIES = ("kind", "id", "index", "pos", "vars")


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
        # plain ints: numpy ids are accepted, and json.dumps refuses np.int64
        out: dict = {"kind": str(self.kind), "id": int(self.id)}
        if self.index is not None:
            out["index"] = int(self.index)
        if self.pos is not None:
            out["pos"] = [float(self.pos[0]), float(self.pos[1])]
        if self.values:
            out["vars"] = {k: _json_value(v) for k, v in self.values}
        return out


def _json_value(v):
    if isinstance(v, tuple | list | np.ndarray):
        return [float(x) for x in v]
    if is_bool(v):
        return bool(v)
    return float(v)


def value_type(value) -> str | None:
    """The variable type a layout's value can start (BOOL, NUM, VEC), None for no type:
    the one test of a value, so its shape and its fit to a variable never disagree."""
    if is_bool(value):
        return BOOL
    if number(value):
        return NUM
    if isinstance(value, np.ndarray) and value.ndim != 1:
        return None
    if isinstance(value, tuple | list | np.ndarray) and len(value) == 2 \
            and all(number(x) for x in value):
        return VEC
    return None


@dataclass(frozen=True)
class Layout:
    """Every agent at tick 0, of every kind that the layout covers (`kinds`).

    Built only well-formed (an option error naming the entry otherwise), so a layout
    drawn by `swarmdsl test`, read from JSON or written by hand holds the same rules."""

    agents: tuple[AgentSpec, ...]
    kinds: tuple[str, ...]

    def __post_init__(self):
        _check_shape(self, Refuse())

    def of(self, kind: str) -> list[AgentSpec]:
        return [a for a in self.agents if a.kind == kind]

    def counts(self) -> dict[str, int]:
        return {k: len(self.of(k)) for k in self.kinds}

    def to_json(self) -> dict:
        return {"kinds": list(self.kinds), "agents": [a.to_json() for a in self.agents]}

    @classmethod
    def from_json(cls, data, where: str | None = None) -> Layout:
        """A Layout from `to_json()`'s form; a malformed one is an option error naming
        the entry, after `where` (the file it came from, say) when given."""
        refuse = Refuse(where)
        if not isinstance(data, dict):
            refuse(f"layout must be an object with \"kinds\" and \"agents\", got "
                   f"{shown(data)}")
        known_keys(refuse, data, _LAYOUT_ENTRIES, "layout: ", "a layout has")
        kinds, agents = data.get("kinds"), data.get("agents")
        if isinstance(agents, list):
            agents = tuple(_agent_from_json(refuse, a, f"layout.agents[{i}]")
                           for i, a in enumerate(agents))
        try:        # the rules a Layout holds however it is built, located by `where`
            return cls(agents, tuple(kinds) if isinstance(kinds, list) else kinds)
        except SwarmOptionError as err:
            refuse(err.message)


def _agent_from_json(refuse: Refuse, a, at: str) -> AgentSpec:
    """The entries JSON spells its own way (objects, lists); their values are the
    Layout's to check."""
    if not isinstance(a, dict):
        refuse(f"{at} must be an object, got {shown(a)}")
    known_keys(refuse, a, _AGENT_ENTRIES, f"{at}: ", "an agent has")
    for key in ("kind", "id"):
        if key not in a:
            refuse(f"{at}: no \"{key}\" entry")
    values = a.get("vars")
    if values is not None and not isinstance(values, dict):
        refuse(f"{at}: \"vars\" must be an object of name: value, got {shown(values)}")
    return AgentSpec(a["kind"], a["id"], _tupled(a.get("pos")),
                     tuple((k, _tupled(v)) for k, v in (values or {}).items()),
                     a.get("index"))


def _tupled(value):
    return tuple(value) if isinstance(value, list) else value


def _check_shape(layout: Layout, refuse: Refuse) -> None:
    """What any layout must be, whatever program it is for."""
    kinds = layout.kinds
    if not isinstance(kinds, tuple | list) or not all(isinstance(k, str) for k in kinds):
        refuse(f"layout.kinds must be a list of kind names, got {shown(kinds)}")
    if len(set(kinds)) != len(kinds):
        refuse(f"layout.kinds lists a kind twice: {shown(kinds)}")
    if not isinstance(layout.agents, tuple | list):
        refuse(f"layout.agents must be a list of agents, got {shown(layout.agents)}")
    ids: dict[int, int] = {}
    indexes: dict[tuple[str, int], int] = {}
    for i, a in enumerate(layout.agents):
        at = f"layout.agents[{i}]"
        if not isinstance(a, AgentSpec):
            refuse(f"{at} must be an AgentSpec, got {shown(a)}")
        _check_agent(refuse, a, at, kinds)
        if a.id in ids:
            refuse(f"{at}: id {a.id} is also layout.agents[{ids[a.id]}]'s; agent ids "
                   "must be distinct")
        ids[a.id] = i
        if a.index is not None and (a.kind, a.index) in indexes:
            refuse(f"{at}: index {a.index} is also "
                   f"layout.agents[{indexes[a.kind, a.index]}]'s")
        if a.index is not None:
            indexes[a.kind, a.index] = i


def _check_agent(refuse: Refuse, a: AgentSpec, at: str, kinds) -> None:
    if not isinstance(a.kind, str):
        refuse(f"{at}: \"kind\" must be a kind name, got {shown(a.kind)}")
    if a.kind not in kinds:
        refuse(f"{at}: kind \"{a.kind}\" is not in layout.kinds ({', '.join(kinds)})")
    whole(refuse, a.id, f"{at}: \"id\"", 0, MAX_WHOLE)
    if a.index is not None:
        whole(refuse, a.index, f"{at}: \"index\"", 0, MAX_WHOLE)
    if a.pos is not None and value_type(a.pos) != VEC:
        refuse(f"{at}: \"pos\" must be two finite numbers [x, y], got {shown(a.pos)}")
    if not isinstance(a.values, tuple | list):
        refuse(f"{at}: \"vars\" must be (name, value) pairs, got {shown(a.values)}")
    for pair in a.values:
        if not (isinstance(pair, tuple | list) and len(pair) == 2
                and isinstance(pair[0], str)):
            refuse(f"{at}: \"vars\" must be (name, value) pairs, got {shown(pair)}")
        name, v = pair
        if value_type(v) is None:
            refuse(f"{at}: variable {name}: {shown(v)} is not a value (a finite number, "
                   "true or false, or [x, y])")


def check_fit(layout, program, where: str | None = None, hint: str | None = None) -> None:
    """Whether `layout` fits `program`: every kind one of its kinds, at most its count of
    agents, each index below the count, each position inside the world, each variable
    one the kind declares with a value of its type. A `Simulation` checks this before
    placing anyone, so a misfit is an option error naming the entry (after `where`),
    not an agent quietly left out."""
    refuse = Refuse(where, hint)
    if not isinstance(layout, Layout):
        refuse(f"the layout must be a swarmdsl Layout (Layout.from_json reads one), got "
               f"{type(layout).__name__}")
    kinds = {k.name: k for k in program.kinds}
    for name in layout.kinds:
        if name not in kinds:
            refuse(f"layout.kinds: no agent kind \"{name}\" in {program.filename} (kinds: "
                   f"{', '.join(kinds) or 'none'})")
    for i, a in enumerate(layout.agents):
        _check_agent_fit(refuse, a, f"layout.agents[{i}] (id {a.id}, {a.kind})",
                         kinds[a.kind], program.world)
    for name in layout.kinds:
        n, count = len(layout.of(name)), kinds[name].count
        if n > count:
            refuse(f"layout: {n} agents of `{name}`, the program places at most {count}")
    _check_ids_apart(refuse, layout, program)


def _check_ids_apart(refuse: Refuse, layout: Layout, program) -> None:
    """A kind the layout leaves out is placed by the program with its rows as ids; an
    agent of the layout with one of those ids would share its random draws."""
    placed, start = {}, 0
    for kind in program.kinds:
        n = place_count(layout, kind)
        if kind.name not in layout.kinds and n:
            placed[kind.name] = range(start, start + n)
        start += n
    for i, a in enumerate(layout.agents):
        for name, ids in placed.items():
            if int(a.id) in ids:
                refuse(f"layout.agents[{i}] (id {a.id}, {a.kind}): id {a.id} is also an "
                       f"agent of `{name}`'s, which the layout leaves to the program (ids "
                       f"{ids.start} to {ids.stop - 1}); agent ids must be distinct")


def _check_agent_fit(refuse: Refuse, a: AgentSpec, at: str, kind, world) -> None:
    if a.index is not None and a.index >= kind.count:
        refuse(f"{at}: index {a.index} is not below the count of `{a.kind}`, {kind.count}")
    if a.pos is not None and not (0 <= a.pos[0] <= world.width
                                  and 0 <= a.pos[1] <= world.height):
        refuse(f"{at}: pos [{a.pos[0]:g}, {a.pos[1]:g}] is outside the world "
               f"({world.width:g} x {world.height:g})")
    declared = {name: t for name, t, _init in kind.vars}
    for name, value in a.values:
        if name not in declared:
            refuse(f"{at}: \"{name}\" is not a variable of `{a.kind}` (its variables: "
                   f"{', '.join(declared) or 'none'})")
        if value_type(value) != declared[name]:
            refuse(f"{at}: variable {name} is a {declared[name]}, not "
                   f"{shown(_json_value(value))}")


def place_count(layout: Layout | None, kind) -> int:
    """How many agents of `kind` start: the layout's (`check_fit` keeps them within the
    program's count), or the program's count."""
    if layout is None or kind.name not in layout.kinds:
        return kind.count
    return len(layout.of(kind.name))


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
            cols[name][row] = value
