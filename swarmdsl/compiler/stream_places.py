"""Where a random draw stands in the program's structure: the name of its stream.

Every draw of a program (`random()`, `uniform`, `normal`, `chance`,
`random_direction()`, `choose(...)`, a sensing model's noise on a field reading) draws
from a sub-stream of its own, so other draws never shift it. That sub-stream is named
by the draw's *place*: the path from the program's root to the call, written with
what the program means, never with where its text happens to stand. A draw keyed by
its line and column changed when a comment was added above it or its line was
re-indented, so annotating a program, or a formatter, changed every run made with it.

The path's steps, from the root down:

- a declaration by its kind and name: ``agent boid``, ``status flying``,
  ``var energy``, ``option velocity`` (the kind's `velocity ...`), ``world``,
  ``field heat``; a second declaration of the same kind and name (two `place`
  options) adds ``#1``. Declarations are named, not counted, so moving a status,
  a variable or an option among its siblings moves none of its draws.
- a statement by its index in its block: ``body[2]`` (the third statement of the
  status), ``body[0]`` inside a `when`'s actions.
- a tree node by its child index (``kids[1]``) under its parent; a named tree used as
  a leaf (``root`` of its expanded copy, its arguments ``args[i]``), so the same named
  tree used in two places draws two streams.
- a sub-expression by its role in its parent: ``value``, ``left``, ``right``,
  ``args[1]``, ``each``, ``then``.

Everything the parser throws away (comments, blank lines, spaces, indentation,
redundant parentheses) is no step, so it changes no stream. `docs/outputs.md` lists
which edits change which streams.

One computation per checked program, kept in `ProgramInfo.extra` and keyed by node
identity (the table holds each node, so an id is never reused while it is looked up).
"""

from __future__ import annotations

from swarmdsl.compiler import ast
from swarmdsl.compiler.facts import NodeTable
from swarmdsl.compiler.tree_ast import TreeNode
from swarmdsl.errors import SwarmRuntimeError

_KEY = "stream_places"


def table_of(info) -> dict[int, tuple[ast.Node, str]]:
    """``id(node) -> (node, place)`` over the checked program `info`, computed once."""
    table = info.extra.get(_KEY)
    if table is None:
        table = info.extra[_KEY] = places(info.tree, _expanded_trees(info))
    return table


def place_of(info, node: ast.Node) -> str:
    """The stream place of `node` (a draw's call) in the checked program `info`."""
    entry = table_of(info).get(id(node))
    if entry is None or entry[0] is not node:
        raise SwarmRuntimeError(f"internal: the draw `{getattr(node, 'name', node)}` has "
                                "no place in the program's structure", node.span)
    return entry[1]


def same_place(info, made: ast.Node, origin: ast.Node) -> None:
    """`made`, a node the compiler built to compile `origin` (`F at P` compiled as
    `sample(F, P)`), draws where `origin` stands."""
    table_of(info)[id(made)] = (made, place_of(info, origin))


def places(root: ast.Node, trees: NodeTable | None = None) -> dict[int, tuple[ast.Node, str]]:
    """``id(node) -> (node, place)`` for every node under `root`. `trees` maps
    a `TreeStmt` to its checked root, named trees expanded (the checker's); a
    statement missing there is walked as written."""
    trees = NodeTable() if trees is None else trees
    table: dict[int, tuple[ast.Node, str]] = {}
    stack: list[tuple[ast.Node, str]] = [(root, "")]
    while stack:   # no recursion: no nesting depth can exhaust the stack
        node, path = stack.pop()
        table[id(node)] = (node, path)
        stack.extend(_children(node, path, trees))
    return table


def _children(node: ast.Node, path: str, trees: NodeTable):
    """(child, its place) for every child node of `node`."""
    prefix = f"{path}/" if path else ""
    for name in ast.node_fields(type(node)):
        value = getattr(node, name)
        if name == "root" and node in trees:
            value = trees[node]   # the tree as it runs: named trees expanded
        if isinstance(value, ast.Node):
            yield value, prefix + name
        elif isinstance(value, tuple):
            yield from _in_tuple(value, prefix + name, prefix)


def _in_tuple(items: tuple, path: str, prefix: str):
    """Declarations by kind and name, anything else (statements, tree nodes,
    arguments) by index; tuples inside tuples (a comparison chain's) by index too."""
    seen: dict[str, int] = {}
    for i, item in enumerate(items):
        if isinstance(item, tuple):
            yield from _in_tuple(item, f"{path}[{i}]", prefix)
        elif not isinstance(item, ast.Node):
            continue
        elif _is_declaration(item):
            label = _label(item)
            k = seen.get(label, 0)
            seen[label] = k + 1
            yield item, prefix + (label if k == 0 else f"{label}#{k}")
        else:
            yield item, f"{path}[{i}]"


def _is_declaration(node: ast.Node) -> bool:
    return not isinstance(node, ast.Expr | ast.Stmt | TreeNode)


def _label(node: ast.Node) -> str:
    """``status flying``: the declaration's kind (its class, less `Decl`) and name."""
    kind = type(node).__name__
    kind = kind[:-4] if kind.endswith("Decl") and len(kind) > 4 else kind
    name = getattr(node, "name", None)
    return kind.lower() if not isinstance(name, str) else f"{kind.lower()} {name}"


def _expanded_trees(info) -> NodeTable:
    trees = info.extra.get("trees")
    return getattr(trees, "roots", None) or NodeTable()
