"""Trails in a wrap-around world: a trail crossing an edge links the regions on either
side, a region beyond an edge owns its copy's nodes, and sliding the whole picture
around the torus changes nothing. Walled worlds (and run folders whose run.json does
not say the world's edges) read as before."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from swarmdsl.analysis.trails import (
    first_direct_link,
    first_linked,
    linked_pairs,
    region_from_json,
    region_nodes,
    trail_labels,
    trail_steps,
    world_box,
)
from swarmdsl.compiler import compile_source
from swarmdsl.runtime.regions import Circle, Polygon, Rect, Region
from swarmdsl.runtime.runner import Run
from swarmdsl.runtime.spool import open_fields

# One ant walks right along y = 5 from x = 15, laying a trail across the right edge of
# a 20 x 10 world: the food (x = 17) and the nest (x = 2) are 15 apart inside the
# world, 5 apart across the edge.
PROGRAM = """world {{ size 20 x 10; grid 1; edges {edges} }}
field trail {{ decay 0 }}
nest home = circle(2, 5, 0.25)
food far = {far}
agent ant {{
  count 1
  place (15, 5)
  velocity (1, 0)
  status walking {{ deposit(trail, 1) }}
}}
"""
FAR = "circle(17, 5, 0.25)"
BEYOND = "circle(37, 15, 0.25)"    # wholly beyond the corner: its copy is FAR


def _run(tmp_path, name: str, far: str = FAR, steps: int = 12, backend=None):
    out = tmp_path / name
    Run(compile_source(PROGRAM.format(edges="wrap", far=far), f"{name}.swarm"),
        seed=0, steps=steps, out=out, backend=backend).execute()
    return out


def _rewrite_world(src, dst, change):
    """A copy of run folder `src` whose run.json's world is `change`d: the same
    recorded fields read with other edges."""
    shutil.copytree(src, dst)
    meta = json.loads((dst / "run.json").read_text())
    change(meta["world"])
    (dst / "run.json").write_text(json.dumps(meta))
    return dst


@pytest.fixture(scope="module")
def wrapped(tmp_path_factory, backend):
    return _run(tmp_path_factory.mktemp("trails"), "wrapped", backend=backend)


def test_a_trail_across_the_edge_links_regions_far_apart_inside_the_world(wrapped, tmp_path):
    with open_fields(wrapped) as data:
        row = data["trail"][-1][5]
    assert row[15:].all() and row[:3].all() and not row[8:15].any()   # across x = 0
    # at tick t the ant has laid on x = 15 .. 15 + t - 1: the nest's node x = 1 at 7
    assert first_linked(wrapped, field="trail") == {("home", "far"): 7}
    # the straight gap, the short way: far's node 18 -> 19 -> 0 -> the nest's node 1
    # (a region's own nodes are passable), laid up to x = 0 by tick 6
    assert first_direct_link(wrapped, "home", "far", field="trail") == 6

    walled = _rewrite_world(wrapped, tmp_path / "walled",
                            lambda w: w.update(edges="wall"))
    assert first_linked(walled, field="trail") == {("home", "far"): None}
    assert first_direct_link(walled, "home", "far", field="trail") is None


def test_a_run_json_without_size_or_edges_reads_as_walled(wrapped, tmp_path):
    for key in ("edges", "size"):
        old = _rewrite_world(wrapped, tmp_path / f"no-{key}", lambda w, k=key: w.pop(k))
        assert first_linked(old, field="trail") == {("home", "far"): None}


def test_a_region_wholly_beyond_the_edge_owns_its_copys_nodes(backend, wrapped, tmp_path):
    beyond = _run(tmp_path, "beyond", far=BEYOND)
    world = json.loads((beyond / "run.json").read_text())["world"]
    regions = world["regions"]
    assert regions[1]["center"] == [37.0, 15.0]      # recorded as declared
    with open_fields(beyond) as a, open_fields(wrapped) as b:
        assert np.array_equal(a["trail"], b["trail"])
        gx, gy = a["grid_x"], a["grid_y"]
    box = world_box(world, gx, gy)
    assert box == (20.0, 10.0)
    there = region_nodes(region_from_json(regions[1]), gx, gy, box)
    copy = region_nodes(Region("far", "food", "far", Circle(17, 5, 0.25)), gx, gy, box)
    assert np.array_equal(there, copy)
    assert np.argwhere(there).tolist() == [[4, 17], [5, 16], [5, 17], [5, 18], [6, 17]]
    assert not region_nodes(region_from_json(regions[1]), gx, gy).any()   # walls: none
    assert first_linked(beyond, field="trail") == first_linked(wrapped, field="trail")
    assert (first_direct_link(beyond, "home", "far", field="trail")
            == first_direct_link(wrapped, "home", "far", field="trail"))


def test_corners_and_sides_meet_across_the_edges():
    above = np.zeros((4, 6), bool)
    above[0, 0] = above[3, 5] = True      # diagonal neighbours across the corner
    above[1, 0] = above[2, 5] = True      # diagonal neighbours across the left edge
    above[0, 3] = above[3, 2] = True      # diagonal neighbours across the bottom edge
    walled, wrapped = trail_labels(above), trail_labels(above, wrap=True)
    assert len(np.unique(walled[above])) == 4          # the pairs on one side touch
    assert len(np.unique(wrapped[above])) == 2
    assert wrapped[0, 0] == wrapped[3, 5] == wrapped[2, 5] == wrapped[1, 0]
    assert wrapped[0, 3] == wrapped[3, 2] != wrapped[0, 0]
    a, b = np.zeros_like(above), np.zeros_like(above)
    a[0, 3], b[3, 2] = True, True
    assert trail_steps(above, 0.5, a, b) is None
    assert trail_steps(above, 0.5, a, b, wrap=True) == 1
    a[:], b[:] = False, False
    a[1, 0], b[3, 5] = True, True
    assert trail_steps(above, 0.5, a, b, wrap=True) == 2   # (1,0) -> (0,0) -> (3,5)


def test_a_recorded_grid_that_does_not_wrap_is_refused():
    gx, gy = np.arange(21.0), np.arange(11.0)    # a walled layout: a node at x = W
    with pytest.raises(ValueError, match="does not wrap around the 20 x 10 world"):
        world_box({"size": [20, 10], "edges": "wrap"}, gx, gy)
    assert world_box({"size": [20, 10], "edges": "wall"}, gx, gy) is None
    assert world_box({"size": [20, 10], "edges": "repel"}, gx, gy) is None


# ---- the torus has no special place -------------------------------------------------

@st.composite
def shapes(draw, w: float, h: float):
    """A small shape anywhere from a world before the world to a world past it, its
    numbers in quarters (exact in floats, so sliding it moves it exactly); a triangle's
    corners in odd eighths, so no node is exactly one spacing from a corner or from an
    upright side (see `_no_ties`)."""
    kind = draw(st.sampled_from(["circle", "rect", "polygon"]))
    x = draw(st.integers(-4 * int(w), 8 * int(w))) / 4
    y = draw(st.integers(-4 * int(h), 8 * int(h))) / 4
    a, b = (draw(st.integers(0, 12)) / 4 for _ in range(2))
    if kind == "circle":
        return Circle(x, y, a)
    if kind == "rect":
        return Rect(x, y, x + a, y + b)
    x, y = x + 1 / 8, y + 1 / 8
    return Polygon(((x, y), (x + a + 0.5, y), (x, y + b + 0.5)))


def moved(shape, dx: float, dy: float):
    if isinstance(shape, Circle):
        return Circle(shape.cx + dx, shape.cy + dy, shape.r)
    if isinstance(shape, Rect):
        return Rect(shape.x0 + dx, shape.y0 + dy, shape.x1 + dx, shape.y1 + dy)
    return Polygon(tuple((x + dx, y + dy) for x, y in shape.points))


@st.composite
def pictures(draw):
    nx, ny = draw(st.integers(3, 9)), draw(st.integers(3, 9))
    spacing = draw(st.sampled_from([0.5, 1.0, 2.0]))
    w, h = nx * spacing, ny * spacing
    values = draw(arrays(np.int64, (ny, nx), elements=st.integers(0, 9)))
    threshold = draw(st.sampled_from([4.5, 6.5, 7.5]))   # 50, 30, 20 % above
    regions = [Region(f"r{k}", "food", None, draw(shapes(w, h)))
               for k in range(draw(st.integers(2, 4)))]
    shift = (draw(st.integers(-2 * nx, 2 * nx)), draw(st.integers(-2 * ny, 2 * ny)))
    return spacing, values, threshold, regions, shift


def _no_ties(spacing, shape_of, regions, box) -> bool:
    """No node lies exactly one spacing from a triangle's slanted side. There the
    rule "within one spacing" is a rounding tie (a triangle's distance is computed
    through a division, and numpy may round it an ulp apart for the same point in
    another batch), walls or not; circles and rects measure exactly."""
    ny, nx = shape_of
    x, y = np.meshgrid(np.arange(nx) * spacing, np.arange(ny) * spacing)
    nodes = np.stack([x.ravel(), y.ravel()], axis=1)
    return all(not np.isclose(r.distance(nodes, box), spacing, rtol=0, atol=1e-9).any()
               for r in regions if isinstance(r.shape, Polygon))


def _read(spacing, values, threshold, regions, wrap: bool):
    ny, nx = values.shape
    gx, gy = np.arange(nx) * spacing, np.arange(ny) * spacing
    box = (nx * spacing, ny * spacing) if wrap else None
    masks = {r.name: region_nodes(r, gx, gy, box) for r in regions}
    pairs = [(a.name, b.name) for i, a in enumerate(regions) for b in regions[i + 1:]]
    linked = linked_pairs(values, masks, threshold, pairs, wrap=wrap)
    steps = {(a, b): trail_steps(values, threshold, masks[a], masks[b], wrap=wrap)
             for a, b in pairs}
    return masks, linked, steps


@settings(max_examples=150, deadline=None)
@given(pictures())
def test_sliding_the_picture_around_the_torus_changes_nothing(picture):
    """Field values and regions moved together by whole grid cells (regions may end up
    beyond the edge: they stand for their copies) link the same pairs in the same
    number of steps, and each region owns its old nodes moved along."""
    spacing, values, threshold, regions, (i, j) = picture
    ny, nx = values.shape
    assume(_no_ties(spacing, values.shape, regions, (nx * spacing, ny * spacing)))
    masks, linked, steps = _read(spacing, values, threshold, regions, wrap=True)
    slid = [Region(r.name, r.kind, r.label, moved(r.shape, i * spacing, j * spacing))
            for r in regions]
    slid_values = np.roll(values, (j, i), axis=(0, 1))
    masks2, linked2, steps2 = _read(spacing, slid_values, threshold, slid, wrap=True)
    for name, mask in masks.items():
        assert np.array_equal(masks2[name], np.roll(mask, (j, i), axis=(0, 1))), name
    assert linked2 == linked
    assert steps2 == steps


@settings(max_examples=100, deadline=None)
@given(pictures())
def test_wrapping_only_adds_links_and_shortcuts(picture):
    """The torus has every neighbour and region node the walled grid has, and more:
    whatever walls link, wrapping links, in at most as many steps."""
    spacing, values, threshold, regions, _shift = picture
    masks, linked, steps = _read(spacing, values, threshold, regions, wrap=False)
    masks2, linked2, steps2 = _read(spacing, values, threshold, regions, wrap=True)
    for name, mask in masks.items():
        assert not (mask & ~masks2[name]).any()
    for pair, walled in linked.items():
        assert linked2[pair] or not walled
        assert steps[pair] is None or steps2[pair] <= steps[pair]
