"""A Run's observers (`runtime/observers.py`): what `Run.attach` sees, and that the viz
package is plugged in by name only when a run asks for a video or a window."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from swarmdsl.errors import SwarmOptionError
from swarmdsl.runtime.runner import Run

ROOT = Path(__file__).resolve().parent.parent
PROGRAM = """world { size 20 x 20; edges wrap }
agent a { count 10
  place uniform
  velocity random_direction()
  status m { velocity = velocity + (0.01, 0) }
}
"""


class _Watcher:
    def __init__(self):
        self.seen: list = []

    def start(self, run):
        self.seen.append(("start", run.sim.tick))

    def tick(self, run):
        self.seen.append(("tick", run.sim.tick))

    def close(self, run, outcome):
        self.seen.append((outcome, run.sim.tick))


def test_an_attached_observer_sees_every_recorded_tick_then_the_end(compile_src, backend):
    run = Run(compile_src(PROGRAM), steps=5, every=2, backend=backend)
    watcher = _Watcher()
    run.attach(watcher)
    assert run.execute() == "completed"
    assert watcher.seen == [("start", 0), ("tick", 0), ("tick", 2), ("tick", 4),
                            ("tick", 5), ("completed", 5)]
    with pytest.raises(SwarmOptionError, match="before run.execute"):
        run.attach(_Watcher())


def test_a_headless_run_without_a_video_loads_no_viz(tmp_path):
    """The runtime reaches viz by name, on a run's first video or window."""
    program = tmp_path / "p.swarm"
    program.write_text(PROGRAM)
    code = ("import sys\nfrom swarmdsl.compiler import compile_file\n"
            "from swarmdsl.runtime.runner import Run\n"
            f"Run(compile_file({str(program)!r}), steps=3, backend='numpy').execute()\n"
            "print(sorted(m for m in sys.modules if m.startswith('swarmdsl.viz')))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"
