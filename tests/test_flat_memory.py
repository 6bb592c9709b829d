"""Flat memory: nothing a tick builds (frames, neighbour sets, the pair table) outlives it.

Reference counting alone must free a tick's objects: a cycle would keep every tick's
pair table alive until the garbage collector happens to run, which at thousands of
agents is hundreds of megabytes.
"""

from __future__ import annotations

import gc
import subprocess
import sys
import textwrap
import weakref
from pathlib import Path

import pytest

from swarmdsl.runtime.simulation import Simulation

ROOT = Path(__file__).resolve().parents[1]

# Every way a tick's objects can point at each other: a `let` holding a neighbour set
# and a filtered one, aggregates over them, a second kind and status, a transition with
# an action, and a deposit (a frame effect).
TWO_KINDS = """
world { size 200 x 200; edges wrap }
field scent { decay 0.1 }
agent a {
  count 60
  velocity random_direction()
  var seen = 0
  status roam {
    let near = neighbors(30)
    let close = near where dist < 10
    seen = count(close) + mean(near : other.vel.x)
    velocity += sum(close : normalize(pos - other.pos)) * 0.1
    deposit(scent, 1)
    when seen > 3 -> rest { seen = 0 }
  }
  status rest {
    let near = neighbors(20)
    velocity = nearest(near : other.vel)
    when count(near) < 2 -> roam
  }
}
agent b {
  count 20
  status watch { velocity = mean(neighbors(40) where other.kind == a : other.pos - pos) }
}
"""


def test_no_tick_leaves_cyclic_garbage(compile_src):
    sim = Simulation(compile_src(TWO_KINDS), 0)
    sim.run(3)
    gc.collect()
    gc.disable()
    try:
        tables = []
        for _ in range(20):
            sim.step()
            tables.append(weakref.ref(sim.pairs))
        alive = sum(ref() is not None for ref in tables)
        garbage = gc.collect()
    finally:
        gc.enable()
    assert alive == 1  # only the current tick's table
    assert garbage == 0  # nothing the collector would have had to free


def assert_last_table_freed_before_the_next(sim) -> None:
    """Each time the simulation builds a pair table, no earlier one is alive (after a
    collection: anything alive is held by a reference, not a cycle)."""
    sim.run(2)
    build = sim.backend.build_pairs
    built, checked = [], []

    def watched(*args):
        gc.collect()
        checked.append(sum(ref() is not None for ref in built))
        table = build(*args)
        built.append(weakref.ref(table))
        return table

    sim.backend.build_pairs = watched
    sim.run(4)
    assert checked == [0, 0, 0, 0] and built[-1]() is sim.pairs


def test_last_ticks_pair_table_is_freed_before_the_next_is_built(compile_src, backend):
    """At a million agents a pair table is hundreds of MB: two alive at once, while the
    next is built, is what set the peak (Vicsek: 1.19 GB; 0.81 GB with one).

    The numpy reference runs TWO_KINDS, every way a tick's objects can point at each
    other. numba runs the shipped boids, whose kernels the suite compiles anyway (its
    tables go through the same tick and numba's own build_pairs); TWO_KINDS on numba,
    a compile of its own, is in the slow suite."""
    if backend == "numba":
        pytest.importorskip("numba")
        from swarmdsl import load_program

        program = load_program(ROOT / "programs" / "boids.swarm", {"n": "60"})
    else:
        program = compile_src(TWO_KINDS)
    assert_last_table_freed_before_the_next(Simulation(program, 0, backend=backend))


@pytest.mark.slow
def test_last_ticks_pair_table_is_freed_before_the_next_is_built_two_kinds_numba(compile_src):
    pytest.importorskip("numba")
    assert_last_table_freed_before_the_next(
        Simulation(compile_src(TWO_KINDS), 0, backend="numba"))


@pytest.mark.parametrize("name", ["boids", "vicsek", "aco"])
def test_shipped_programs_leave_no_cyclic_garbage(name):
    from swarmdsl import load_program

    sim = Simulation(load_program(ROOT / "programs" / f"{name}.swarm"), 0)
    sim.run(2)
    gc.collect()
    gc.disable()
    try:
        sim.run(10)
        garbage = gc.collect()
    finally:
        gc.enable()
    assert garbage == 0


def test_resident_memory_stays_flat_over_100_ticks(backend):
    """2,000 boids, 100 ticks, in a fresh process: the resident set grows by a few MB.

    Before the frames were closed after each tick it grew by ~100 MB over 80 ticks and
    ~390 MB over 200 on numpy (each tick's pair table, ~2 MB, lived until a
    collection), and by more with the collector off.
    """
    code = textwrap.dedent(f"""
        import resource
        from swarmdsl import load_program
        from swarmdsl.runtime.simulation import Simulation

        def rss_mb():
            with open("/proc/self/statm") as f:
                return int(f.read().split()[1]) * resource.getpagesize() / 2**20

        program = load_program({str(ROOT / "programs" / "boids.swarm")!r},
                               {{"n": "2000", "width": "2683", "height": "2683"}})
        sim = Simulation(program, 0, backend={backend!r})
        sim.run(10)
        before = rss_mb()
        sim.run(100)
        print(rss_mb() - before)
    """)
    if not Path("/proc/self/statm").exists():
        pytest.skip("needs /proc to read the resident set size")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT)
    assert done.returncode == 0, done.stderr
    growth_mb = float(done.stdout.strip())
    assert growth_mb < 40, f"resident memory grew by {growth_mb:.0f} MB over 100 ticks"
