"""The viewer draws the MAS environment: grid nodes (refined ones too) and vector arrows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pygame")

from swarmdsl.compiler import compile_file  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402
from swarmdsl.viz.frames import FrameRenderer, RenderOptions  # noqa: E402
from swarmdsl.viz.layers import ARROW, GRID_POINT  # noqa: E402

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
BARE = {"show_field": False, "show_regions": False, "show_legend": False,
        "show_tick": False}


def _frame(**opts):
    sim = Simulation(compile_file(PROGRAMS / "mas_environment.swarm"), 0)
    sim.agents.cols["pos"][:] = 1e9    # agents off the picture: only the grid is drawn
    snap = sim.snapshot()
    return snap, FrameRenderer(416, 416).render(snap, RenderOptions(**BARE, **opts))


def _mask(img, colour):
    return (img == np.asarray(colour, np.uint8)).all(axis=2)


def test_grid_nodes_are_drawn_when_asked_and_denser_where_refined(backend):
    snap, img = _frame(show_grid_points=True, show_vectors=False)
    dots = _mask(img, GRID_POINT)
    assert dots.sum() > 0.8 * len(snap.grid_points)
    h = img.shape[0]
    upper_left = dots[: h // 4, : h // 4].sum()      # refined corner (y flipped)
    centre = dots[3 * h // 8: 5 * h // 8, 3 * h // 8: 5 * h // 8].sum()
    assert upper_left > 8 * centre > 0
    _snap, plain = _frame(show_grid_points=False, show_vectors=False)
    assert not _mask(plain, GRID_POINT).any()


def test_a_uniform_grid_draws_its_nodes_from_its_axes(backend):
    from swarmdsl.compiler import compile_source

    src = "world { size 100 x 100; grid 10 }\nfield f { }\nagent a { count 1; status s { } }"
    snap = Simulation(compile_source(src, "u.swarm"), 0).snapshot()
    assert snap.grid_points is None
    img = FrameRenderer(208, 208).render(snap, RenderOptions(**BARE, show_grid_points=True))
    assert _mask(img, GRID_POINT).sum() >= 100


def test_vector_twins_are_drawn_as_arrows(backend):
    snap, img = _frame(show_vectors=True)
    assert "current" in snap.vectors
    assert _mask(img, ARROW).sum() > 500
    _snap, off = _frame(show_vectors=False)
    assert not _mask(off, ARROW).any()
