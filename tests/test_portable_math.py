"""The transcendental functions every evaluator shares (`swarmdsl/ops/portable.py`):
one float at a time and over arrays they give the same bits, whatever numpy's SIMD
dispatch picked on this CPU, and they stay within an ulp or two of the C library."""

from __future__ import annotations

import hashlib
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from swarmdsl.ops import portable, portable_runtime

# name: (one float, arrays, the C library's, most ulps apart, least share of equal values)
ONE = {"exp": (portable.exp, portable.exp_array, math.exp, 1, 0.93),
       "log": (portable.log, portable.log_array, math.log, 1, 0.95),
       "sin": (portable.sin, portable.sin_array, math.sin, 1, 0.95),
       "cos": (portable.cos, portable.cos_array, math.cos, 1, 0.95),
       "tan": (portable.tan, portable.tan_array, math.tan, 2, 0.65)}
TWO = {"atan2": (portable.atan2, portable.atan2_array, math.atan2, 1, 0.72),
       "hypot": (portable.hypot, portable.hypot_array, math.hypot, 1, 0.99),
       "pow": (portable.pow, portable.pow_array, math.pow, 1, 0.85)}
ANY = st.floats(allow_nan=True, allow_infinity=True)


def _same(a, b) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return bool(np.all((a.view(np.int64) == b.view(np.int64)) | (np.isnan(a) & np.isnan(b))))


def _ulps(a, b) -> np.ndarray:
    """Distance in units in the last place (0 where both are NaN or equal)."""
    def ordered(v):
        i = np.asarray(v, float).view(np.int64)
        return np.where(i < 0, np.int64(-2**63) - i, i)
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = np.abs(ordered(a) - ordered(b)).astype(float)
    return np.where((a == b) | (np.isnan(a) & np.isnan(b)), 0.0, d)


@pytest.mark.parametrize("name", sorted(ONE))
@given(xs=st.lists(ANY, min_size=1, max_size=12))
def test_one_float_and_an_array_give_the_same_bits(name, xs):
    """Element by element, whatever else the array holds (an infinity or NaN among
    ordinary values takes the array form's careful path for all of them)."""
    scalar, array = ONE[name][:2]
    assert _same([scalar(x) for x in xs], array(np.array(xs)))


@pytest.mark.parametrize("name", sorted(TWO))
@given(pairs=st.lists(st.tuples(ANY, ANY), min_size=1, max_size=12))
@example(pairs=[(math.inf, -4.6), (math.nan, 1.0)])      # y's max is NaN, its min inf
def test_one_pair_and_arrays_give_the_same_bits(name, pairs):
    scalar, array = TWO[name][:2]
    xs, ys = (np.array(v) for v in zip(*pairs, strict=True))
    assert _same([scalar(x, y) for x, y in pairs], array(xs, ys))


def _sample(n=4000, seed=0):
    rng = np.random.default_rng(seed)
    sign = rng.choice([-1.0, 1.0], n)
    return np.concatenate([rng.uniform(-10, 10, n), rng.standard_normal(n) * 1e3,
                           sign * np.exp(rng.uniform(-700, 700, n)),
                           rng.uniform(-1e6, 1e6, n)])


def _libm(fn, *args):
    out = []
    for t in zip(*(a.tolist() for a in args), strict=True):
        try:
            out.append(fn(*t))
        except (ValueError, OverflowError, ZeroDivisionError):
            out.append(math.nan)        # domain and range errors: compared only where finite
    return np.array(out)


@pytest.mark.parametrize("name", sorted(ONE) + sorted(TWO))
def test_within_an_ulp_of_the_c_library(name):
    """Within 1 ulp (tan: 2) of the C library wherever it has a finite value, and equal
    to it about as often as measured when this was written (a wrong digit in a
    coefficient would show in both)."""
    x = _sample()
    if name in ONE:
        _, array, ref, bound, equal = ONE[name]
        if name == "log":
            x = np.abs(x)
        if name in ("sin", "cos", "tan"):
            x = x[np.abs(x) < 1.6e6]
        if name == "exp":
            x = np.clip(x, -745.0, 709.0)
        got, want = array(x), _libm(ref, x)
    else:
        _, array, ref, bound, equal = TWO[name]
        y = np.random.default_rng(1).permutation(x)
        if name == "pow":
            x, y = np.clip(np.abs(x), 1e-3, 1e3), np.clip(y, -40.0, 40.0)
        got, want = array(x, y), _libm(ref, x, y)
    finite = np.isfinite(want)
    assert finite.sum() > 10_000
    err = _ulps(got[finite], want[finite])
    assert err.max() <= bound
    assert (err == 0).mean() > equal


def test_whole_powers_are_exact_and_squares_are_products():
    a = np.arange(-30.0, 31.0)[:, None]
    b = np.arange(0.0, 11.0)[None, :]
    exact = np.array([[float(int(x) ** int(y)) for y in b[0]] for x in a[:, 0]])
    fits = np.abs(exact) < 2.0**53
    assert _same(portable.pow_array(a, b)[fits], exact[fits])
    x = np.random.default_rng(2).standard_normal(1000) * 1e3
    assert _same(portable.pow_array(x, 2.0), x * x)


@pytest.mark.parametrize(("x", "y", "want"), [
    (0.0, -1.0, math.inf), (-0.0, -1.0, -math.inf), (-0.0, 3.0, -0.0), (-8.0, 1 / 3, math.nan),
    (math.nan, 0.0, 1.0), (1.0, math.nan, 1.0), (-1.0, math.inf, 1.0), (0.5, math.inf, 0.0),
    (-math.inf, 3.0, -math.inf), (-math.inf, -3.0, -0.0), (-2.0, 1e300, math.inf)])
def test_pow_keeps_the_c_standards_special_values(x, y, want):
    assert _same(portable.pow(x, y), want)
    assert _same(portable.pow_array(np.array([x]), np.array([y]))[0], want)


@pytest.mark.parametrize(("y", "x", "want"), [
    (0.0, -0.0, math.pi), (-0.0, -1.0, -math.pi), (-0.0, 0.0, -0.0), (1.0, 0.0, math.pi / 2),
    (math.inf, -math.inf, 3 * math.pi / 4), (-1.0, math.inf, -0.0), (1e-300, -1e300, math.pi)])
def test_atan2_keeps_the_c_standards_special_values(y, x, want):
    assert _same(portable.atan2(y, x), want)
    assert _same(portable.atan2_array(np.array([y]), np.array([x]))[0], want)


def test_the_numba_kernels_compile_the_same_bits():
    numba = pytest.importorskip("numba")
    from swarmdsl.runtime.compiled.kernels import scalar_function as _scalar

    exp, log, sin, cos = _scalar("exp"), _scalar("log"), _scalar("sin"), _scalar("cos")
    tan, atan2, hypot, pow_ = _scalar("tan"), _scalar("atan2"), _scalar("hypot"), _scalar("pow")

    @numba.njit
    def every(x, y, out):
        for i in range(x.shape[0]):
            out[0, i] = exp(x[i])
            out[1, i] = log(x[i])
            out[2, i] = sin(x[i])
            out[3, i] = cos(x[i])
            out[4, i] = tan(x[i])
            out[5, i] = atan2(y[i], x[i])
            out[6, i] = hypot(x[i], y[i])
            out[7, i] = pow_(x[i], y[i])

    x = np.concatenate([_sample(500), [0.0, -0.0, math.inf, -math.inf, math.nan, 5e-324]])
    y = np.concatenate([np.random.default_rng(3).permutation(_sample(500)) / 100.0,
                        [-0.0, 2.0, math.nan, 0.5, -math.inf, 3.0]])
    out = np.empty((8, len(x)))
    every(x, y, out)
    with np.errstate(all="ignore"):
        want = [portable.exp_array(x), portable.log_array(x), portable.sin_array(x),
                portable.cos_array(x), portable.tan_array(x), portable.atan2_array(y, x),
                portable.hypot_array(x, y), portable.pow_array(x, y)]
    for row, expected in zip(out, want, strict=True):
        assert _same(row, expected)


_DIGEST = textwrap.dedent("""
    import hashlib, itertools, math, sys
    import numpy as np
    from swarmdsl.ops.functions import FUNCTIONS
    from swarmdsl.ops.operators import ARITHMETIC
    from swarmdsl.ops.types import NUM
    edges = [-math.inf, -1e308, -7.5, -2.5, -1.0, -0.0, 0.0, 5e-324, 0.5, 1.0, 2.5, 3.0,
             math.pi, 1e308, math.inf, math.nan]
    rng = np.random.default_rng(0)
    sample = np.concatenate([rng.uniform(-10, 10, 3000), rng.standard_normal(3000) * 1e3])
    h = hashlib.sha256()
    with np.errstate(all="ignore"):
        for row in sorted(FUNCTIONS.values(), key=lambda r: r.name):
            if row.random or any(p != NUM for p in row.params):
                continue
            grid = np.array(list(itertools.product(edges, repeat=len(row.params))))
            cols = [np.concatenate([grid[:, i], np.roll(sample, i)]) for i in
                    range(len(row.params))]
            h.update(np.ascontiguousarray(row.numpy(None, *cols), dtype=float).tobytes())
        for op in sorted(ARITHMETIC.values(), key=lambda o: o.symbol):
            grid = np.array(list(itertools.product(edges, repeat=2)))
            a = np.concatenate([grid[:, 0], sample])
            b = np.concatenate([grid[:, 1], np.roll(sample, 1) / 100])
            h.update(np.ascontiguousarray(op.numpy(a, b), dtype=float).tobytes())
    print(h.hexdigest())
""")


def _digest(env) -> str:
    done = subprocess.run([sys.executable, "-c", _DIGEST], env=env, capture_output=True,
                          text=True, check=True)
    return done.stdout.strip()


def test_numpys_simd_dispatch_does_not_change_a_bit():
    """Every row's numpy evaluator, run once with every SIMD target numpy can dispatch
    to on this CPU and once with all of them turned off (`NPY_DISABLE_CPU_FEATURES`),
    gives the same bytes: what the cross-check of the rows holds here holds on a CPU
    with fewer (or more) vector units too."""
    from numpy._core import _multiarray_umath as umath

    targets = [t for t in umath.__cpu_dispatch__ if umath.__cpu_features__.get(t)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    env.pop("NPY_DISABLE_CPU_FEATURES", None)
    full = _digest(env)
    limited = _digest({**env, "NPY_DISABLE_CPU_FEATURES": " ".join(targets)})
    assert full == limited
    assert len(full) == len(hashlib.sha256().hexdigest())


def test_a_folded_power_is_the_per_agent_power(backend, run_src):
    """`param p = 2.5 ^ 2.5` (folded) and the same power per agent are one number."""
    sim = run_src("""
param p = 2.5 ^ 2.5
param q = atan2(2.5, -7.5) + exp(3.7) + log(7.3) + tan(1.3) + hypot(3.1, 4.2) + sin(9.1)
world { size 100 x 100 }
agent a {
  count 3
  var b = 2.5
  var c = -7.5
  var d = 3.7
  var e = 7.3
  var f = 1.3
  var g = 3.1
  var h = 4.2
  var k = 9.1
  var vp = 0
  var vq = 0
  status s {
    vp = b ^ b
    vq = atan2(b, c) + exp(d) + log(e) + tan(f) + hypot(g, h) + sin(k)
  }
}
""", steps=1)
    assert np.all(sim.agents.cols["vp"] == sim.program.params["p"])
    assert np.all(sim.agents.cols["vq"] == sim.program.params["q"])


_RUNS = textwrap.dedent("""
    import hashlib, sys
    from pathlib import Path
    import numpy as np
    import swarmdsl
    from swarmdsl.runtime.simulation import Simulation
    h = hashlib.sha256()
    for path in sorted(Path(sys.argv[1]).glob("*.swarm")):
        sim = Simulation(swarmdsl.load_program(path), 5, backend="numpy")
        sim.run(12)
        for name in sorted(sim.agents.cols):
            col = np.ascontiguousarray(sim.agents.cols[name])
            h.update(name.encode() + col.tobytes())
        env = sim.environment
        for name, field in sorted(env.fields.items() if env is not None else []):
            h.update(name.encode() + np.ascontiguousarray(field.values).tobytes())
    print(h.hexdigest())
""")


def test_every_shipped_program_runs_to_the_same_bits_with_simd_turned_off():
    """Whole runs, not only the rows: motion, headings, draws, sums and fields of every
    shipped program do not depend on which vector units numpy found."""
    from numpy._core import _multiarray_umath as umath

    from tests.conftest import PROGRAMS

    targets = [t for t in umath.__cpu_dispatch__ if umath.__cpu_features__.get(t)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    env.pop("NPY_DISABLE_CPU_FEATURES", None)

    def digest(env):
        return subprocess.run([sys.executable, "-c", _RUNS, str(PROGRAMS)], env=env,
                              capture_output=True, text=True, check=True).stdout.strip()

    assert digest(env) == digest({**env, "NPY_DISABLE_CPU_FEATURES": " ".join(targets)})


def test_a_numba_run_evaluates_big_arrays_in_compiled_loops_with_the_same_bits():
    pytest.importorskip("numba")
    from swarmdsl.runtime.compiled import math_loops

    x = np.concatenate([_sample(1200), [0.0, -0.0, math.inf, -math.inf, math.nan]])
    y = np.random.default_rng(4).permutation(x) / 50.0
    assert x.size >= portable.COMPILED_MIN
    forms = [(portable.exp_array, (x,)), (portable.log_array, (x,)),
             (portable.sin_array, (x,)), (portable.cos_array, (x,)),
             (portable.tan_array, (x,)), (portable.atan2_array, (y, x)),
             (portable.hypot_array, (x, y)), (portable.pow_array, (x, y)),
             (portable.cos_array, (x.reshape(-1, 5),)),
             (portable.atan2_array, (y[:, None], x[None, :7]))]
    before = portable._compiled
    try:
        portable.use_compiled(None)
        with np.errstate(all="ignore"):
            want = [fn(*args) for fn, args in forms]
        math_loops.install()
        got = [fn(*args) for fn, args in forms]
    finally:
        portable.use_compiled(before)
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape and _same(g, w)


def test_inside_a_numba_tick_small_arrays_go_to_the_compiled_loops_with_the_same_bits():
    """A numba tick (`portable.EVERY_SIZE`) hands the runtime's arrays of a few values to
    the compiled loops too: strided, 0-d, broadcast and empty arguments included."""
    pytest.importorskip("numba")
    from swarmdsl.runtime.compiled import math_loops

    x = np.concatenate([_sample(6), [0.0, -0.0, math.inf, -math.inf, math.nan]])
    y = np.random.default_rng(5).permutation(x) / 50.0
    grid = np.stack([x, y], axis=1)                       # columns: strided views
    forms = [(portable.exp_array, (x,)), (portable.log_array, (grid[:, 0],)),
             (portable.sin_array, (x[:3],)), (portable.cos_array, (np.float64(0.5),)),
             (portable.tan_array, (x,)), (portable.atan2_array, (grid[:, 1], grid[:, 0])),
             (portable.hypot_array, (x, 2.0)), (portable.pow_array, (0.7, x)),
             (portable.pow_array, (x[:, None], y[None, :4])), (portable.exp_array, (x[:0],)),
             (portable_runtime.log1p_array, (y,)),
             (portable_runtime.tanh_array, (x,))]
    before = portable._compiled
    try:
        portable.use_compiled(None)
        with np.errstate(all="ignore"):
            want = [fn(*args) for fn, args in forms]
        math_loops.install()
        with portable.EVERY_SIZE, np.errstate(all="ignore"):
            got = [fn(*args) for fn, args in forms]
    finally:
        portable.use_compiled(before)
    for g, w in zip(got, want, strict=True):
        assert np.shape(g) == np.shape(w) and _same(np.asarray(g), np.asarray(w))


def test_a_small_numba_run_evaluates_its_extensions_math_in_the_loops_a_numpy_run_not():
    """The ant colony (7 ants: arrays of a few values) hands its direction choices' math
    to the compiled loops inside numba ticks, the same run's numpy twin never, and both
    end on the same bits."""
    pytest.importorskip("numba")
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.simulation import Simulation

    program = compile_file(Path(__file__).parents[1] / "programs" / "aco.swarm")
    sims = {b: Simulation(program, 2, backend=b) for b in ("numpy", "numba")}
    loop = portable._compiled
    assert loop is not None            # the numba simulation installed its loops
    calls = {"numpy": 0, "numba": 0}
    running = ""

    def counted(name, args):
        calls[running] += 1
        return loop(name, args)

    portable.use_compiled(counted)
    try:
        for running in ("numpy", "numba"):
            sims[running].run(30)
    finally:
        portable.use_compiled(loop)
    assert calls["numpy"] == 0 and calls["numba"] > 30
    a, b = (s.agents.cols for s in sims.values())
    for col in ("pos", "vel", "heading"):
        assert _same(a[col][:sims["numpy"].agents.n], b[col][:sims["numba"].agents.n])
