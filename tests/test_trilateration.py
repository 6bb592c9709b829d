"""trilaterate(): exact recovery, "no fix" for collinear references, error bounded by
the distance noise, and the set form choosing a well-shaped triple per agent."""

from __future__ import annotations

import numpy as np
from hypothesis import assume, example, given
from hypothesis import strategies as st

from swarmdsl.runtime.trilateration import solve3, solve_sets

coord = st.floats(-200, 200, allow_nan=False, allow_infinity=False)
point = st.tuples(coord, coord).map(np.array)


def _well_shaped(p1, p2, p3) -> bool:
    u, v = p2 - p1, p3 - p2
    sides = min(np.linalg.norm(u), np.linalg.norm(v), np.linalg.norm(p3 - p1))
    sine = abs(u[0] * v[1] - u[1] * v[0]) / (np.linalg.norm(u) * np.linalg.norm(v) + 1e-300)
    return sides > 20 and sine > 0.2


@given(point, point, point, point)
def test_exact_distances_recover_the_point(p1, p2, p3, q):
    assume(_well_shaped(p1, p2, p3))
    r = [np.linalg.norm(q - p) for p in (p1, p2, p3)]
    out = solve3(p1[None], r[0], p2[None], r[1], p3[None], r[2])[0]
    assert out[2] == 1.0
    assert np.allclose(out[:2], q, rtol=0, atol=1e-9)


@given(point, point, st.floats(-3, 3), st.floats(-3, 3), point)
@example(np.array([0.0, 1.0]), np.array([1.0, 0.0]), 1.7e-12, 9.3e-05, np.array([0.0, 0.0]))
def test_collinear_references_give_no_fix_never_nan(p1, p2, t1, t2, q):
    p3 = p1 + t1 * (p2 - p1)          # on the line through p1, p2 (or equal to one)
    p4 = p1 + t2 * (p2 - p1)
    rs = [np.linalg.norm(q - p) for p in (p1, p3, p4)]
    out = solve3(p1, rs[0], p3, rs[1], p4, rs[2])
    assert np.isfinite(out).all()
    assert out[2] == 0.0 and out[0] == 0.0 and out[1] == 0.0


@given(point, point, point, point, st.floats(0.001, 2.0),
       st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_distance_noise_gives_an_error_bounded_by_sigma(p1, p2, p3, q, sigma, unit):
    """|error| <= ||M^-1|| * |(dC, dF)| with |dr_i| <= sigma; linear in sigma."""
    assume(_well_shaped(p1, p2, p3))
    r = np.array([np.linalg.norm(q - p) for p in (p1, p2, p3)])
    dr = sigma * np.asarray(unit)
    out = solve3(p1, r[0] + dr[0], p2, r[1] + dr[1], p3, r[2] + dr[2])
    assert out[2] == 1.0
    m = np.array([p2 - p1, p3 - p2])
    worst = [(2 * ri + sigma) * sigma for ri in r]            # |(r+d)^2 - r^2|
    dc, df = (worst[0] + worst[1]) / 2, (worst[1] + worst[2]) / 2
    bound = np.linalg.norm(np.linalg.inv(m), 2) * np.hypot(dc, df)
    assert np.linalg.norm(out[:2] - q) <= bound * (1 + 1e-9) + 1e-9


def test_set_form_skips_collinear_triples_and_fixes_each_agent():
    # Agent 0: three references in a row plus one off the line -> a fix.
    # Agent 1: only three references in a row -> no fix.  Agent 2: two references.
    truth = np.array([[10.0, 25.0], [50.0, 30.0], [0.0, 0.0]])
    refs = [np.array([[0.0, 0.0], [40.0, 0.0], [80.0, 0.0], [-40.0, 40.0]]),
            np.array([[0.0, 0.0], [40.0, 0.0], [80.0, 0.0]]),
            np.array([[5.0, 5.0], [9.0, 1.0]])]
    seg = np.concatenate([np.full(len(r), i) for i, r in enumerate(refs)])
    pts = np.concatenate(refs)
    dist = np.linalg.norm(pts - truth[seg], axis=1)
    out = solve_sets(pts, dist, seg, 3)
    assert out[:, 2].tolist() == [1.0, 0.0, 0.0]
    assert np.allclose(out[0, :2], truth[0], atol=1e-9)
    assert np.isfinite(out).all()


def test_set_form_vectorised_over_many_agents_matches_truth():
    rng = np.random.default_rng(3)
    m = 500
    truth = rng.uniform(0, 100, (m, 2))
    k = rng.integers(3, 9, m)
    seg = np.repeat(np.arange(m), k)
    pts = rng.uniform(-50, 150, (seg.size, 2))
    dist = np.linalg.norm(pts - truth[seg], axis=1)
    out = solve_sets(pts, dist, seg, m)
    assert out[:, 2].all()
    assert np.allclose(out[:, :2], truth, atol=1e-7)


def test_language_forms(run_src):
    sim = run_src("""
agent a {
  count 3
  place (10 + 20 * index, 30)
  believe (0, 0)
  status s {
    let fix = trilaterate((0, 0), length(pos), (100, 0), length(pos - (100, 0)),
                          (0, 100), length(pos - (0, 100)))
    let flat = trilaterate((0, 0), 1, (1, 0), 1, (2, 0), 1)
    when fix.ok and not flat.ok -> done { believe(fix.pos) }
  }
  status done { }
}
""", steps=1)
    cols = sim.agents.cols
    assert np.allclose(cols["believed"], cols["pos"], atol=1e-9)
    assert cols["located"].all()
