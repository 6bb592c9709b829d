"""`python -m swarmdsl.analysis.picture`: a recorded tick drawn as the viewer draws it,
and every bad input refused as one `error:` line naming the option or file (exit 2)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from swarmdsl.analysis.picture import main

PROGRAM = """world { size 100 x 50; edges wrap; steps 4 }
field scent { decay 0.1; initial pos.x }
nest home = circle(110, 25, 8)
agent a { count 3
  place (50, 25)
  status s { } }
"""
NEST = (200, 140, 90)      # REGION_COLOURS["nest"]


@pytest.fixture(scope="module")
def run_dir(backend, tmp_path_factory) -> Path:
    """A run of 4 ticks recorded every 2 (ticks 0, 2 and 4), on the module's backend."""
    from swarmdsl.cli import main as swarmdsl

    tmp = tmp_path_factory.mktemp("picture")
    (tmp / "edge.swarm").write_text(PROGRAM)
    out = tmp / "run"
    assert swarmdsl(["run", str(tmp / "edge.swarm"), "--headless", "--every", "2",
                     "--backend", backend, "--out", str(out)]) == 0
    return out


def refused(capsys, *argv) -> str:
    """The one line the picture tool prints for `argv`, which must be refused (exit 2)."""
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert lines and lines[0].startswith("error: ") and "Traceback" not in captured.err
    assert len([line for line in lines if not line.startswith("  hint:")]) == 1
    assert captured.out == ""
    return lines[0]


def test_a_recorded_tick_is_drawn(run_dir, tmp_path, capsys):
    out = tmp_path / "t2.png"
    assert main([str(run_dir), str(out), "--tick", "2", "--field", "scent"]) == 0
    assert out.is_file() and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert capsys.readouterr().out.strip() == str(out)


def _nest_near(png: Path, points, reach: int = 2) -> list[bool]:
    """Whether the nest's outline colour is within `reach` pixels of each world point."""
    import pygame

    from swarmdsl.viz.geometry import Transform

    surface = pygame.image.load(str(png))
    img = pygame.surfarray.array3d(surface).swapaxes(0, 1)
    mask = (img == np.array(NEST, np.uint8)).all(axis=2)
    tf = Transform((100.0, 50.0), surface.get_width(), surface.get_height())
    found = []
    for px, py in np.rint(tf.to_px(points)).astype(int):
        found.append(bool(mask[py - reach:py + reach + 1, px - reach:px + reach + 1].any()))
    return found


def test_a_region_beyond_a_wrapping_edge_is_drawn_at_its_copy(run_dir, tmp_path):
    """`home` is declared at x = 110 in a 100-wide wrap-around world: the runtime
    counts an agent at x = 10 in it, so the picture must draw it there: the recorded
    run.json has to tell the viewer's renderer that the world wraps."""
    out = tmp_path / "wrap.png"
    assert main([str(run_dir), str(out), "--px", "416"]) == 0
    copy = [(18, 25), (10, 17), (2, 25)]            # the copy's right, bottom, left
    assert _nest_near(out, copy) == [True, True, True]


def test_a_picture_that_fails_to_save_leaves_the_old_one(run_dir, tmp_path, monkeypatch,
                                                          capsys):
    """The PNG goes under a hidden name and is renamed into place: a save that fails
    (a full disk) keeps the previous picture whole and leaves no partial file."""
    import pygame

    out = tmp_path / "same.png"
    assert main([str(run_dir), str(out), "--tick", "0"]) == 0
    before = out.read_bytes()
    assert main([str(run_dir), str(out), "--tick", "4"]) == 0     # replaced whole
    assert out.read_bytes() != before and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    after = out.read_bytes()

    def full_disk(surface, fh, namehint=""):
        fh.write(b"\x89PNG half")
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(pygame.image, "save", full_disk)
    assert refused(capsys, run_dir, out, "--tick", "2") == (
        f"error: OUT {out}: cannot write the picture (no space left on device)")
    assert out.read_bytes() == after
    assert sorted(p.name for p in tmp_path.iterdir()) == ["same.png"]


def test_a_missing_output_folder_is_made(run_dir, tmp_path):
    out = tmp_path / "figures" / "new" / "last.png"
    assert main([str(run_dir), str(out)]) == 0
    assert out.is_file()


def test_a_missing_run_folder(tmp_path, capsys):
    line = refused(capsys, tmp_path / "nowhere", tmp_path / "o.png")
    assert line.startswith(f"error: RUN_DIR {tmp_path / 'nowhere'}: no such folder")


def test_an_empty_run_folder(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    line = refused(capsys, tmp_path / "empty", tmp_path / "o.png")
    assert line.startswith(f"error: RUN_DIR {tmp_path / 'empty'}: the folder is empty")


def test_a_folder_that_is_not_a_run(tmp_path, capsys):
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("x")
    line = refused(capsys, tmp_path / "notes", tmp_path / "o.png")
    assert line.startswith(f"error: RUN_DIR {tmp_path / 'notes'}: no run.json")
    assert not (tmp_path / "o.png").exists()


def test_a_file_given_as_the_run_folder(run_dir, tmp_path, capsys):
    line = refused(capsys, run_dir / "run.json", tmp_path / "o.png")
    assert line.startswith(f"error: RUN_DIR {run_dir / 'run.json'}: is a file")


@pytest.mark.parametrize("text", ["{not json", "[]", '{"world": {}}'])
def test_a_damaged_run_json(tmp_path, capsys, text):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "run.json").write_text(text)
    line = refused(capsys, tmp_path / "run", tmp_path / "o.png")
    assert line.startswith(f"error: RUN_DIR {tmp_path / 'run'}: run.json is ")


def test_a_status_that_run_json_does_not_list_still_gets_drawn(run_dir, tmp_path):
    """run.json edited, or copied from another run: its status counts miss the status
    every agent is in. The picture is drawn all the same."""
    import json
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    meta = json.loads((copy / "run.json").read_text())
    meta["status_counts"] = {"elsewhere": 3}
    (copy / "run.json").write_text(json.dumps(meta))
    out = tmp_path / "o.png"
    assert main([str(copy), str(out)]) == 0 and out.is_file()


def test_a_run_without_its_fields_or_agents(run_dir, tmp_path, capsys):
    import shutil

    for missing in ("fields.npz", "agents.parquet"):
        copy = tmp_path / missing
        shutil.copytree(run_dir, copy)
        p = copy / missing
        shutil.rmtree(p) if p.is_dir() else p.unlink()
        line = refused(capsys, copy, tmp_path / "o.png")
        assert line.startswith(f"error: RUN_DIR {copy}: ") and missing in line


@pytest.mark.parametrize("tick, nearest", [(3, "nearest 2 and 4"), (99, "nearest 4"),
                                           (-1, "nearest 0")])
def test_a_tick_that_was_not_recorded(run_dir, tmp_path, capsys, tick, nearest):
    line = refused(capsys, run_dir, tmp_path / "o.png", "--tick", tick)
    assert line == (f"error: --tick {tick}: not recorded in {run_dir} (3 ticks from 0 "
                    f"to 4; {nearest})")
    assert not (tmp_path / "o.png").exists()


def test_an_unknown_field(run_dir, tmp_path, capsys):
    line = refused(capsys, run_dir, tmp_path / "o.png", "--field", "sent")
    assert line.startswith("error: --field sent: not a field of the run")
    assert "fields: scent" in line
    assert main([str(run_dir), str(tmp_path / "o.png"), "--field", "sent"]) == 2
    assert "  hint: did you mean 'scent'?" in capsys.readouterr().err.splitlines()


@pytest.mark.parametrize("option, value, message", [
    ("--px", "0", "must be from 16 to 16,384"), ("--px", "20000", "must be from 16"),
    ("--window", "0", "must be 1 or more"), ("--window", "-3", "must be 1 or more")])
def test_bad_px_and_window(run_dir, tmp_path, capsys, option, value, message):
    line = refused(capsys, run_dir, tmp_path / "o.png", option, value)
    assert line.startswith(f"error: {option} {value}: {message}")
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize("name", ["o.txt", "picture", "o.png.bak"])
def test_an_output_that_is_not_a_png(run_dir, tmp_path, capsys, name):
    line = refused(capsys, run_dir, tmp_path / name)
    assert line == f"error: OUT {tmp_path / name}: the picture must end in .png"
    assert not (tmp_path / name).exists()


def test_an_output_folder_that_cannot_be(run_dir, tmp_path, capsys):
    (tmp_path / "plain").write_text("x")
    out = tmp_path / "plain" / "o.png"
    line = refused(capsys, run_dir, out)
    assert line.startswith(f"error: OUT {out}: is under {tmp_path / 'plain'}, which is a file")
    (tmp_path / "shelf.png").mkdir()
    line = refused(capsys, run_dir, tmp_path / "shelf.png")
    assert line.startswith(f"error: OUT {tmp_path / 'shelf.png'}: is a folder")


@pytest.mark.parametrize("argv", [["", "o.png"], ["RUN", ""]])
def test_empty_paths(capsys, argv):
    line = refused(capsys, *argv)
    assert line.startswith('error: RUN_DIR "": the path is empty' if argv[0] == ""
                           else 'error: OUT "": the path is empty')


def test_a_bug_is_one_internal_error_line(run_dir, tmp_path, capsys, monkeypatch):
    from swarmdsl.viz import frames

    def broken(self, snapshot, options=None):
        raise RuntimeError("drawing failed")

    monkeypatch.delenv("SWARMDSL_DEBUG", raising=False)
    monkeypatch.setattr(frames.FrameRenderer, "draw", broken)
    assert main([str(run_dir), str(tmp_path / "o.png")]) == 3
    err = capsys.readouterr().err
    assert err.startswith("error: internal error: RuntimeError: drawing failed")
    assert "Traceback" not in err


def _picture(*argv) -> subprocess.CompletedProcess:
    env = dict(os.environ, SDL_VIDEODRIVER="dummy")
    env.pop("SWARMDSL_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "swarmdsl.analysis.picture",
                           *map(str, argv)], capture_output=True, text=True, env=env,
                          timeout=120)


def test_the_module_command_prints_no_traceback(tmp_path):
    proc = _picture(tmp_path / "nowhere", tmp_path / "o.png")
    assert proc.returncode == 2
    assert proc.stderr == (f"error: RUN_DIR {tmp_path / 'nowhere'}: no such folder; give "
                           "a folder written by `swarmdsl run --out`\n")
