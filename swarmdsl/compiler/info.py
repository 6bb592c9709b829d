"""What the checker learns about a program: resolved params, world settings, agent
kinds, and per-expression types and name resolutions that codegen relies on (those in
one side table, `facts.Facts`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import BOOL, CONSTANTS, KIND, NUM, STATUS, VEC
from swarmdsl.compiler.facts import Facts

# Per-agent state every kind has. name -> (type, assignable, column)
AGENT_STATE = {
    "pos": (VEC, False, "pos"),
    "velocity": (VEC, True, "vel"),
    "vel": (VEC, True, "vel"),
    "heading": (NUM, False, "heading"),
    "speed": (NUM, False, "speed"),
    "id": (NUM, False, "id"),
    "index": (NUM, False, "index"),
    "status": (STATUS, False, "status"),
    "kind": (KIND, False, "kind"),
    "sense": (NUM, False, "sense"),
    "max_speed": (NUM, False, "max_speed"),
}
# Names readable everywhere in agent code that are not per agent.
GLOBAL_STATE = {"tick": NUM}
PAIR_NAMES = {"dist": NUM}
# Every name that means something in agent code without being declared: no declaration
# may take one, as it would hide the built-in (or be hidden by it). Extensions add theirs
# (`believed`, `msg`).
BUILTIN_NAMES = {*AGENT_STATE, *GLOBAL_STATE, *PAIR_NAMES, "other", *CONSTANTS}
EDGE_MODES = ("wall", "wrap", "repel")


@dataclass
class WorldInfo:
    width: float = 100.0
    height: float = 100.0
    grid: float = 10.0
    edges: str = "wall"
    edge_weight: float = 1.0
    edge_range: float | None = None   # None: two grid spacings
    steps: int = 1000


@dataclass
class VarInfo:
    name: str
    type: str
    decl: ast.VarDecl | ast.AttrDecl
    assignable: bool


@dataclass
class KindInfo:
    name: str
    index: int
    decl: ast.AgentDecl
    count: int = 0
    options: dict[str, ast.Option] = field(default_factory=dict)
    vars: dict[str, VarInfo] = field(default_factory=dict)       # vars and attrs, in order
    statuses: list[str] = field(default_factory=list)
    status_decls: dict[str, ast.StatusDecl] = field(default_factory=dict)
    sense: float | None = None       # constant sense radius, when known
    robot: str = "generic"
    uses_neighbors: bool = False
    neighbor_calls: list = field(default_factory=list)   # (call node, constant radius|None)


@dataclass
class ProgramInfo:
    """The checked program. What the checker learned per node is in `facts`
    (`facts.type_of(node)`, `facts.name_of(node)`)."""

    tree: ast.Program
    filename: str
    params: dict[str, object]
    param_decls: dict[str, ast.ParamDecl]
    world: WorldInfo
    kinds: list[KindInfo]
    status_names: list[str]                  # distinct status names across kinds
    facts: Facts = field(default_factory=Facts)
    warnings: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)       # what extension hooks learned



    def kind(self, name: str) -> KindInfo | None:
        return next((k for k in self.kinds if k.name == name), None)

    def status_name_id(self, name: str) -> int:
        return self.status_names.index(name)

    def var_types(self) -> dict[str, str]:
        """Every declared per-agent variable across kinds -> its type."""
        out: dict[str, str] = {}
        for k in self.kinds:
            for v in k.vars.values():
                out.setdefault(v.name, v.type)
        return out


VALUE_DEFAULT = {NUM: 0.0, BOOL: False, VEC: (0.0, 0.0)}
