"""Frame rendering, video recording and the viewer loop, all headless (SDL dummy)."""

import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import gc  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from conftest import shipped  # noqa: E402

import swarmdsl  # noqa: E402
from swarmdsl import SwarmOptionError, viz  # noqa: E402
from swarmdsl.compiler.errors import SwarmError  # noqa: E402
from swarmdsl.runtime.snapshot import Snapshot  # noqa: E402
from swarmdsl.viz import (  # noqa: E402
    FrameRenderer,
    RenderOptions,
    VideoWriter,
    display_available,
    fit_size,
    legend_entries,
    run_viewer,
)
from swarmdsl.viz.palette import BACKGROUND, PALETTE  # noqa: E402
from swarmdsl.viz.viewer import ViewState  # noqa: E402

pygame = pytest.importorskip("pygame")

NAMES = ["seeking", "fooded", "foodless"]
BARE = dict(show_legend=False, show_tick=False, show_field=False, show_regions=False)


def make_snapshot(pos, heading=None, status=None, *, world=(100.0, 100.0), tick=0, **extra):
    pos = np.asarray(pos, dtype=np.float64).reshape(-1, 2)
    n = len(pos)
    return Snapshot(
        tick=tick,
        world_size=world,
        pos=pos,
        heading=np.zeros(n) if heading is None else np.asarray(heading, dtype=np.float64),
        status=np.zeros(n, np.int32) if status is None else np.asarray(status, np.int32),
        kind=np.zeros(n, np.int32),
        ids=np.arange(n, dtype=np.int64),
        status_names=list(NAMES),
        kind_names=["ant"],
        **extra,
    )


def expected_pixel(x, y, world=(100.0, 100.0), size=(208, 208)):
    """Where the renderer should put world point (x, y): aspect kept, y flipped."""
    (ww, wh), (w, h) = world, size
    scale = min((w - 4) / ww, (h - 4) / wh)
    ox, oy = (w - ww * scale) / 2, (h - wh * scale) / 2
    return ox + x * scale, oy + (wh - y) * scale


def colour_mask(img, colour):
    return (img == np.asarray(colour, np.uint8)).all(axis=2)


# -- frames ---------------------------------------------------------------------------


def test_frame_has_requested_shape_and_dtype():
    img = FrameRenderer(96, 64).render(make_snapshot([[10, 10]]))
    assert img.shape == (64, 96, 3)
    assert img.dtype == np.uint8


def test_bad_frame_size_is_a_swarm_error():
    with pytest.raises(SwarmError, match="width"):
        FrameRenderer(8, 64)


@pytest.mark.parametrize("splat_above", [3000, 0], ids=["polygons", "splats"])
def test_agent_marker_lands_at_its_world_position_with_y_flipped(splat_above):
    x, y = 25.0, 80.0                 # high y: must land in the top half of the image
    img = FrameRenderer(208, 208).render(
        make_snapshot([[x, y]], status=[1]),
        RenderOptions(marker_px=10, splat_above=splat_above, **BARE))
    mask = colour_mask(img, PALETTE[1])
    rows, cols = np.nonzero(mask)
    assert len(rows) >= 3
    ex, ey = expected_pixel(x, y)
    assert mask[int(ey), int(ex)]                       # the agent's own pixel
    assert abs(cols.mean() - ex) <= 3 and abs(rows.mean() - ey) <= 3
    # ...and nowhere else: every marker pixel is within the marker's reach.
    assert np.hypot(cols - ex, rows - ey).max() <= 10
    assert rows.max() < 104                             # top half: y was flipped


@pytest.mark.parametrize("splat_above", [3000, 0], ids=["polygons", "splats"])
@pytest.mark.parametrize("heading, axis, sign", [
    (0.0, "x", +1), (math.pi, "x", -1), (math.pi / 2, "y", -1), (-math.pi / 2, "y", +1),
])
def test_marker_points_along_heading(splat_above, heading, axis, sign):
    img = FrameRenderer(208, 208).render(
        make_snapshot([[50, 50]], heading=[heading]),
        RenderOptions(marker_px=14, splat_above=splat_above, **BARE))
    rows, cols = np.nonzero(colour_mask(img, PALETTE[0]))
    ex, ey = expected_pixel(50, 50)
    coords, centre = (cols, ex) if axis == "x" else (rows, ey)
    ahead = (coords - centre).max() if sign > 0 else (centre - coords).max()
    behind = (centre - coords).max() if sign > 0 else (coords - centre).max()
    assert ahead > behind           # the nose sticks out further than the tail


def test_two_statuses_get_two_distinct_palette_colours():
    snap = make_snapshot([[20, 20], [80, 80]], status=[0, 2])
    img = FrameRenderer(208, 208).render(snap, RenderOptions(marker_px=10, **BARE))
    for (x, y), s in (((20, 20), 0), ((80, 80), 2)):
        ex, ey = expected_pixel(x, y)
        assert tuple(img[int(ey), int(ex)]) == PALETTE[s]
    assert PALETTE[0] != PALETTE[2]
    assert not colour_mask(img, PALETTE[1]).any()


def test_led_colour_replaces_status_colour_only_when_enabled():
    led = np.array([[250, 10, 200]], np.uint8)
    snap = make_snapshot([[50, 50]], led=led)
    ex, ey = expected_pixel(50, 50)
    renderer = FrameRenderer(208, 208)
    on = renderer.render(snap, RenderOptions(marker_px=10, use_led=True, **BARE))
    off = renderer.render(snap, RenderOptions(marker_px=10, use_led=False, **BARE))
    assert tuple(on[int(ey), int(ex)]) == (250, 10, 200)
    assert tuple(off[int(ey), int(ex)]) == PALETTE[0]


def test_legend_entries_count_live_statuses():
    snap = make_snapshot(np.full((5, 2), 50.0), status=[0, 0, 2, 2, 2])
    entries = legend_entries(snap)
    assert [(name, count) for name, count, _ in entries] == [
        ("seeking", 2), ("fooded", 0), ("foodless", 3)]
    assert [colour for _, _, colour in entries] == list(PALETTE[:3])


def test_legend_pixels_change_when_counts_change():
    pos = [[90, 10], [90, 15], [85, 10], [85, 15]]      # bottom right, clear of the legend
    renderer = FrameRenderer(320, 320)
    opts = RenderOptions(show_field=False)
    a = renderer.render(make_snapshot(pos, status=[0, 0, 0, 1]), opts)
    x, y, w, h = renderer.legend_rect
    b = renderer.render(make_snapshot(pos, status=[0, 1, 1, 1]), opts)
    assert renderer.legend_rect[:2] == (x, y)
    assert not np.array_equal(a[y:y + h, x:x + w], b[y:y + h, x:x + w])
    # Besides the recoloured agents, only the legend changed.
    diff = (a != b).any(axis=2)
    diff[y:y + h, x:x + w] = False
    rows, cols = np.nonzero(diff)
    assert len(rows) and rows.min() > 200 and cols.min() > 200


def test_tick_counter_changes_with_tick():
    renderer = FrameRenderer(320, 320)
    a = renderer.render(make_snapshot([[50, 50]], tick=1))
    b = renderer.render(make_snapshot([[50, 50]], tick=9876))
    diff = (a != b).any(axis=2)
    rows, cols = np.nonzero(diff)
    assert diff.any()
    assert rows.max() < 40 and cols.min() > 160          # only the top-right counter


def hot_field_snapshot():
    gx = np.linspace(0, 100, 11)
    gy = np.linspace(0, 100, 11)
    values = np.zeros((11, 11))
    values[8, 3] = 5.0                                    # node at x=30, y=80
    return make_snapshot([[90, 10]], fields={"pheromone": values, "other": values.T},
                         grid_x=gx, grid_y=gy)


def test_heatmap_toggle_changes_pixels_under_a_hot_cell():
    snap = hot_field_snapshot()
    renderer = FrameRenderer(208, 208)
    ex, ey = expected_pixel(30, 80)
    cold_x, cold_y = expected_pixel(70, 30)
    bare = {k: v for k, v in BARE.items() if k != "show_field"}
    on = renderer.render(snap, RenderOptions(show_field=True, field_alpha=1.0, **bare))
    off = renderer.render(snap, RenderOptions(show_field=False, **bare))
    hot = on[int(ey), int(ex)].astype(int)
    assert tuple(off[int(ey), int(ex)]) == BACKGROUND
    assert tuple(hot) != BACKGROUND
    assert hot.sum() > on[int(cold_y), int(cold_x)].astype(int).sum() + 300


def test_choosing_a_field_and_unknown_field_error():
    snap = hot_field_snapshot()
    renderer = FrameRenderer(208, 208)
    bare = {k: v for k, v in BARE.items() if k != "show_field"}
    first = renderer.render(snap, RenderOptions(**bare))
    other = renderer.render(snap, RenderOptions(field="other", **bare))
    assert not np.array_equal(first, other)
    with pytest.raises(SwarmError, match="pheromone") as info:
        renderer.render(snap, RenderOptions(field="pheromon", **bare))
    assert info.value.hint == "did you mean 'pheromone'?"


def test_regions_are_outlined_and_bad_shapes_rejected():
    regions = [
        {"name": "nest", "kind": "nest", "label": "nest", "shape": "circle",
         "center": [50, 50], "radius": 20},
        {"name": "alpha", "kind": "food", "label": "alpha", "shape": "rect",
         "min": [5, 5], "max": [25, 25]},
        {"name": "wall", "kind": "region", "label": None, "shape": "polygon",
         "points": [[70, 70], [95, 70], [95, 95]]},
    ]
    snap = make_snapshot(np.zeros((0, 2)), regions=regions)
    renderer = FrameRenderer(208, 208)
    bare = {k: v for k, v in BARE.items() if k != "show_regions"}
    on = renderer.render(snap, RenderOptions(show_regions=True, **bare))
    off = renderer.render(snap, RenderOptions(show_regions=False, **bare))
    ex, ey = expected_pixel(50, 70)                     # top of the nest circle
    near = (on[int(ey) - 2:int(ey) + 3, int(ex) - 2:int(ex) + 3] != BACKGROUND).any()
    assert near and not np.array_equal(on, off)
    bad = make_snapshot(np.zeros((0, 2)), regions=[{"name": "x", "shape": "blob"}])
    with pytest.raises(SwarmError, match="unknown shape 'blob'"):
        renderer.render(bad)


NEST = (200, 140, 90)      # REGION_COLOURS["nest"]
EDGY = [  # a circle across the right edge, a rect across the top one (world 100 x 50)
    {"name": "", "kind": "nest", "label": None, "shape": "circle",
     "center": [2, 25], "radius": 8},
    {"name": "", "kind": "nest", "label": None, "shape": "rect",
     "min": [40, 45], "max": [60, 55]},
]


def _region_pixels(wraps, regions=EDGY, world=(100.0, 50.0)):
    snap = make_snapshot(np.zeros((0, 2)), world=world, regions=regions, wraps=wraps)
    bare = {k: v for k, v in BARE.items() if k != "show_regions"}
    return colour_mask(FrameRenderer(208, 208).render(snap, RenderOptions(**bare)), NEST)


def _near(mask, x, y, world=(100.0, 50.0), reach=2):
    px, py = (int(round(v)) for v in expected_pixel(x, y, world))
    return mask[py - reach:py + reach + 1, px - reach:px + reach + 1].any()


def test_a_region_across_a_wrapping_edge_is_drawn_on_both_sides():
    """The runtime counts an agent at x = 95 inside a circle at x = 2 of radius 8 in a
    100-wide wrap-around world, so the picture must show that part of the circle."""
    wrap, wall = _region_pixels(True), _region_pixels(False)
    for mask in (wrap, wall):
        assert _near(mask, 10, 25) and _near(mask, 50, 45)   # the regions themselves
    assert _near(wrap, 94, 25) and not _near(wall, 94, 25)   # the circle's copy, right
    assert _near(wrap, 50, 5) and not _near(wall, 50, 5)     # the rect's copy, bottom


def test_a_wrapped_region_stays_inside_the_world():
    """What lies beyond an edge is drawn across the other one, not in the margin."""
    wrap, wall = _region_pixels(True), _region_pixels(False)
    (_, top), (_, bottom) = (expected_pixel(0, 50, (100.0, 50.0)),
                             expected_pixel(0, 0, (100.0, 50.0)))
    margin = np.ones(wrap.shape[0], bool)
    margin[int(top):int(bottom) + 1] = False
    assert wall[margin].any()            # a walled world draws a region as declared
    assert not wrap[margin].any()


def test_a_region_inside_a_wrapping_world_is_drawn_once():
    regions = [{"name": "", "kind": "nest", "label": None, "shape": "circle",
                "center": [50, 25], "radius": 8}]
    assert np.array_equal(_region_pixels(True, regions), _region_pixels(False, regions))


def test_a_wrapping_programs_region_is_drawn_across_the_edge(backend, tmp_path):
    """From a program: the snapshot says the world wraps, and the copy is drawn."""
    import swarmdsl
    from swarmdsl.runtime.simulation import Simulation

    path = tmp_path / "edge.swarm"
    path.write_text("world { size 100 x 50; edges wrap; steps 1 }\n"
                    "nest home = circle(2, 25, 8)\n"
                    "agent a { count 1\n status s { } }\n")
    snap = Simulation(swarmdsl.load_program(str(path)), seed=0, backend=backend).snapshot()
    assert snap.wraps
    snap.pos = np.zeros((0, 2))
    snap.heading = snap.ids = snap.status = snap.kind = np.zeros(0)
    bare = {k: v for k, v in BARE.items() if k != "show_regions"}
    mask = colour_mask(FrameRenderer(208, 208).render(snap, RenderOptions(**bare)), NEST)
    assert _near(mask, 94, 25) and _near(mask, 10, 25)


def _label_pixels(renderer, legend, **region):
    """The pixels of a nest's label (text on its box): where naming the nest changes
    the frame."""
    opts = RenderOptions(show_field=False, show_tick=False, show_legend=legend)
    named, bare = (renderer.render(make_snapshot(np.zeros((0, 2)), regions=[
        {"name": "", "kind": "nest", "label": label, "shape": "circle", **region}]), opts)
        for label in ("home", None))
    return (named != bare).any(axis=2)


def test_a_region_label_moves_clear_of_the_legend():
    """A region near the top-left corner would be labelled where the legend is drawn
    afterwards; the label moves out of the legend's box, whole, not under it."""
    renderer = FrameRenderer(208, 208)
    corner = dict(center=[12, 80], radius=6)
    alone = _label_pixels(renderer, False, **corner)
    beside = _label_pixels(renderer, True, **corner)
    x, y, w, h = renderer.legend_rect
    assert alone[y:y + h, x:x + w].any()        # where it goes without a legend
    assert not beside[y:y + h, x:x + w].any()
    assert beside.sum() >= 0.95 * alone.sum()   # all of it (bar the outline), elsewhere


def test_a_region_label_clear_of_the_legend_stays_put():
    renderer = FrameRenderer(208, 208)
    middle = dict(center=[50, 50], radius=6)
    assert np.array_equal(_label_pixels(renderer, True, **middle),
                          _label_pixels(renderer, False, **middle))


@pytest.mark.parametrize("copies", [1, 2500], ids=["line-calls", "numpy-sampled"])
def test_links_toggle_draws_between_linked_agents(copies):
    links = np.repeat(np.array([[0, 1]]), copies, axis=0)
    snap = make_snapshot([[20, 50], [80, 50]], links=links)
    renderer = FrameRenderer(208, 208)
    ex, ey = expected_pixel(50, 50)
    on = renderer.render(snap, RenderOptions(show_links=True, marker_px=6, **BARE))
    off = renderer.render(snap, RenderOptions(show_links=False, marker_px=6, **BARE))
    assert tuple(off[int(ey), int(ex)]) == BACKGROUND
    assert tuple(on[int(ey), int(ex)]) != BACKGROUND


def test_believed_position_is_a_hollow_marker_tied_to_the_true_one():
    snap = make_snapshot([[30, 50]], believed=np.array([[70, 50]]))
    renderer = FrameRenderer(208, 208)
    opts = dict(marker_px=16, **BARE)
    on = renderer.render(snap, RenderOptions(show_believed=True, **opts))
    off = renderer.render(snap, RenderOptions(show_believed=False, **opts))
    bx, by = expected_pixel(70, 50)
    mx, my = expected_pixel(50, 50)
    window = colour_mask(on, PALETTE[0])[int(by) - 8:int(by) + 9, int(bx) - 8:int(bx) + 9]
    assert window.any()                                   # outline in status colour
    assert not colour_mask(off, PALETTE[0])[int(by) - 8:int(by) + 9,
                                            int(bx) - 8:int(bx) + 9].any()
    assert tuple(on[int(my), int(mx)]) != BACKGROUND      # the line between them
    assert tuple(off[int(my), int(mx)]) == BACKGROUND


def test_twenty_thousand_agents_render_without_per_agent_draw_calls(monkeypatch):
    calls = []
    original = pygame.draw.polygon
    monkeypatch.setattr(pygame.draw, "polygon", lambda *a, **k: calls.append(1) or
                        original(*a, **k))
    rng = np.random.default_rng(0)
    n = 20_000
    snap = make_snapshot(rng.uniform(0, 100, (n, 2)), rng.uniform(-3, 3, n),
                         rng.integers(0, 3, n), links=rng.integers(0, n, (5000, 2)),
                         believed=rng.uniform(0, 100, (n, 2)))
    img = FrameRenderer(320, 320).render(
        snap, RenderOptions(show_links=True, show_believed=True))
    assert img.shape == (320, 320, 3)
    assert calls == []
    for colour in PALETTE[:3]:
        assert colour_mask(img, colour).sum() > 1000


def test_non_finite_positions_are_skipped():
    snap = make_snapshot([[np.nan, 5], [50, 50]], heading=[0.0, np.inf])
    img = FrameRenderer(64, 64).render(snap, RenderOptions(**BARE))
    assert img.shape == (64, 64, 3)


def test_fit_size_keeps_aspect_in_multiples_of_16():
    w, h = fit_size((800, 600), 800)
    assert (w, h) == (800, 592)
    assert w % 16 == 0 and h % 16 == 0
    assert fit_size((10, 1000), 400)[0] == 16
    with pytest.raises(SwarmError):
        fit_size((0, 10))


# -- video ----------------------------------------------------------------------------


def frames(n, size=(48, 64)):
    return [np.full((*size, 3), 40 * i, np.uint8) for i in range(n)]


def read_mp4(path):
    import imageio.v2 as iio2

    # imageio's ffmpeg reader leaves pipe objects to the garbage collector; collect them
    # here so their ResourceWarning cannot fail an unrelated test later.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        with iio2.get_reader(str(path), format="FFMPEG") as reader:
            out = [frame for frame in reader]  # len(reader) may be inf
        gc.collect()
    return out


def read_gif(path):
    import imageio.v3 as iio

    return iio.imread(path, index=None)


@pytest.mark.parametrize("ext", [".gif", ".mp4"])
def test_video_written_from_five_frames_reads_back_five(tmp_path, ext):
    path = tmp_path / f"run{ext}"
    with VideoWriter(path, fps=10) as video:
        for frame in frames(5):
            video.add(frame)
    assert video.frames_written == 5
    got = read_gif(path) if ext == ".gif" else read_mp4(path)
    assert len(got) == 5
    assert got[0].shape[:2] == (48, 64)
    assert abs(int(got[4][20, 20, 0]) - 160) <= 8       # content survived, in order
    assert int(got[0][20, 20, 0]) <= 8


@pytest.mark.parametrize("ext", [".gif", ".mp4"])
def test_exception_mid_recording_leaves_a_readable_file(tmp_path, ext):
    path = tmp_path / f"cut{ext}"
    with pytest.raises(RuntimeError, match="boom"):
        with VideoWriter(path, fps=10) as video:
            for i, frame in enumerate(frames(5)):
                if i == 3:
                    raise RuntimeError("boom")
                video.add(frame)
    got = read_gif(path) if ext == ".gif" else read_mp4(path)
    assert len(got) == 3


@pytest.mark.parametrize("ext", [".gif", ".mp4"])
def test_a_video_is_only_at_its_path_once_finished(tmp_path, ext):
    path = tmp_path / f"v{ext}"
    video = VideoWriter(path, fps=10)
    for frame in frames(3):
        video.add(frame)
    assert not path.exists()                # written under a hidden name meanwhile
    video.close()
    assert video.complete and path.exists()
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_a_video_the_encoder_could_not_finish_is_not_claimed(tmp_path, monkeypatch):
    path = tmp_path / "v.mp4"
    video = VideoWriter(path, fps=10)
    for frame in frames(3):
        video.add(frame)

    def die():
        raise OSError("ffmpeg was killed")
    monkeypatch.setattr(video, "_finish", die)
    video.close()
    assert not video.complete
    assert list(tmp_path.iterdir()) == []
    video._ffmpeg.close()                   # the real encoder, ended by the test
    assert not path.exists()


def moving_square(n, size=(48, 64), colours=None):
    """Frames of a square moving over a still background; `colours` > 256 gives the
    background a gradient of that many colours (more than one GIF palette holds)."""
    h, w = size
    base = np.zeros((h, w, 3), np.uint8)
    base[...] = (30, 30, 40)
    if colours:
        shade = np.arange(h * w).reshape(h, w) * colours // (h * w)
        base[..., 0] = shade % 256
        base[..., 1] = shade // 256 * 60
    out = []
    for i in range(n):
        frame = base.copy()
        frame[10:20, 4 * i:4 * i + 10] = (250, 200, 60)
        out.append(frame)
    return out


def test_a_gif_is_written_as_frames_come_so_finishing_is_instant(tmp_path):
    """Stopping a long recording waited about a minute while every frame held in memory
    was quantised; each frame now reaches the file as it is added, and closing only
    ends the file."""
    video = VideoWriter(tmp_path / "v.gif", fps=10)
    sizes = []
    for frame in moving_square(6):
        video.add(frame)
        video._gif.fh.flush()
        sizes.append(video.tmp.stat().st_size)
    assert all(b > a for a, b in zip(sizes, sizes[1:], strict=False))
    video.close()
    assert video.complete and (tmp_path / "v.gif").stat().st_size == sizes[-1] + 1


def test_gif_frames_of_few_colours_come_back_exactly(tmp_path):
    """Rendered frames mostly have at most 256 colours: no quantisation at all, every
    frame kept, a repeated frame too."""
    shown = moving_square(5)
    shown.insert(3, shown[2].copy())
    with VideoWriter(tmp_path / "v.gif", fps=10) as video:
        for frame in shown:
            video.add(frame)
    got = read_gif(tmp_path / "v.gif")
    assert len(got) == len(shown)
    assert all(np.array_equal(g[..., :3], f) for g, f in zip(got, shown, strict=True))


def test_gif_frames_of_many_colours_are_as_close_as_pillows_own_gifs(tmp_path):
    """Past 256 colours a palette must drop some: no further from the frames than
    Pillow's animated-GIF writer (the writer before) gets."""
    from PIL import Image

    shown = moving_square(6, colours=700)
    with VideoWriter(tmp_path / "v.gif", fps=10) as video:
        for frame in shown:
            video.add(frame)
    first, *rest = [Image.fromarray(f) for f in shown]
    first.save(tmp_path / "pillow.gif", save_all=True, append_images=rest, duration=100,
               loop=0)

    def error(path):
        got = read_gif(path)[..., :3].astype(float)
        assert got.shape == (6, 48, 64, 3)
        return np.sqrt(((got - np.asarray(shown)) ** 2).mean())
    assert error(tmp_path / "v.gif") <= error(tmp_path / "pillow.gif")


@pytest.mark.parametrize("ext", [".gif", ".mp4"])
def test_a_video_that_fails_midway_is_not_claimed_and_the_run_goes_on(tmp_path,
                                                                    monkeypatch, ext):
    """A full disk while frames stream in: `add` does not raise into the run; the
    video is dropped with the reason, as when finishing it fails."""
    import errno

    video = VideoWriter(tmp_path / f"v{ext}", fps=10)
    send = getattr(video, f"_send_{ext[1:]}")

    def full(frame):
        if video.frames_written == 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        send(frame)
    monkeypatch.setattr(video, f"_send_{ext[1:]}", full)
    for frame in frames(4):
        video.add(frame)
    video.close()
    assert not video.complete and video.error == "no space left on device"
    assert video.frames_written == 2
    assert list(tmp_path.iterdir()) == []


def test_mp4_pads_odd_sizes_to_macro_blocks(tmp_path):
    path = tmp_path / "odd.mp4"
    with VideoWriter(path) as video:
        for frame in frames(2, size=(30, 50)):
            video.add(frame)
    got = read_mp4(path)
    assert got[0].shape[:2] == (32, 64)


def test_unknown_video_extension_names_the_option():
    with pytest.raises(SwarmError) as info:
        VideoWriter("out.avi")
    message = str(info.value)
    assert "--record" in message and ".gif" in message and ".mp4" in message


def test_video_rejects_a_frame_of_another_size(tmp_path):
    with VideoWriter(tmp_path / "a.gif") as video:
        video.add(frames(1)[0])
        with pytest.raises(SwarmError, match="size changed"):
            video.add(np.zeros((10, 10, 3), np.uint8))


def test_the_viewer_docs_recording_example_runs_as_written(backend, tmp_path, monkeypatch):
    """docs/viewer.md's "Using it from code" is a whole script: copied into a file and
    run from the repository's root it writes run.mp4, one frame per tick."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    text = (root / "docs" / "viewer.md").read_text()
    section = text.split("## Using it from code", 1)[1]
    script = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    (tmp_path / "programs").symlink_to(root / "programs")
    monkeypatch.chdir(tmp_path)
    exec(compile(script, "viewer.md", "exec"), {})
    got = read_mp4(tmp_path / "run.mp4")
    assert len(got) == 100

# -- viewer ---------------------------------------------------------------------------


class FakeDriver:
    """Counts steps; done after `steps`; can be told to fail on a given tick."""

    def __init__(self, steps, fail_at=None):
        self.steps, self.fail_at, self.tick = steps, fail_at, 0
        gx = np.linspace(0, 100, 5)
        self.fields = {"a": np.eye(5), "b": np.ones((5, 5))}
        self.grid = gx

    @property
    def done(self):
        return self.tick >= self.steps

    def step(self):
        if self.fail_at is not None and self.tick == self.fail_at:
            raise RuntimeError("kernel fault")
        self.tick += 1

    def snapshot(self):
        return make_snapshot([[10 + self.tick % 80, 50]], tick=self.tick,
                             fields=self.fields, grid_x=self.grid, grid_y=self.grid)


def key(k, char=""):
    return pygame.event.Event(pygame.KEYDOWN, key=k, mod=0, unicode=char)


@pytest.fixture
def display():
    pygame.display.init()
    pygame.event.clear()
    yield
    pygame.display.quit()


def test_pause_then_single_steps_then_quit(display):
    for event in (key(pygame.K_SPACE, " "), key(pygame.K_PERIOD, "."),
                  key(pygame.K_RIGHT), pygame.event.Event(pygame.QUIT)):
        pygame.event.post(event)
    driver = FakeDriver(steps=100)
    assert run_viewer(driver, fps=1000) == "quit"
    assert driver.tick == 2
    assert not pygame.display.get_init()                 # window closed


def test_single_step_key_does_nothing_while_running(display):
    pygame.event.post(key(pygame.K_PERIOD, "."))
    pygame.event.post(key(pygame.K_q, "q"))
    driver = FakeDriver(steps=100)
    assert run_viewer(driver, fps=1000) == "quit"
    assert driver.tick == 0


def test_runs_to_done_and_records_one_frame_per_tick(display):
    recorded = []

    class Recorder:
        def add(self, frame):
            recorded.append(frame)

    driver = FakeDriver(steps=5)
    assert run_viewer(driver, fps=1000, recorder=Recorder(), max_px=160) == "done"
    assert driver.tick == 5
    assert len(recorded) == 6                            # ticks 0..5
    assert recorded[0].shape == (160, 160, 3)
    assert not np.array_equal(recorded[0], recorded[-1])


def test_faster_keys_take_more_ticks_per_frame(display):
    pygame.event.post(key(pygame.K_EQUALS, "="))         # 2 ticks per frame
    pygame.event.post(key(pygame.K_PLUS, "+"))           # 4 ticks per frame
    driver = FakeDriver(steps=8)
    frames_seen = []
    run_viewer(driver, fps=1000, recorder=type("R", (), {"add": frames_seen.append})())
    assert driver.tick == 8
    assert len(frames_seen) == 3                         # ticks 0, 4, 8


def test_driver_exception_propagates_and_closes_the_window(display):
    driver = FakeDriver(steps=10, fail_at=3)
    with pytest.raises(RuntimeError, match="kernel fault"):
        run_viewer(driver, fps=1000)
    assert driver.tick == 3
    assert not pygame.display.get_init()


def test_view_state_keys_toggle_options():
    state = ViewState(RenderOptions(show_field=True))
    state.sync_fields(hot_field_snapshot())
    assert state.handle(pygame, key(pygame.K_f)) is None
    assert state.options.show_field is False
    state.handle(pygame, key(pygame.K_TAB))
    assert state.options.field == "other" and state.options.show_field
    state.handle(pygame, key(pygame.K_TAB))
    assert state.options.field == "pheromone"
    state.handle(pygame, key(pygame.K_l))
    state.handle(pygame, key(pygame.K_b))
    assert state.options.show_links and state.options.show_believed
    state.handle(pygame, key(pygame.K_MINUS, "-"))
    assert [state.ticks_due() for _ in range(4)] == [0, 1, 0, 1]
    state.handle(pygame, key(pygame.K_SPACE, " "))
    assert state.paused and state.ticks_due() == 0
    assert state.handle(pygame, key(pygame.K_PERIOD, ".")) == "step"
    assert state.handle(pygame, key(pygame.K_ESCAPE)) == "quit"


def test_no_display_under_the_dummy_driver():
    assert display_available() is False


# -- optional dependencies --------------------------------------------------------------


def run_python(code):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=60)


def test_importing_viz_loads_neither_pygame_nor_imageio():
    out = run_python("import sys, swarmdsl.viz; "
                     "print(sorted(m for m in ('pygame', 'imageio') if m in sys.modules))")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_missing_pygame_is_a_swarm_error_naming_the_extra():
    out = run_python(
        "import sys; sys.modules['pygame'] = None\n"
        "from swarmdsl.viz import FrameRenderer\n"
        "from swarmdsl.compiler.errors import SwarmError\n"
        "try:\n    FrameRenderer(32, 32)\n"
        "except SwarmError as e:\n    print(e.render())\n")
    assert out.returncode == 0, out.stderr
    assert "pygame" in out.stdout and "pip install 'swarmdsl[viz]'" in out.stdout
    assert out.stdout.count("\n") >= 2 and "Traceback" not in out.stderr


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_fps_sets_the_frame_rate_of_a_headless_recording(backend, tmp_path, suffix):
    # headless `--record` played at 30 fps whatever `--fps` said
    import imageio.v3 as iio

    from swarmdsl.cli import main

    program = tmp_path / "walk.swarm"
    program.write_text("world { size 50 x 50 }\nagent a { count 3; velocity (1, 0); status s { } }\n")
    video = tmp_path / f"walk{suffix}"
    assert main(["run", str(program), "--headless", "--steps", "4", "--fps", "8",
                 "--record", str(video)]) == 0
    if suffix == ".gif":
        from PIL import Image

        with Image.open(video) as gif:
            durations = []
            for i in range(gif.n_frames):
                gif.seek(i)
                durations.append(gif.info["duration"])
        assert durations == [120] * 5               # 1/8 s, in whole hundredths
    else:
        assert iio.immeta(video)["fps"] == 8


def _hidden_agents(img, snap, size):
    """Agents whose own pixel does not show their colour (a panel drawn over them)."""
    from swarmdsl.viz.palette import status_palette

    palette = status_palette(len(NAMES))
    hidden = []
    for (x, y), status in zip(snap.pos, snap.status, strict=True):
        ex, ey = expected_pixel(x, y, size=size)
        if tuple(img[int(ey), int(ex)]) != tuple(palette[status]):
            hidden.append((x, y))
    return hidden


def test_the_legend_moves_off_a_swarm_gathered_in_its_corner():
    # agents in the top-left corner were drawn under the legend, out of sight
    pos = np.array([[x, y] for x in (3, 9, 15, 21) for y in (79, 85, 91, 97)], float)
    snap = make_snapshot(pos, status=np.arange(len(pos)) % 3)
    renderer = FrameRenderer(208, 208)
    opts = RenderOptions(show_field=False, show_tick=True, splat_above=0)
    img = renderer.render(snap, opts)
    assert _hidden_agents(img, snap, (208, 208)) == []
    x, y, w, h = renderer.legend_rect
    assert x > 104 or y > 104                          # another corner
    ex, ey = expected_pixel(*pos.T, size=(208, 208))
    assert not ((ex >= x) & (ex < x + w) & (ey >= y) & (ey < y + h)).any()
    # the same picture next frame: the legend does not jump back
    assert np.array_equal(renderer.render(snap, opts), img)


def test_the_legend_stays_top_left_when_nothing_is_under_it():
    snap = make_snapshot([[90, 10], [50, 50]], status=[0, 1])
    renderer = FrameRenderer(208, 208)
    renderer.render(snap, RenderOptions(show_field=False))
    assert renderer.legend_rect[:2] == (4, 4)


def test_a_legend_in_the_lower_right_stays_clear_of_the_tick_and_captions():
    # agents in every corner but the bottom right: the legend goes there, and never
    # over the tick counter or the bottom-left captions
    pos = [[3, 97], [10, 97], [97, 97], [90, 97], [3, 3], [10, 5], [50, 50]]
    snap = make_snapshot(pos, status=[0, 1, 2, 0, 1, 2, 0])
    renderer = FrameRenderer(208, 208)
    renderer.render(snap, RenderOptions(show_field=False, hud_text="keys"))
    x, y, w, h = renderer.legend_rect
    assert x + w == 208 - 4 and y + h == 208 - 4


def _tiny_snapshot():
    return shipped("boids.swarm").snapshot()


def _render(options):
    return viz.FrameRenderer(64, 64).render(_tiny_snapshot(), options)


def _options(**settings):
    return viz.RenderOptions(**settings)


def _record(path, frame=None, fps=30):
    with viz.VideoWriter(path, fps=fps) as video:
        video.add(np.zeros((32, 32, 3), np.uint8) if frame is None else frame)
    return video


def _add_after_close(path):
    _record(path).add(np.zeros((32, 32, 3), np.uint8))


class _Driver:
    """The viewer's driver protocol over a simulation, done after two ticks."""

    def __init__(self):
        self.sim = shipped("boids.swarm")
        self.step, self.snapshot = self.sim.step, self.sim.snapshot

    tick = property(lambda self: self.sim.tick)
    done = property(lambda self: self.sim.tick >= 2)


def _viewer(**settings):
    return viz.run_viewer(_Driver(), **settings)


@pytest.mark.parametrize("call, named", [
    (lambda tmp: _render({"show_links": True}), "options must be a RenderOptions"),
    (lambda tmp: _render(_options(colormap=None)), "RenderOptions.colormap"),
    (lambda tmp: _render(_options(field=3)), "RenderOptions.field"),
    (lambda tmp: _render(_options(field_alpha=float("nan"))), "RenderOptions.field_alpha"),
    (lambda tmp: _render(_options(splat_above="10")), "RenderOptions.splat_above"),
    (lambda tmp: _render(_options(marker_px=-4)), "RenderOptions.marker_px"),
    (lambda tmp: _render(_options(hud_text=5)), "RenderOptions.hud_text"),
    (lambda tmp: viz.FrameRenderer(64, 64).render({}),
     "draws a Snapshot"),
    (lambda tmp: viz.FrameRenderer(64, 64, font_px="big"),
     "font_px"),
    (lambda tmp: viz.fit_size((600, 600), "640"), "max_px"),
    (lambda tmp: viz.fit_size("600x600", 640), "world size"),
    (lambda tmp: viz.fit_size((600, 600), 640, multiple=0), "multiple"),
    (lambda tmp: _record(None), "--record"),
    (lambda tmp: _record(tmp / "a.gif", fps="30"), "frames per second"),
    (lambda tmp: _record(tmp / "a.gif", frame=np.zeros((32, 32, 3))), "uint8"),
    (lambda tmp: _record(tmp / "a.gif", frame=np.zeros((0, 5, 3), np.uint8)), "uint8"),
    (lambda tmp: _add_after_close(tmp / "a.gif"), "closed"),
    (lambda tmp: _viewer(fps="30"), "--fps"),
    (lambda tmp: _viewer(options={"show_links": True}), "options"),
    (lambda tmp: _viewer(ticks_per_frame=float("nan")), "ticks_per_frame"),
    (lambda tmp: _viewer(title=None), "title"),
    (lambda tmp: _viewer(recorder=object()), "recorder"),
    (lambda tmp: viz.run_viewer(shipped("boids.swarm")), "driver needs"),
])
def test_a_bad_viz_argument_is_an_option_error_naming_it(tmp_path, call, named):
    """Each of these was a TypeError, ValueError, AttributeError or pygame error from
    inside a layer, a NaN field_alpha a garbage heatmap, and a closed or refused frame a
    bare ValueError; now a SwarmOptionError names the argument."""
    with pytest.raises(SwarmOptionError, match=named):
        call(tmp_path)


def test_a_video_under_a_file_is_refused_before_the_first_frame(tmp_path):
    """`VideoWriter("notes.txt/run.gif")` was accepted, and every frame was then lost
    with only `complete` False to say so; it is refused when the writer is made."""
    (tmp_path / "notes.txt").write_text("")
    with pytest.raises(SwarmOptionError, match="a file, not a folder"):
        viz.VideoWriter(tmp_path / "notes.txt" / "run.gif")


@pytest.mark.parametrize("bad", [
    dict(regions=[{"shape": "circle", "name": "nest"}]),
    dict(regions={"nest": 1}),
    dict(vectors={"wind": np.ones((11, 11))}),
    dict(grid_points=np.ones(5)),
])
def test_a_hand_built_snapshot_the_layers_cannot_draw_is_a_swarm_error(bad):
    """A snapshot built by hand (from a recorded run, say) with a circle without its
    centre, regions not a list, a vector field without its components or grid points
    not (P, 2) failed with a KeyError, AttributeError or numpy ValueError."""
    from dataclasses import replace

    snap = replace(shipped("aco.swarm").snapshot(), **bad)
    options = viz.RenderOptions(show_grid_points=True)
    with pytest.raises(swarmdsl.SwarmError, match="snapshot|run.json"):
        viz.FrameRenderer(64, 64).render(snap, options)
