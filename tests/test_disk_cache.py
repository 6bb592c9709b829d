"""Composed kernels kept on disk: a later process loads them instead of compiling, gets
the same bits, and a kernel made of anything different never loads another's code."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from swarmdsl.runtime.compiled import disk_cache
from swarmdsl.runtime.compiled.disk_cache import fingerprint

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[1]


def _factory(value):
    def kernel(x):
        return x * value
    return kernel


_numbers = st.one_of(st.integers(-5, 5), st.floats(allow_nan=True), st.booleans(),
                     st.none(), st.text(max_size=3))


@given(_numbers, _numbers)
def test_closures_share_a_key_only_when_their_cells_are_alike(a, b):
    same = type(a) is type(b) and repr(a) == repr(b)
    assert (fingerprint(_factory(a)) == fingerprint(_factory(b))) == same
    assert fingerprint(_factory(a)) is not None


def _helper_one(x):
    return x + 1


def _helper_two(x):
    return x + 2          # the same bytecode as _helper_one: only a constant differs


def _caller(x):
    return helper(x)      # noqa: F821 (bound through the globals given below)


def _with_globals(fn, **scope):
    return types.FunctionType(fn.__code__, {"__name__": __name__, **scope}, fn.__name__)


def test_a_change_to_a_function_reached_through_the_globals_changes_the_key():
    one = fingerprint(_with_globals(_caller, helper=_helper_one))
    two = fingerprint(_with_globals(_caller, helper=_helper_two))
    assert one != two
    assert one == fingerprint(_with_globals(_caller, helper=_helper_one))


def test_arrays_and_numpy_scalars_are_keyed_by_value():
    a, b = np.zeros((2, 2)), np.zeros((2, 2))
    assert fingerprint(_factory(a)) == fingerprint(_factory(b))
    b[1, 1] = 1
    assert fingerprint(_factory(a)) != fingerprint(_factory(b))
    assert fingerprint(_factory(np.float32(1))) != fingerprint(_factory(np.float64(1)))


def test_the_compiler_options_are_part_of_the_key():
    from numba import njit

    def kernel(x):
        return x + 1
    serial, threaded = njit(nogil=True)(kernel), njit(nogil=True, parallel=True)(kernel)
    assert fingerprint(serial) != fingerprint(threaded)
    assert fingerprint(serial) == fingerprint(njit(nogil=True)(kernel))


def test_anything_without_a_stable_description_is_not_kept():
    assert fingerprint(_factory(object())) is None
    assert fingerprint(_factory({"a": 1})) is None

    def later():
        return value(1)     # a cell filled only after the function is made
    assert fingerprint(later) is None
    value = _helper_one
    assert fingerprint(later) is not None


def _recursive(x):
    return _recursive(x - 1) if x else 0


def test_a_function_that_reaches_itself_has_a_key():
    assert fingerprint(_recursive) == fingerprint(_recursive) is not None


# Two programs whose kernels have the same shape but for one operator: a kernel of
# one loaded for the other would give the other's numbers.
PROGRAM = """
world {{ size 30 x 20; edges wrap }}
agent a {{
  count 60
  sense 6
  velocity (sin(index), cos(index)) * 0.3
  var u = index % 5
  var c = 0
  var s = (0, 0)
  status idle {{
    let near = neighbors(5)
    c = count(near where dist {op} 2)
    s = sum(near : (other.pos - pos) * other.u {op2} dist)
    velocity = normalize(velocity + 0.01 * s) * 0.3
  }}
}}
"""
VARIANTS = {"A": {"op": ">", "op2": "*"}, "B": {"op": "<", "op2": "/"}}

PROBE = """
import hashlib, json, sys
from swarmdsl.compiler import compile_source
from swarmdsl.runtime.compiled import disk_cache
from swarmdsl.runtime.simulation import Simulation

counts = {"loaded": 0, "saved": 0}
cls = disk_cache._cache_class()
load, save = cls.load_overload, cls.save_overload
def counting_load(self, *a):
    got = load(self, *a)
    counts["loaded"] += got is not None
    return got
def counting_save(self, *a):
    counts["saved"] += 1
    return save(self, *a)
cls.load_overload, cls.save_overload = counting_load, counting_save
out = {}
for name, text in json.loads(sys.argv[1]).items():
    sim = Simulation(compile_source(text, name + ".swarm"), 5, backend=sys.argv[2])
    sim.run(4)
    cols = sim.agents.cols
    out[name] = {k: cols[k].tolist() for k in ("pos", "vel", "c", "s")}
print(json.dumps({"counts": counts, "cols": out}))
"""


def _run(folder, names, backend="numba"):
    texts = {n: PROGRAM.format(**VARIANTS[n]) for n in names}
    env = dict(os.environ, NUMBA_CACHE_DIR=str(folder / "numba"),
               SWARMDSL_KERNEL_CACHE="1",
               SWARMDSL_CACHE_DIR=str(folder / "grammar"))
    done = subprocess.run([sys.executable, "-c", PROBE, json.dumps(texts), backend],
                          capture_output=True, text=True, cwd=ROOT, env=env)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


@pytest.fixture(scope="module")
def filled(tmp_path_factory):
    """A cache folder after a first process ran program A, and what it saw."""
    folder = tmp_path_factory.mktemp("kernels")
    return folder, _run(folder, ["A"])


def test_a_later_process_loads_the_kernels_and_gets_the_same_bits(filled):
    """The first process ran the kernels it compiled, the second only loaded ones: the
    same bits (a third process compiling them again, without the cache, gave nothing
    more and cost a compile of every kernel)."""
    folder, first = filled
    assert first["counts"]["loaded"] == 0 and first["counts"]["saved"] >= 3
    second = _run(folder, ["A"])
    assert second["counts"] == {"loaded": first["counts"]["saved"], "saved": 0}
    assert second["cols"] == first["cols"]


def test_a_kernel_of_another_program_is_never_loaded_for_this_one(filled):
    folder, _first = filled
    got = _run(folder, ["B"])
    # B's one pair loop (its count and sum) differs from A's and is compiled; the
    # statements that are alike in both may be loaded.
    assert got["counts"]["saved"] >= 1
    want = _run(folder, ["A", "B"], backend="numpy")["cols"]
    for col, values in want["B"].items():
        np.testing.assert_allclose(got["cols"]["B"][col], values, rtol=1e-9, atol=1e-12)
    assert not np.allclose(want["A"]["c"], want["B"]["c"])   # the variants differ


def test_two_processes_saving_kernels_to_one_index_never_swap_their_code(tmp_path):
    """Two writers that both read the index before either saved (a sweep's workers
    compiling at once): each key's code goes to a file of its own, so whichever index
    survives, a key finds its own kernel or none (then it is compiled again)."""
    files = disk_cache._cache_class().files
    first, second = (files(str(tmp_path), "kernels.run-1.py311", ("stamp", 1))
                     for _ in range(2))
    second._load_index = lambda: {}         # the view it had before `first` saved
    first.save(("sig", "A"), "code of A")
    second.save(("sig", "B"), "code of B")
    reader = files(str(tmp_path), "kernels.run-1.py311", ("stamp", 1))
    assert reader.load(("sig", "B")) == "code of B"
    assert reader.load(("sig", "A")) in (None, "code of A")
    assert len(list(tmp_path.glob("*.nbc"))) == 2


# Two kernels alike but for a constant, the second a loop too big to inline: each is
# compiled first in a fresh process, then both are loaded into a third.
ALIKE = """
import sys
import numpy as np
from swarmdsl.runtime.compiled import disk_cache
from swarmdsl.runtime.compiled.jit import njit

def make(c):
    @njit
    def inner(a, i):
        s = 0.0
        for j in range(a.shape[0]):
            if a[j] > c:
                s += np.sin(a[j] * c) + j
            else:
                s -= np.cos(a[j] - c)
        return s + i

    @njit
    def outer(a):
        t = 0.0
        for i in range(3):
            t += inner(a, i)
        return t
    return disk_cache.keep_on_disk(outer)

a = np.linspace(0.0, 5.0, 50)
for c in sys.argv[1:]:
    kernel = make(float(c))
    print(c, kernel(a), kernel.py_func(a), len(kernel.stats.cache_hits))
"""


def test_kernels_compiled_in_different_processes_run_their_own_code_in_one(tmp_path):
    """numba names machine code by a function's name, its types and a counter that
    used to start at 1 in every process: the two kernels got the same name, and the
    third process ran the first one's code for both."""
    script = tmp_path / "alike.py"
    script.write_text(ALIKE)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"),
               SWARMDSL_KERNEL_CACHE="1", PYTHONPATH=str(ROOT))

    def run(*constants):
        done = subprocess.run([sys.executable, str(script), *constants],
                              capture_output=True, text=True, env=env)
        assert done.returncode == 0, done.stderr
        return [line.split() for line in done.stdout.splitlines()]

    assert [hits for *_, hits in run("2") + run("3")] == ["0", "0"]
    # One process loading both shows the bug in either order (the second loaded ran
    # the first one's code), so one order is enough.
    for c, compiled, python, hits in run("2", "3"):
        assert hits == "1", "loaded from disk"
        assert float(compiled) == pytest.approx(float(python), rel=1e-12), c
