"""The package's imports, read with `ast` (at module level and inside functions alike):
no import cycle among files, none among packages beyond the listed debts, and the
compiler never reaches into a backend (docs/architecture.md, "Layers")."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "swarmdsl"


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _target(name: str) -> str | None:
    """The module of ours `name` is, or is inside (`swarmdsl.a.b.NAME` -> `swarmdsl.a.b`)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str) -> dict[str, int]:
    """Every module of ours `module` imports, anywhere in its text -> the first line."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: dict[str, int] = {}
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join(up + ([node.module] if node.module else []))
            names = [f"{base}.{a.name}" for a in node.names]
        for name in names:
            target = _target(name)
            if target is not None and target != module:
                found.setdefault(target, node.lineno)
    return found


GRAPH = {m: _imports(m) for m in MODULES}


def _unit(module: str) -> str:
    """A module's package; a module directly under `swarmdsl/` is a unit of its own (the
    top-level modules range from leaves, `errors`, to the command, `cli`)."""
    if MODULES[module].name == "__init__.py" or module.count(".") == 1:
        return module
    return module.rpartition(".")[0]


def _cycles(nodes, edges) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found = []
    for start in nodes:
        if start in index:
            continue
        work = [(start, iter(sorted(edges.get(start, ()))))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def _described(cycles, edges_of) -> str:
    lines = []
    for comp in cycles:
        lines.append(" <-> ".join(comp))
        for a in comp:
            for b, why in sorted(edges_of(a).items()):
                if b in comp:
                    lines.append(f"    {a} -> {b}: {why}")
    return "\n".join(lines)


def test_no_import_cycle_among_files():
    cycles = _cycles(sorted(GRAPH), GRAPH)
    assert not cycles, "import cycles:\n" + _described(
        cycles, lambda m: {t: f"line {n}" for t, n in GRAPH[m].items()})


# The layers, lowest first (docs/architecture.md, "Layers"): a package imports only
# from its own layer or lower ones. The runtime runs any program through the protocols
# it declares and knows no language; the compiler emits closures that call the
# runtime's array operations; a backend implements the compiler's lowering and the
# runtime's backend protocol, so it sits above both; tools and commands sit on top.
LAYERS = (
    ("swarmdsl.errors", "swarmdsl.files", "swarmdsl.internal", "swarmdsl.stopping",
     "swarmdsl.limits", "swarmdsl.version", "swarmdsl.command_args", "swarmdsl.ops"),
    ("swarmdsl.runtime", "swarmdsl.runtime.numpy_backend"),   # the reference backend
    ("swarmdsl.compiler",),
    ("swarmdsl.runtime.compiled",),
    ("swarmdsl.viz",),
    ("swarmdsl.testing", "swarmdsl.export"),
    ("swarmdsl.cli",),   # the command; its subcommands plug in above it, by name
    ("swarmdsl.analysis", "swarmdsl.train", "swarmdsl.sweep", "swarmdsl.plot",
     "swarmdsl.studio", "swarmdsl.lsp", "swarmdsl.format"),
    ("swarmdsl", "swarmdsl.__main__"),   # the API (`import swarmdsl`), `python -m`
)
RANK = {unit: i for i, units in enumerate(LAYERS) for unit in units}

# Package imports that still run up the layers, each a debt to pay by moving code,
# never one to add to: the test fails on any other. None is left.
KNOWN_UPWARD: set[tuple[str, str]] = set()


def _package_edges() -> dict[str, dict[str, str]]:
    edges: dict[str, dict[str, str]] = defaultdict(dict)
    for module, targets in GRAPH.items():
        for target, line in targets.items():
            a, b = _unit(module), _unit(target)
            if a != b:
                edges[a].setdefault(b, f"{module} -> {target} (line {line})")
    return edges


def test_every_package_has_a_layer():
    assert not {_unit(m) for m in MODULES} - set(RANK)


def test_packages_import_only_down_the_layers():
    edges = _package_edges()
    up = {(a, b): why for a, bs in edges.items() for b, why in bs.items()
          if RANK[a] < RANK[b] and (a, b) not in KNOWN_UPWARD}
    assert not up, "imports up the layers:\n" + "\n".join(
        f"    {a} -> {b}: {why}" for (a, b), why in sorted(up.items()))


def test_no_import_cycle_among_packages():
    edges = _package_edges()
    kept = {a: {b: why for b, why in bs.items() if (a, b) not in KNOWN_UPWARD}
            for a, bs in edges.items()}
    cycles = _cycles(sorted(kept), kept)
    assert not cycles, "package cycles:\n" + _described(cycles, lambda a: kept.get(a, {}))


def test_the_known_upward_imports_are_still_there():
    """A debt paid comes off the list, so the list says what is left."""
    edges = _package_edges()
    gone = [pair for pair in KNOWN_UPWARD if pair[1] not in edges.get(pair[0], {})]
    assert not gone, f"no longer imported, remove from KNOWN_UPWARD: {gone}"


# The runtime reaches the plug-ins above it (the backends, the viz package's video and
# window) by module names kept as data and imported on first request, not by imports:
# each such table, read from its module's text, and the plug-ins' layers.
PLUGIN_TABLES = {"swarmdsl.runtime.backends": "PLUGINS", "swarmdsl.runtime.observers": "VIZ"}


def _table(module: str, name: str) -> list[str]:
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == name for t in node.targets):
            value = ast.literal_eval(node.value)
            return list(value.values()) if isinstance(value, dict) else [value]
    raise AssertionError(f"{module} has no table {name}")


def test_the_runtime_reaches_its_plug_ins_by_name_only():
    """Every module a plug-in table names exists and is the plug-in's own (its own
    layer or one above the runtime), and the runtime imports none of them: the table is
    the only way down to them, and it is data."""
    runtime = [m for m in MODULES if _unit(m) == "swarmdsl.runtime"]
    for module, name in PLUGIN_TABLES.items():
        for target in _table(module, name):
            assert target in MODULES, f"{module}.{name}: no module {target}"
            assert RANK[_unit(target)] >= RANK["swarmdsl.runtime"]
            importers = [m for m in runtime if target in GRAPH[m]]
            assert not importers, f"{target} imported by {importers}"


BACKEND = "swarmdsl.runtime.compiled"


def _imports_of(prefix: str):
    for module, targets in GRAPH.items():
        if module == prefix or module.startswith(prefix + "."):
            for target, line in targets.items():
                yield module, target, line


def test_the_compiler_never_imports_a_backend():
    """The compiler stops at a checked program and the lowering protocol
    (`compiler/lowering.py`); a backend plugs in from above."""
    bad = [f"{m} -> {t} (line {n})" for m, t, n in _imports_of("swarmdsl.compiler")
           if t == BACKEND or t.startswith(BACKEND + ".")]
    assert not bad, bad


def test_the_runtime_core_asks_its_backend_and_program_through_protocols():
    """Frames reach the backend through `sim.backend` (runtime/backend.py), the metric log
    its metrics through `Program.metrics`: neither imports them."""
    assert not [t for t in GRAPH["swarmdsl.runtime.frame"] if t.startswith(BACKEND)]
    assert not [t for t in GRAPH["swarmdsl.runtime.metrics"] if t.startswith(
        "swarmdsl.compiler.lang_")]


def test_the_backend_plans_without_the_code_generator():
    """The numba planner asks the code generator it is handed (`cg.extension_call`),
    never the module: `compiled/plan.py` imports no codegen."""
    assert "swarmdsl.compiler.codegen" not in GRAPH["swarmdsl.runtime.compiled.plan"]


def test_the_walk_sees_imports_inside_functions():
    """The reader is itself tested: a lazy import in a function counts."""
    assert "swarmdsl.testing.monitor" in GRAPH["swarmdsl.cli"]
    cycles = _cycles(["a", "b", "c"], {"a": {"b": 1}, "b": {"c": 1}, "c": {"a": 1}})
    assert cycles == [["a", "b", "c"]]
