"""The backend registry (`runtime/backends.py`): every known backend is a plug-in that
registers itself, a run gets one by name without the runtime importing it, a backend
registered from outside runs programs, and no code outside a backend's own package
branches on a backend's name."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from swarmdsl.errors import SwarmOptionError
from swarmdsl.runtime import backends
from swarmdsl.runtime.protocols import Backend

ROOT = Path(__file__).resolve().parent.parent
PROGRAM = """world { size 30 x 30; edges wrap }
agent a { count 60
  place uniform
  velocity random_direction()
  status m {
    let near = neighbors(3)
    velocity = normalize(velocity + sum(near : other.vel - vel) / max(count(near), 1))
  }
}
"""


def _declared() -> set[str]:
    """The names `protocols.Backend` declares: attributes and methods."""
    own = set(Backend.__annotations__)
    own |= {n for n, v in vars(Backend).items() if callable(v) and not n.startswith("_")}
    return own


@pytest.mark.parametrize("name", list(backends.PLUGINS))
def test_every_known_backend_registers_itself_as_a_whole_backend(name):
    plugin = backends.plugin(name)
    assert plugin is not None and plugin.name == name
    if not plugin.installed():
        pytest.skip(f"{name} is not installed")
    made = plugin.factory()
    assert made.name == name
    assert not [n for n in _declared() if not hasattr(made, n)]
    assert backends.make(name) is not backends.make(name)   # one per run


def test_a_run_on_the_reference_never_imports_another_backend():
    """The runtime reaches a backend through the registry only: a numpy run loads no
    numba package (nor numba)."""
    code = ("import sys\nfrom swarmdsl.compiler import compile_source\n"
            "from swarmdsl.runtime.simulation import Simulation\n"
            f"sim = Simulation(compile_source({PROGRAM!r}, 't.swarm'), backend='numpy')\n"
            "sim.step()\n"
            "print(sorted(m for m in sys.modules if m.startswith('swarmdsl.runtime.compiled')"
            " or m == 'numba'))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


class _Counting:
    """A backend of its own: another backend's every answer, with its pair searches
    counted (what a third backend plugs in through)."""

    def __init__(self, inner):
        self._inner, self.searches = inner, 0
        self.name = "counting"

    def __getattr__(self, attr):
        return getattr(self._inner, attr)

    def __setattr__(self, attr, value):
        if attr in ("_inner", "searches", "name"):
            object.__setattr__(self, attr, value)
        else:
            setattr(self._inner, attr, value)

    def build_pairs(self, *args, **kw):
        self.searches += 1
        return self._inner.build_pairs(*args, **kw)


def test_a_backend_registered_from_outside_runs_programs_alike(compile_src, backend):
    from swarmdsl.runtime.simulation import Simulation

    made = []
    backends.register("counting", lambda: made.append(_Counting(backends.make(backend)))
                      or made[-1])
    try:
        assert "counting" in backends.names()
        got = Simulation(compile_src(PROGRAM), seed=3, backend="counting")
        want = Simulation(compile_src(PROGRAM), seed=3, backend=backend)
        for _ in range(5):
            got.step()
            want.step()
    finally:
        del backends._REGISTERED["counting"]
    assert made[0].searches == 5
    for col in ("pos", "vel"):
        assert np.array_equal(got.agents.cols[col], want.agents.cols[col])


def test_an_unknown_backend_is_refused_naming_the_choices(compile_src):
    from swarmdsl.runtime.simulation import Simulation

    with pytest.raises(SwarmOptionError, match="unknown backend `cuda`: choose numba or "
                       "numpy"):
        Simulation(compile_src(PROGRAM), backend="cuda")
    assert backends.plugin(["numba"]) is None    # not a name at all


BACKEND_PACKAGES = {p.replace(".", "/") for p in backends.PLUGINS.values()}


def _outside_backends():
    for path in sorted((ROOT / "swarmdsl").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if not any(rel.startswith(pkg + "/") for pkg in BACKEND_PACKAGES):
            yield rel, ast.parse(path.read_text(encoding="utf-8"))


def test_no_code_outside_a_backend_branches_on_which_backend_runs():
    """A comparison with a backend's name, or a test of `.fused`, belongs in that
    backend's own methods (a third backend would add a branch to each)."""
    names = set(backends.PLUGINS)
    found = []
    for rel, tree in _outside_backends():
        for node in ast.walk(tree):
            if isinstance(node, ast.Compare):
                parts = [node.left, *node.comparators]
                if any(isinstance(p, ast.Constant) and p.value in names for p in parts):
                    found.append(f"{rel}:{node.lineno}")
            elif isinstance(node, ast.Attribute) and node.attr == "fused":
                found.append(f"{rel}:{node.lineno}")
    assert not found, found
