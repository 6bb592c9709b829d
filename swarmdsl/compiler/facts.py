"""What the checker learned about each node: its type and what its name resolved to.

One home for the per-node facts every later walker reads (codegen, the backends'
planners, the property and metric rules, the language server): `Facts`, a typed side
table, written by the checker (and the extension rules it calls) and read by everyone
else through `type_of`/`name_of`.

Why a side table and not attributes on the nodes: the AST is a tree of frozen
dataclasses, and one parsed tree is checked more than once (a sweep checks it once per
`--set` value, the language server re-checks an unchanged tree, a named tree's body is
checked at each use), so what a check learned belongs to that check, not to the tree:
a resolution carries a param's value (`("const", 3)`), which differs between two checks
of the same nodes. A side table also keeps `ast.shape`, equality and the nodes' repr
as they were.

Why keyed by identity: two equal nodes (`x` at two places) can resolve differently (a
`let` in one status, a variable in another), so value equality is no key. Identity is
taken with `id()` *inside this module only*: the table holds each node it has a fact
about (`_nodes`), so no id is reused by another node while the table lives. A caller
passes the node, never its id.

A resolution is a tuple whose first item is its category: `("local", name)`,
`("var", name)`, `("state", column)`, `("const", value)`, `("status", name)`,
`("kind", index)`, `("global", name)`, `("pair", name)`, `("component", 0|1)`,
`("other_state", column)`, `("other_var", name)`, `("func", name)`,
`("agg", name)`, `("neighbors",)`, and an extension's own (`("field", name)`,
`("env_call", name)`, `("msg_value", name)`, ...: `codegen.NAME_CODEGEN` and
`CALL_CODEGEN` compile them).
"""

from __future__ import annotations

from swarmdsl.compiler import ast


class Facts:
    """Per-node types and name resolutions of one checked program.

    The checker writes (`set_type`, `set_name`); everything after it reads
    (`type_of`, `name_of`, `category`, `is_name`). `types` and `names` are the tables
    themselves, keyed by `id(node)`, kept to be read by the modules outside the compiler
    not moved to the accessors yet (the kilobot export, the numba backend's statement
    fusion: `KNOWN_ID_READERS` in `tests/test_visit.py`)."""

    __slots__ = ("_types", "_names", "_nodes")

    def __init__(self):
        self._types: dict[int, str] = {}
        self._names: dict[int, tuple] = {}
        self._nodes: list[ast.Node] = []   # keeps every keyed node alive: ids stay unique

    # ---- written by the checker ----
    def set_type(self, node: ast.Node, t: str) -> None:
        self._nodes.append(node)
        self._types[id(node)] = t

    def set_name(self, node: ast.Node, resolution: tuple) -> None:
        self._nodes.append(node)
        self._names[id(node)] = resolution

    # ---- read by everything after it ----
    def type_of(self, node: ast.Node, default: str | None = None) -> str | None:
        """The checked type of expression `node` (`default` if it was never checked)."""
        return self._types.get(id(node), default)

    def name_of(self, node: ast.Node, default=None):
        """What `node` (a name, attribute, call or assignment) resolved to, or
        `default`."""
        return self._names.get(id(node), default)

    def category(self, node: ast.Node) -> str:
        """The first item of `node`'s resolution ("" if it has none)."""
        res = self._names.get(id(node))
        return res[0] if res else ""

    def is_name(self, node: ast.Node, *resolution) -> bool:
        """Whether `node` resolved to exactly `resolution` (`is_name(n, "state", "pos")`)."""
        return self._names.get(id(node)) == resolution

    def resolutions(self):
        """Every resolution the checker recorded (which calls and names the program
        has: a network, a trilateration), in no particular order."""
        return self._names.values()


class NodeTable:
    """A mapping keyed by node identity that holds its nodes, for a walker's own
    per-node notes (which comparisons a `when` guards, a planner's columns, the signs
    the parser met): equal nodes at two places are two keys, and no key's id can be
    reused by another node while the table lives."""

    __slots__ = ("_items",)

    def __init__(self, items=()):
        self._items: dict[int, tuple[ast.Node, object]] = {}
        for node, value in items:
            self[node] = value

    def __setitem__(self, node: ast.Node, value) -> None:
        self._items[id(node)] = (node, value)

    def __getitem__(self, node: ast.Node):
        return self._items[id(node)][1]

    def get(self, node: ast.Node, default=None):
        got = self._items.get(id(node))
        return default if got is None else got[1]

    def __contains__(self, node: ast.Node) -> bool:
        return id(node) in self._items

    def __len__(self) -> int:
        return len(self._items)

    def items(self):
        """(node, value) pairs, in the order they were first set."""
        return iter(self._items.values())
