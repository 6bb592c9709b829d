"""Region shapes against brute-force oracles; obstacle blocking as a property."""

import json
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from swarmdsl.runtime.fields import Grid
from swarmdsl.runtime.regions import Circle, Polygon, Rect, Region, block_moves

PROPS = settings(max_examples=60, deadline=None)

coord = st.floats(-50, 150, allow_nan=False, allow_infinity=False)
circles = st.builds(Circle, st.floats(0, 100), st.floats(0, 100), st.floats(0.5, 30))
rects = st.tuples(st.floats(0, 100), st.floats(0, 100), st.floats(0.5, 40),
                  st.floats(0.5, 40)).map(lambda t: Rect(t[0], t[1], t[0] + t[2], t[1] + t[3]))
points = st.lists(st.tuples(coord, coord), min_size=1, max_size=40).map(np.array)

L_SHAPE = Polygon([(0, 0), (10, 0), (10, 4), (4, 4), (4, 10), (0, 10)])  # concave


def _ray_cast_one(poly, x, y):
    """Textbook point-in-polygon for a single point (the slow oracle)."""
    inside = False
    pts = poly.points
    for (xa, ya), (xb, yb) in zip(pts, pts[1:] + pts[:1], strict=True):
        if (ya > y) != (yb > y) and x < xa + (y - ya) * (xb - xa) / (yb - ya):
            inside = not inside
    return inside


def _boundary_samples(shape, n=4000):
    """Points densely along a shape's outline, for a brute-force distance."""
    if isinstance(shape, Circle):
        a = np.linspace(0, 2 * np.pi, n, endpoint=False)
        return np.column_stack([shape.cx + shape.r * np.cos(a), shape.cy + shape.r * np.sin(a)])
    if isinstance(shape, Rect):
        shape = Polygon([(shape.x0, shape.y0), (shape.x1, shape.y0),
                         (shape.x1, shape.y1), (shape.x0, shape.y1)])
    pts = np.array(shape.points)
    ends = np.roll(pts, -1, axis=0)
    t = np.linspace(0, 1, n // len(pts), endpoint=False)[:, None, None]
    return (pts + t * (ends - pts)).reshape(-1, 2)


def _check_against_brute_force(shape, pts, inside_oracle):
    inside = shape.contains(pts)
    np.testing.assert_array_equal(inside, inside_oracle)
    d = shape.distance(pts)
    assert (d[inside] == 0).all()
    outline = _boundary_samples(shape)
    brute = np.sqrt(((pts[:, None] - outline[None]) ** 2).sum(axis=2)).min(axis=1)
    step = np.sqrt((np.diff(outline, axis=0) ** 2).sum(axis=1)).max()
    out = ~inside
    assert (d[out] > 0).all()
    assert (d[out] <= brute[out] + 1e-9).all()  # exact distance never exceeds a sample's
    assert (brute[out] - d[out] <= step).all()


@PROPS
@given(circles, points)
def test_circle_vs_brute_force(c, pts):
    oracle = [math.hypot(x - c.cx, y - c.cy) <= c.r for x, y in pts]
    _check_against_brute_force(c, pts, oracle)


@PROPS
@given(rects, points)
def test_rect_vs_brute_force(r, pts):
    oracle = [r.x0 <= x <= r.x1 and r.y0 <= y <= r.y1 for x, y in pts]
    _check_against_brute_force(r, pts, oracle)


@PROPS
@given(st.lists(st.tuples(st.integers(-120, 120), st.integers(-120, 120)), min_size=2,
                max_size=40))
def test_concave_polygon_vs_brute_force(raw):
    pts = np.array(raw) / 10 + 0.05  # never on the integer outline, where ray casts differ
    oracle = [_ray_cast_one(L_SHAPE, x, y) for x, y in pts]
    _check_against_brute_force(L_SHAPE, pts, oracle)


@PROPS
@given(rects, points)
def test_polygon_of_a_rect_agrees_with_the_rect(r, pts):
    p = Polygon([(r.x0, r.y0), (r.x1, r.y0), (r.x1, r.y1), (r.x0, r.y1)])
    x, y = pts[:, 0], pts[:, 1]
    to_outline = np.minimum.reduce([abs(x - r.x0), abs(x - r.x1), abs(y - r.y0), abs(y - r.y1)])
    clear = (to_outline > 1e-9) | (r.distance(pts) > 1e-9)  # rounding decides the outline
    np.testing.assert_array_equal(p.contains(pts)[clear], r.contains(pts)[clear])
    np.testing.assert_allclose(p.distance(pts), r.distance(pts), rtol=1e-9, atol=1e-9)


def test_boundary_points_are_inside():
    assert Circle(0, 0, 5).contains([[5.0, 0.0]]).all()
    assert Rect(0, 0, 1, 1).contains([[1.0, 0.5], [0.0, 0.0]]).all()
    assert L_SHAPE.contains([[4.0, 7.0], [10.0, 2.0], [7.0, 4.0]]).all()
    assert not L_SHAPE.contains([[7.0, 7.0]]).any()


def test_centers():
    assert Circle(3, 4, 1).center == (3, 4)
    assert Rect(0, 0, 4, 2).center == (2, 1)
    assert Polygon([(0, 0), (4, 0), (4, 2), (0, 2)]).center == pytest.approx((2, 1))
    # The L is the 10 x 10 square minus the 6 x 6 square in its upper-right corner.
    expected = (100 * 5 - 36 * 7) / 64
    assert L_SHAPE.center == pytest.approx((expected, expected))
    assert L_SHAPE.area() == 64


def test_to_json_matches_run_json_format():
    assert Circle(330, 320, 5).to_json() == {"shape": "circle", "center": [330.0, 320.0],
                                             "radius": 5.0}
    assert Rect(1, 2, 3, 4).to_json() == {"shape": "rect", "min": [1.0, 2.0], "max": [3.0, 4.0]}
    assert Polygon([(0, 0), (1, 0), (0, 1)]).to_json() == {
        "shape": "polygon", "points": [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]}
    r = Region("alpha", "food", "alpha", Circle(330, 320, 5))
    assert list(r.to_json()) == ["name", "kind", "label", "shape", "center", "radius"]
    assert json.loads(json.dumps(Region("nest", "region", None, Rect(0, 0, 1, 1)).to_json())) == {
        "name": "nest", "kind": "region", "label": None, "shape": "rect",
        "min": [0.0, 0.0], "max": [1.0, 1.0]}


@pytest.mark.parametrize(
    "make",
    [lambda: Circle(0, 0, -1), lambda: Rect(5, 0, 1, 1), lambda: Polygon([(0, 0), (1, 1)]),
     lambda: Circle(math.nan, 0, 1)],
)
def test_bad_shapes_rejected(make):
    with pytest.raises(ValueError):
        make()


def test_points_must_be_m_by_2():
    with pytest.raises(ValueError, match=r"shape \(M, 2\)"):
        Circle(0, 0, 1).contains(np.zeros(4))


@pytest.mark.parametrize("shape", [Circle(50, 30, 12), Rect(10, 10, 45, 30), L_SHAPE])
def test_nodes_inside_agrees_with_contains(shape):
    g = Grid(100, 60, 2)
    mask = shape.nodes_inside(g)
    assert mask.shape == g.shape and mask.dtype == bool
    x, y = g.nodes()
    for j, i in [(0, 0), (15, 25), (5, 5), (3, 2)]:
        assert mask[j, i] == shape.contains([[x[j, i], y[j, i]]])[0]
    assert mask.sum() == shape.contains(np.column_stack([x.ravel(), y.ravel()])).sum() > 0
    assert Region("n", "region", None, shape).nodes_inside(g).sum() == mask.sum()


@pytest.mark.parametrize("shape", [Circle(50, 30, 12), Rect(10, 10, 45, 30), L_SHAPE])
def test_sample_points_inside_is_uniform_and_seeded(shape):
    pts = shape.sample_points_inside(np.random.default_rng(0), 20_000)
    assert pts.shape == (20_000, 2) and shape.contains(pts).all()
    np.testing.assert_array_equal(pts, shape.sample_points_inside(np.random.default_rng(0),
                                                                  20_000))
    np.testing.assert_allclose(pts.mean(axis=0), shape.center, atol=0.02 * math.sqrt(
        shape.area()))
    assert shape.sample_points_inside(np.random.default_rng(0), 0).shape == (0, 2)


def test_sample_points_inside_a_degenerate_shape():
    assert (Circle(3, 4, 0).sample_points_inside(np.random.default_rng(0), 5) == [3, 4]).all()
    with pytest.raises(ValueError, match="no area"):
        Polygon([(0, 0), (1, 1), (2, 2)]).sample_points_inside(np.random.default_rng(0), 5)


@PROPS
@given(st.lists(st.one_of(circles, rects), min_size=1, max_size=4), points, points)
def test_block_moves_never_ends_inside_an_obstacle(obstacles, old, new):
    m = min(len(old), len(new))
    old, new = old[:m], new[:m]
    outside = ~np.any([o.contains(old) for o in obstacles], axis=0)
    assume(outside.any())
    old, new = old[outside], new[outside]
    moved = block_moves(old, new, obstacles)
    for o in obstacles:
        assert not o.contains(moved).any()
    kept = (moved == new).all(axis=1)
    stayed = (moved == old).all(axis=1)
    assert (kept | stayed).all()
    free = ~np.any([o.contains(new) for o in obstacles], axis=0)
    assert kept[free].all()  # moves that end outside are never blocked


def test_block_moves_accepts_regions_and_checks_shapes():
    wall = Region("wall", "obstacle", None, Rect(4, 0, 6, 10))
    old = np.array([[0.0, 5.0], [0.0, 5.0]])
    new = np.array([[5.0, 5.0], [3.0, 5.0]])
    np.testing.assert_array_equal(block_moves(old, new, [wall]), [[0, 5], [3, 5]])
    np.testing.assert_array_equal(block_moves(old, new, []), new)
    with pytest.raises(ValueError, match="differ in shape"):
        block_moves(old, new[:1], [wall])


# ---- wrap-around worlds: a region repeats a whole world width and height away ----

triangles = st.lists(st.tuples(st.floats(-40, 180), st.floats(-40, 180)), min_size=3,
                     max_size=3).map(Polygon)
world_sizes = st.tuples(st.floats(50, 150), st.floats(50, 150))


def _every_copy(shape, pts, box, measure):
    """``(S, M)`` a measure taken against every copy of the shape up to four worlds away
    (the slow oracle: far beyond any copy that can be nearest for these shapes)."""
    w, h = box
    return np.array([measure(shape, pts + [k * w, j * h])
                     for k in range(-4, 5) for j in range(-4, 5)])


@PROPS
@given(st.one_of(circles, rects, triangles), world_sizes,
       st.lists(st.tuples(st.floats(0, 1, exclude_max=True),
                          st.floats(0, 1, exclude_max=True)), min_size=1, max_size=30),
       st.integers(-2, 2), st.integers(-2, 2))
def test_wrapped_distance_is_the_distance_to_the_nearest_copy(shape, box, unit, k, j):
    """In a wrap-around world an agent's distance to a region is the distance to the
    nearest copy of it, the same from any of the agent's own copies a world away."""
    pts = np.array(unit) * box
    brute = _every_copy(shape, pts, box, lambda s, p: s.distance(p)).min(axis=0)
    d = shape.distance_around(pts, box)
    np.testing.assert_allclose(d, brute, rtol=1e-9, atol=1e-9)
    moved = pts + [k * box[0], j * box[1]]
    np.testing.assert_allclose(shape.distance_around(moved, box), d, rtol=1e-9, atol=1e-9)
    inside = _every_copy(shape, pts, box, lambda s, p: s.contains(p)).any(axis=0)
    clear = np.abs(brute) > 1e-9   # on an outline, rounding decides
    np.testing.assert_array_equal(shape.contains_around(pts, box)[clear], inside[clear])


def test_wrapped_queries_without_a_box_are_the_plain_ones():
    pts = np.array([[2.0, 50.0], [99.0, 1.0]])
    for shape in (Circle(98, 50, 1), Rect(90, 40, 99, 60), L_SHAPE):
        np.testing.assert_array_equal(shape.distance_around(pts, None), shape.distance(pts))
        np.testing.assert_array_equal(shape.contains_around(pts, None), shape.contains(pts))


def test_an_obstacle_crossing_an_edge_blocks_across_the_other():
    wall = Region("wall", "obstacle", None, Rect(98, 0, 103, 100))
    old = np.array([[10.0, 5.0], [10.0, 5.0]])
    new = np.array([[2.0, 5.0], [4.0, 5.0]])
    np.testing.assert_array_equal(block_moves(old, new, [wall], (100.0, 100.0)),
                                  [[10, 5], [4, 5]])
    np.testing.assert_array_equal(block_moves(old, new, [wall]), new)   # walls: no copy
