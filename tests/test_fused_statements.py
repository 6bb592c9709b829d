"""Fused per-agent statements on the numba backend against the reference closures: every
built-in and operator, masked writes under `when`, located faults, random draws, the
`-v` report, fallback, shared kernels, and generated programs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from conftest import REFERENCE, assert_backends_agree, run_both  # noqa: E402
from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.compiler.errors import SwarmError  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402


def assert_agree(sims, rtol=1e-12):
    """Every agent column agrees to `rtol` relative (NaN and infinities exactly)."""
    ref, fast = sims
    for col, a in ref.agents.cols.items():
        b = fast.agents.cols[col]
        assert a.shape == b.shape and a.dtype == b.dtype, col
        if a.dtype.kind != "f":
            assert np.array_equal(a, b), col
            continue
        assert np.array_equal(np.isnan(a), np.isnan(b)), col
        fin = np.isfinite(a)
        assert np.array_equal(a[~fin & ~np.isnan(a)], b[~fin & ~np.isnan(b)]), col
        scale = 1.0 + np.max(np.abs(a[fin]), initial=0.0)
        assert np.allclose(a[fin], b[fin], rtol=rtol, atol=rtol * scale), col


def assert_agree_to_1e_9(sims, prog):
    """`assert_agree` for generated programs: a tiny `sin` or summation-order difference
    may grow over the first ticks."""
    assert_agree(sims, rtol=1e-9)


def statement_lines(sim, prog) -> list[str]:
    return [ln for ln in sim.backend.summary(prog) if " statement `" in ln]


EVERY_BUILTIN = """
param k = 0.5
world { size 40 x 30; edges wrap }
agent a {
  count 50
  sense 5
  velocity (sin(index) * 2, cos(index * 3))
  var g = index % 7 - 3
  var b = index % 3 == 0
  var v = (index % 4 - 1, 0.5)
  var n1 = 0
  var n2 = 0
  var n3 = 0
  var n4 = 0
  var n5 = 0
  var vv = (0, 0)
  status idle {
    let near = count(neighbors())
    let u = normalize(v - (1, 0.5)) + normalise(vel) * k
    let r = rotate(u, g * 0.3) + unit(g) - (abs(g), sqrt(abs(g)))
    n1 = exp(g * 0.1) + log(abs(g) + 1) + sin(g) * cos(g) - tan(g * 0.2)
    n2 = floor(g * 1.5) + ceil(g / 4) + round(g * 0.5) + sign(g) * g % 3 - -g + abs(g) ^ 1.5
    n3 = atan2(g, 2) + min(g, near) - max(g, k) + clamp(g * 2, -3, 3) + tick * 0.5
    n4 = length(r) + dot(r, v) - cross(r, v) * angle(r) + angle_between(r, v) + distance(pos, r)
    n5 = (if b then -g else g ^ 2) + (if g > 0 and not b or g == -3 then 1 else 2) * near
    vv = vec(n1, n2) * 0.5 + (r.x, u.y) / (g + 3.5) + (if status == idle then pos else v)
    velocity = rotate(normalize(vel + r * 0.1) * 1.5, g * 0.01)
  }
}
"""


def test_every_builtin_and_operator_in_a_fused_statement_agrees_with_numpy():
    """All of them in statements that run fused, the zero vector normalised (agents with
    `v = (1, 0.5)`), constants, params, `tick` and a status compared, over 3 ticks."""
    prog, sims = run_both(EVERY_BUILTIN, steps=3, other="numba")
    assert_agree(sims)
    lines = statement_lines(sims[1], prog)
    assert len(lines) == 9 and all(ln.endswith(": compiled") for ln in lines), lines
    assert "19:5 statement `let u = ...`: compiled" in lines
    assert not any("let near" in ln for ln in lines)   # one aggregate: nothing to fuse


def test_the_zero_vector_normalises_to_the_zero_vector(other_backend):
    text = """
agent a {
  count 4
  var v = (index % 2, 0)
  var u = (9, 9)
  status s { u = normalize(v * 2 - v) * 3 + (0, 0) }
}
"""
    prog, (ref, fast) = run_both(text, steps=1, other=other_backend)
    order = np.argsort(fast.agents.cols["id"])
    got = fast.agents.cols["u"][order]
    assert np.array_equal(got, [[0, 0], [3, 0], [0, 0], [3, 0]])
    assert np.array_equal(ref.agents.cols["u"], fast.agents.cols["u"])
    assert statement_lines(fast, prog)


MASKED = """
agent a {
  count 30
  var g = index
  var h = 0
  var v = (0, 0)
  status s {
    when index % 3 == 0 -> t { h = g * 2 + 1 - g / 4; v += (g, 1) * 2 - (1, 1) }
    h = g * 3 - 1 + g / 8
    v -= (g, 2) * 0.5 + (1, 1)
  }
  status t { h += g * 0.25 + 1 - tick }
}
"""


def test_masked_writes_under_when_keep_the_other_agents_values(other_backend):
    """Agents a `when` took out keep what its body wrote; the rest get the body's
    statements; a status entered later applies its operator to the current value."""
    prog, sims = run_both(MASKED, steps=1, other=other_backend)
    for sim in sims:
        cols = sim.agents.cols
        x, took = cols["index"], cols["index"] % 3 == 0
        assert np.array_equal(cols["h"], np.where(took, x * 2 + 1 - x / 4, x * 3 - 1 + x / 8))
        expect_v = np.where(took[:, None], np.stack([x * 2 - 1, np.ones_like(x)], 1),
                            -(np.stack([x * 0.5 + 1, np.full_like(x, 2.0)], 1)))
        assert np.array_equal(cols["v"], expect_v)
    assert_agree(sims, rtol=0)
    assert len(statement_lines(sims[1], prog)) == 5
    prog, sims = run_both(MASKED, steps=4, other=other_backend)
    assert_agree(sims, rtol=0)


@pytest.mark.parametrize("statement, words", [
    ("velocity = (1 / (5 - t) + idle_nan, 0) * 2 + vel", "`velocity` became infinite for"),
    ("q -= sqrt(4 - t - index) * 2 + 1 + idle_nan", "`q` became NaN for agent"),
    ("q += 1 / (2 - t) * 2 + 1 + idle_nan", "`q` became infinite for agent"),
    # agent 1 becomes infinite, agent 2 NaN: the message says what agent 1 holds
    ("q = 1 / (2 - t - index) + sqrt(2.5 - t - index) * 0 + idle_nan",
     "`q` became infinite for agent 1 "),
    ("let z = (log(3 - t) * 0 - index + idle_nan, 1) + vel\n    velocity = z",
     "`z` is NaN for agent"),
])
def test_a_fault_gives_the_same_located_error_on_both_backends(statement, words,
                                                                other_backend):
    """The same text, line and column, agent, kind, status and tick; an agent a `when`
    took out does not fault (index 0 leaves `s` at tick 0, with NaN in `idle_nan`)."""
    statement = statement.replace("idle_nan", "sqrt(index - 0.5) * 0")
    text = f"""
agent a {{
  count 4
  var t = 0
  var q = 0
  status s {{
    when index == 0 -> idle
    t += 1
    {statement}
  }}
  status idle {{ }}
}}
"""
    prog = compile_source(text, "test.swarm")
    said = []
    for backend in (REFERENCE, other_backend):
        sim = Simulation(prog, 0, backend=backend)
        with pytest.raises(SwarmError) as err:
            sim.run(10)
        said.append(str(err.value))
    assert said[0] == said[1]
    assert "test.swarm:9:5: error: " + words in said[1], said[1]
    assert "(kind `a`, status `s`) at tick" in said[1]
    assert "agent 0 " not in said[1]


def test_random_draws_in_a_fused_statement_are_the_reference_draws_bit_for_bit():
    text = """
agent a {
  count 200
  var g = 0
  var h = (0, 0)
  status s {
    g = normal(0, 1) * 2 + uniform(-1, 1) - g * 0.5
    h += (random(), normal(3, 0.5)) * 2 - (g, 1) + random_direction()
  }
}
"""
    prog, (ref, fast) = run_both(text, steps=3, seed=5, other="numba")
    assert len(statement_lines(fast, prog)) == 2
    for col in ("g", "h"):
        assert np.array_equal(ref.agents.cols[col], fast.agents.cols[col]), col
    again = Simulation(prog, 5, backend="numba")
    again.run(3)
    assert np.array_equal(again.agents.cols["h"], fast.agents.cols["h"])


def test_run_verbose_lists_the_fused_statements(tmp_path, capsys):
    """The program's aggregate and `velocity` have the shapes of EVERY_BUILTIN's
    (`count(neighbors())`, `velocity = rotate(...)`): they compile no new kernel."""
    from swarmdsl.cli import main

    path = tmp_path / "flock.swarm"
    path.write_text("""agent a {
  count 20
  sense 5
  var w = 1
  status s {
    let c = count(neighbors())
    let steer = (vel * 2 + (c, -c) * 0.1) / max(c, 1)
    velocity = rotate(normalize(vel + steer * 0.1) * 2, w * 0.01)
    w = w + 1
  }
}
""")
    assert main(["run", str(path), "--headless", "--steps", "3", "--backend", "numba",
                 "-v", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "7:5 statement `let steer = ...`: compiled" in err
    assert "8:5 statement `velocity = ...`: compiled" in err
    assert "let c" not in err and "`w =" not in err     # too small to fuse
    assert main(["run", str(path), "--headless", "--steps", "3", "--backend", "numpy",
                 "-v", "--out", str(tmp_path / "p")]) == 0
    assert "statement" not in capsys.readouterr().err


def test_a_statement_numba_cannot_compile_keeps_the_reference_with_its_draws(monkeypatch):
    """The refusal is found before the statement's draws are made, so the run still
    gives the reference's numbers bit for bit, and `-v` says why."""
    from swarmdsl.runtime.compiled import stmt_kernels

    def refused(*args):
        raise RuntimeError("lowering failed\nmore")

    monkeypatch.setattr(stmt_kernels, "_body", refused)
    monkeypatch.setattr(stmt_kernels, "_KERNELS", {})
    text = """
agent a {
  count 30
  var g = 0
  status s { g = normal(0, 1) * 2 + g * 0.5 - 1 }
}
"""
    prog, (ref, fast) = run_both(text, steps=3, other="numba")
    assert np.array_equal(ref.agents.cols["g"], fast.agents.cols["g"])
    assert statement_lines(fast, prog) == [
        "5:14 statement `g = ...`: numpy (numba could not compile it: lowering failed)"]


def test_programs_that_differ_only_in_params_share_the_statement_kernels():
    from swarmdsl.runtime.compiled import stmt_kernels

    for k in ("0.5", "2"):
        Simulation(compile_source(EVERY_BUILTIN, "test.swarm", {"k": k}), 0,
                   backend="numba").run(1)
        if k == "0.5":
            before = len(stmt_kernels._KERNELS)
    assert len(stmt_kernels._KERNELS) == before


# ---- generated programs ----

_NUM = st.sampled_from(["g", "pos.x", "speed", "tick", "w", "1.5", "p", "id", "near",
                        "normal(0, 1)", "vel.y", "heading"])
_VEC = st.sampled_from(["vel", "pos", "v", "(1, 2)", "(g, uniform(0, 1))",
                        "nearest(neighbors() : other.pos - pos else (0, 1))"])
_BOOL = st.sampled_from(["b", "g > 1", "status == busy", "chance(0.5)", "near >= 2"])


def _exprs():
    def grow(inner):
        n, v, b = (inner.map(lambda t: t[0]), inner.map(lambda t: t[1]),
                   inner.map(lambda t: t[2]))
        num = st.one_of(
            n,
            st.tuples(n, st.sampled_from(["+", "-", "*", "/", "%", "^"]), n).map(
                lambda t: f"({t[0]} {t[1]} {t[2]})"),
            st.tuples(st.sampled_from(["abs", "sqrt", "sin", "cos", "exp", "log", "floor",
                                       "round", "sign"]), n).map(lambda t: f"{t[0]}({t[1]})"),
            st.tuples(st.sampled_from(["min", "max", "atan2"]), n, n).map(
                lambda t: f"{t[0]}({t[1]}, {t[2]})"),
            st.tuples(st.sampled_from(["length", "angle"]), v).map(lambda t: f"{t[0]}({t[1]})"),
            st.tuples(v, v).map(lambda t: f"dot({t[0]}, {t[1]})"),
            st.tuples(b, n, n).map(lambda t: f"(if {t[0]} then {t[1]} else {t[2]})"),
            v.map(lambda x: f"({x}).y"),
            n.map(lambda x: f"(-{x})"))
        vec = st.one_of(
            v,
            st.tuples(v, st.sampled_from(["+", "-"]), v).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
            st.tuples(v, st.sampled_from(["*", "/"]), n).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
            v.map(lambda x: f"normalize({x})"),
            n.map(lambda x: f"unit({x})"),
            st.tuples(v, n).map(lambda t: f"rotate({t[0]}, {t[1]})"))
        boolean = st.one_of(
            b, st.tuples(n, st.sampled_from(["<", ">=", "!="]), n).map(
                lambda t: f"({t[0]} {t[1]} {t[2]})"),
            st.tuples(b, b).map(lambda t: f"({t[0]} and not {t[1]})"))
        return st.tuples(num, vec, boolean)
    return st.recursive(st.tuples(_NUM, _VEC, _BOOL), grow, max_leaves=6)


@st.composite
def generated_programs(draw):
    e1, e2 = draw(_exprs()), draw(_exprs())
    op_n = draw(st.sampled_from(["=", "+=", "-=", "*=", "/="]))
    op_v = draw(st.sampled_from(["=", "+=", "-="]))
    edges = draw(st.sampled_from(["wrap", "wall"]))
    return f"""
param p = 0.75
world {{ size 24 x 16; edges {edges} }}
agent a {{
  count 30
  sense 5
  velocity (cos(index), sin(index))
  var g = index % 4
  var b = index % 3 == 0
  var v = (index % 5, 2)
  var x2 = 1
  var v2 = (1, 1)
  status idle {{
    let near = count(neighbors(4))
    let w = g + 1
    let z = {e1[0]} + {e2[0]} * w
    let u = {e1[1]} - {e2[1]}
    x2 {op_n} {e2[0]} + z
    when {e1[2]} -> busy {{ v2 {op_v} {e2[1]} + u }}
    v2 {op_v} {e1[1]} * z
    velocity = normalize(vel + u * 0.01) * 2
  }}
  status busy {{ x2 = count(neighbors() where other.status == idle); when b -> idle }}
}}
"""


@settings(max_examples=4, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(generated_programs())
def test_generated_statements_agree_with_the_reference(text):
    assert_backends_agree(text, assert_agree_to_1e_9)


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(generated_programs())
def test_generated_statements_agree_long(text):
    assert_backends_agree(text, assert_agree_to_1e_9)
