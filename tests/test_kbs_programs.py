"""The KBS experiments (docs/experiments.md: the 1D spring and the 2D matrix) run headless
and show what they must, with their params changed as a user would."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from swarmdsl.compiler import compile_file
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"


def _sim(name: str, seed: int = 0, backend: str | None = None, **overrides) -> Simulation:
    prog = compile_file(PROGRAMS / name, {k: str(v) for k, v in overrides.items()})
    return Simulation(prog, seed, backend=backend)


def _status(sim) -> np.ndarray:
    names = np.array(sim.program.status_display)
    return names[sim.agents.cols["status"]]


@pytest.fixture(scope="module")
def spring(backend):
    sim = _sim("spring1d.swarm", backend=backend)
    labelled = []          # (tick, sorted ids of labelled extensions)
    for _ in range(300):
        sim.step()
        labelled.append(np.flatnonzero(_status(sim) == "extension.labeled").tolist())
    return sim, labelled


def test_spring_ends_equally_spaced_38_apart(spring):
    sim, _ = spring
    cols = sim.agents.cols
    order = np.argsort(cols["pos"][:, 0])
    true_x = cols["pos"][order, 0] - sim.program.params["x0"]
    believed_x = cols["believed"][order, 0]
    want = np.array([0, 38, 76, 114, 152, 190])
    step = sim.program.params["step"]
    assert np.all(np.abs(true_x - want) <= step)
    assert np.all(np.abs(believed_x - want) <= step)
    assert np.allclose(cols["pos"][:, 1], sim.program.params["y0"])


def test_spring_labels_and_ids_left_to_right(spring):
    sim, labelled = spring
    cols = sim.agents.cols
    order = np.argsort(cols["pos"][:, 0])
    assert cols["lid"][order].tolist() == [0, 1, 2, 3, 4, 5]
    ext = order[1:5]                                  # the four extensions, left to right
    first_seen = [next(t for t, rows in enumerate(labelled) if r in rows) for r in ext]
    assert np.all(np.diff(first_seen) > 0)          # one at a time, left to right


def test_spring_with_motion_noise_still_spreads(spring):
    sim = _sim("spring1d.swarm", seed=1, turn_noise=0.05, pace_noise=0.05)
    sim.run(300)
    x = np.sort(sim.agents.cols["pos"][:, 0]) - sim.program.params["x0"]
    assert np.all(np.abs(np.diff(x) - 38) < 8)


@pytest.fixture(scope="module")
def matrix(backend):
    sim = _sim("matrix2d.swarm", backend=backend)
    cell = sim.program.info.kind("cell").index
    rows = np.flatnonzero(sim.agents.cols["kind"] == cell)
    content_at = np.full(rows.size, -1)
    for t in range(40):
        sim.step()
        st = _status(sim)[rows]
        content_at[(content_at < 0) & (st == "cell.content")] = t
    seeking = {"believed": sim.agents.cols["believed"][rows].copy(),
               "pos": sim.agents.cols["pos"][rows].copy(), "content_at": content_at}
    sim.run(260)
    return sim, rows, seeking


def test_matrix_every_inner_agent_localises_exactly(matrix):
    sim, rows, seeking = matrix
    p = sim.program.params
    assert np.all(seeking["content_at"] >= 0)
    offset = np.array([p["ox"], p["oy"]])
    assert np.allclose(seeking["believed"], seeking["pos"] - offset, atol=1e-9)


def test_matrix_corners_resolve_first(matrix):
    sim, rows, seeking = matrix
    p = sim.program.params
    grid = np.round((seeking["pos"] - [p["ox"], p["oy"]]) / p["s0"]).astype(int)
    corner = (np.isin(grid[:, 0], [0, p["cols"] - 1]) &
              np.isin(grid[:, 1], [0, p["rows"] - 1]))
    t = seeking["content_at"]
    assert t[corner].max() < t[~corner].min()


def test_matrix_stretch_spreads_rows_and_narrows_the_block(matrix):
    sim, rows, _ = matrix
    p = sim.program.params
    cols = sim.agents.cols
    assert (_status(sim)[rows] == "cell.content").all()          # all at rest again
    truth = cols["pos"][rows] - [p["ox"], p["oy"]]
    believed = cols["believed"][rows]
    assert np.allclose(believed, truth, atol=1e-6)      # no motion noise: odometry exact
    row = np.round(truth[:, 1] / p["s0"]).astype(int)   # moved at most shift/s0 < 0.5 rows
    span = (p["rows"] - 1) * p["s0"] + p["shift"]
    assert np.allclose(truth[row == p["rows"] - 1, 1], span, atol=p["tol"])   # movers
    assert np.allclose(truth[row == 0, 1], 0)                                  # bottom
    middle = (row > 0) & (row < p["rows"] - 1)
    for r in (1, 2):                                    # rows spread evenly toward movers
        assert np.allclose(truth[row == r, 1], r * span / 3, atol=0.05)
    sh = p["s0"] ** 2 / (span / 3)                      # area kept: s0^2 / sv
    widths = [np.ptp(truth[row == r, 0]) for r in (1, 2)]
    assert np.allclose(widths, 2 * sh, atol=0.1)
    assert max(widths) < (p["cols"] - 1) * p["s0"] - 5  # narrower than the rest width 80
    assert np.allclose(truth[middle][:, 0].reshape(2, -1).mean(axis=1), 40, atol=0.05)


def test_viewer_draws_leds_links_and_beliefs_of_a_kbs_run():
    from swarmdsl.viz.frames import FrameRenderer, RenderOptions

    sim = _sim("matrix2d.swarm", turn_noise=0.2, pace_noise=0.2)
    sim.run(80)                                 # localised, top row moved with noise
    snap = sim.snapshot()
    n = sim.agents.n
    assert snap.led.shape == (n, 3) and snap.led.dtype == np.uint8
    assert snap.believed.shape == (n, 2) and np.isfinite(snap.believed).all()
    assert snap.links.shape[1] == 2 and len(snap.links) > n      # the lattice talks
    assert np.abs(snap.believed - snap.pos).max() > 0.01         # noisy odometry drifts
    renderer = FrameRenderer(360, 440)
    plain = renderer.render(snap, RenderOptions(show_links=False, show_believed=False))
    links = renderer.render(snap, RenderOptions(show_links=True, show_believed=False))
    belief = renderer.render(snap, RenderOptions(show_links=False, show_believed=True))
    assert (plain != links).any() and (plain != belief).any()
    by_status = renderer.render(snap, RenderOptions(use_led=False))
    assert (by_status != plain).any()


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
def test_matrix_with_vibration_noise_still_narrows(backend, seed):
    sim = _sim("matrix2d.swarm", seed=seed, turn_noise=0.1, pace_noise=0.1)
    sim.run(400)
    p = sim.program.params
    rows = np.flatnonzero(sim.agents.cols["kind"] == sim.program.info.kind("cell").index)
    truth = sim.agents.cols["pos"][rows] - [p["ox"], p["oy"]]
    row = np.round(truth[:, 1] / p["s0"]).astype(int)
    for r in (1, 2):
        assert np.ptp(truth[row == r, 0]) < 76                 # rest width 80, ideal 73.85
        assert abs(truth[row == r, 1].mean() - r * 130 / 3) < 0.5
    assert np.abs(sim.agents.cols["believed"][rows] - truth).max() < 3   # odometry drift


def test_spring_on_a_longer_span_settles_equally_spaced(backend):
    """The world used to be a fixed 240 x 80, so `--set span=250` was refused (the end
    robot outside the world); now the world grows with the chain."""
    sim = _sim("spring1d.swarm", span=250)
    sim.run(600)
    x = np.sort(sim.agents.cols["believed"][:, 0])
    np.testing.assert_allclose(x, [0, 50, 100, 150, 200, 250], atol=1.0)


def test_spring_with_six_extensions_labels_and_spreads_them_all(backend):
    """The extension count was fixed at 4 (and the end's id at 5): a user could not add
    robots with `--set`; now `extensions` sets both, and the span grows with it."""
    sim = _sim("spring1d.swarm", extensions=6)
    sim.run(600)
    order = np.argsort(sim.agents.cols["believed"][:, 0])
    assert sim.agents.cols["lid"][order].tolist() == list(range(8))
    x = sim.agents.cols["believed"][order, 0]
    np.testing.assert_allclose(x, np.arange(8) * 250 / 7, atol=1.0)


def test_matrix_with_four_columns_comes_to_rest(backend):
    """With `--set cols=4` the middle rows used to swing side to side for ever (each
    robot jumping to a target made from one-tick-old positions); now they come to rest,
    evenly spaced along the row."""
    sim = _sim("matrix2d.swarm", cols=4)
    sim.run(250)
    cells = np.flatnonzero(sim.agents.cols["kind"] == sim.program.info.kind("cell").index)
    before = sim.agents.cols["believed"][cells].copy()
    sim.run(50)
    after = sim.agents.cols["believed"][cells]
    assert np.abs(after - before).max() < 0.05
    middle = after[(after[:, 1] > 20) & (after[:, 1] < 110)]
    for y in (43.33, 86.67):
        row = np.sort(middle[np.abs(middle[:, 1] - y) < 1, 0])
        assert row.size == 4
        inner_gap = row[2] - row[1]
        assert abs((row[1] - row[0]) - (row[3] - row[2])) < 0.1 and inner_gap < 40
