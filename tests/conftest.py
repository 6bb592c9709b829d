"""Shared fixtures: the backend a test runs its programs on (each in turn), compile
program text, run it, check its located errors; hypothesis profiles; reading the trails of
the ant-colony programs."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

# The grammar cache goes to a folder of the test session's own, not the user's cache.
_CACHE = tempfile.mkdtemp(prefix="swarmdsl-test-cache-")
atexit.register(shutil.rmtree, _CACHE, ignore_errors=True)
os.environ["SWARMDSL_CACHE_DIR"] = _CACHE
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
# A test that runs no program, or does not take the `backend` fixture below, runs the
# reference (numpy) backend: the variable is what an unnamed backend defaults to.
os.environ.setdefault("SWARMDSL_BACKEND", "numpy")
# Runs step tick by tick, so what a test sees of the per-tick kernels (pair tables, the
# parts `-v` lists) does not hang on whether another test left the whole-tick kernel of
# its program on disk; the tests of whole ticks ask for them (`test_tick_kernel.py`).
os.environ.setdefault("SWARMDSL_WHOLE_TICKS", "0")
# A test's process (and a command it starts) stops its background compiles as it exits,
# rather than leaving them to finish beside the next tests; tests/test_tiered.py checks
# that a compile goes on after its process ends, which is what users get.
os.environ.setdefault("SWARMDSL_COMPILE_AFTER_EXIT", "0")

# The default profile draws the same examples in every run, so the suite a change lands
# with gives the same verdict on any machine; `dev` and `long` draw new ones each run
# (README: the exploring runs).
settings.register_profile("ci", max_examples=60, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=200, deadline=None)
settings.register_profile("long", max_examples=2000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


# Every backend a program runs on, read from the backend registry
# (`runtime/backends.py`), the reference first: a backend a package registers (one row
# of `backends.PLUGINS`) runs every test that takes the `backend` fixture, with no list
# here to extend. One whose libraries are missing is skipped saying what to install.
REFERENCE = "numpy"     # the backend the others are compared against


def _registered() -> list[str]:
    from swarmdsl.runtime import backends

    names = [n for n in backends.names() if backends.plugin(n) is not None]
    return sorted(names, key=lambda n: n != REFERENCE)     # stable: registry order


def _param(name: str):
    from swarmdsl.runtime import backends

    got = backends.plugin(name)
    marks = () if got.installed() else pytest.mark.skip(
        reason=f"the {name} backend {got.missing or 'is not installed'}")
    return pytest.param(name, id=name, marks=marks)


BACKENDS = [_param(name) for name in _registered()]
# every backend but the reference, each compared with it (`other_backend`, `run_both`)
OTHER_BACKENDS = [_param(name) for name in _registered() if name != REFERENCE]


def backend_names() -> list[str]:
    """The installed backends, the reference first: for a test that runs one program
    on each in turn and compares them (hypothesis tests, which cannot take a
    parametrized fixture per example, and loops over every backend)."""
    from swarmdsl.runtime import backends

    return [name for name in _registered() if backends.installed(name)]


@pytest.fixture(scope="module", params=BACKENDS)
def backend(request) -> str:
    """The backend this run of the test runs its programs on: each registered backend
    in turn, the reference ("numpy") first.

    Pass it where the test makes a run (`Simulation(..., backend=backend)`,
    `Run(..., backend=backend)`, `--backend`); it is also `$SWARMDSL_BACKEND` while the
    test runs (`_backend_variable`), so a run made without naming one (the CLI, sweep
    workers, `swarmdsl test`) takes it too. Module-scoped, so that a module's fixtures
    can build their runs on it and hypothesis tests can take it."""
    return request.param


@pytest.fixture(scope="module", params=OTHER_BACKENDS)
def other_backend(request) -> str:
    """A backend that is not the reference, each in turn: the one a test compares
    with the reference (`run_both(..., other_backend)`)."""
    return request.param


@pytest.fixture(autouse=True)
def _backend_variable(request, monkeypatch):
    """`$SWARMDSL_BACKEND` is the test's backend, for a test that takes one."""
    if "backend" in request.fixturenames:
        monkeypatch.setenv("SWARMDSL_BACKEND", request.getfixturevalue("backend"))


@pytest.fixture
def compile_src():
    """Compile program text (default name `test.swarm`) into a Program."""
    from swarmdsl.compiler import compile_source

    def _compile(text: str, overrides=None, filename="test.swarm"):
        return compile_source(text, filename, overrides)
    return _compile


@pytest.fixture
def run_src(compile_src, backend):
    """Compile and run program text for `steps` ticks on the test's backend; return the
    Simulation."""
    from swarmdsl.runtime.simulation import Simulation

    def _run(text: str, steps: int = 1, seed: int = 0, overrides=None):
        sim = Simulation(compile_src(text, overrides), seed, backend=backend)
        sim.run(steps)
        return sim
    return _run


@pytest.fixture
def assert_located_error(compile_src):
    """Check that program text fails to compile with the line a user reads,
    `test.swarm:LINE:COL: error: TEXT`, given `message` as "LINE:COL: TEXT"."""
    from swarmdsl.compiler.errors import SwarmError

    def _check(text: str, message: str):
        with pytest.raises(SwarmError) as err:
            compile_src(text)
        where, said = message.split(": ", 1)
        assert f"test.swarm:{where}: error: {said}" in str(err.value)
    return _check


PROGRAMS = Path(__file__).resolve().parent.parent / "programs"


def shipped(name: str, seed: int = 3, overrides=None):
    """A Simulation of the shipped program `programs/NAME`, on the test's backend."""
    import swarmdsl
    from swarmdsl.runtime.simulation import Simulation

    return Simulation(swarmdsl.load_program(PROGRAMS / name, overrides), seed)


WALK = Path(__file__).parent / "data" / "walk.swarm"


@pytest.fixture
def walk(tmp_path) -> Path:
    """A copy of tests/data/walk.swarm in the test's folder: a program with a field, a
    metric and params of each type, so a run of it writes every output there is."""
    path = tmp_path / "walk.swarm"
    shutil.copyfile(WALK, path)
    return path


def cli_error(capsys, argv, code: int = 2) -> str:
    """Run a command that must fail with `code`; its error output, never a traceback."""
    from swarmdsl.cli import main

    assert main(argv) == code
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    return err


def run_both(text: str, steps: int = 1, seed: int = 0, overrides=None, other=None):
    """The program compiled once and run `steps` ticks on the reference backend and on
    `other` (a test's `other_backend`; None: the first other installed backend):
    (program, [reference simulation, other simulation])."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime import backends
    from swarmdsl.runtime.simulation import Simulation

    other = other or _first_other()
    if not backends.installed(other):
        pytest.skip(f"the {other} backend is not installed")
    prog = compile_source(text, "test.swarm", overrides)
    sims = []
    for backend in (REFERENCE, other):
        sim = Simulation(prog, seed, backend=backend)
        sim.run(steps)
        sims.append(sim)
    return prog, sims


def _first_other() -> str:
    others = backend_names()[1:]
    if not others:
        pytest.skip("no backend but the reference is installed")
    return others[0]


def assert_backends_agree(text: str, assert_same_state) -> None:
    """Every installed backend runs the first ticks of `text` to states
    `assert_same_state([reference, other], prog)` accepts, or faults as the reference
    does: the same located fault, at the same agent and tick. A program that does not
    compile is not an example (hypothesis `assume`)."""
    from hypothesis import assume

    from swarmdsl.compiler import compile_source
    from swarmdsl.compiler.errors import SwarmError
    from swarmdsl.runtime.simulation import Simulation

    try:
        prog = compile_source(text, "test.swarm")
    except SwarmError:
        assume(False)
    sims, faults = [], []
    for backend in backend_names():
        sim = Simulation(prog, 0, backend=backend)
        try:
            sim.run(2)
            faults.append(None)
        except SwarmError as err:   # e.g. `max(near : log(other.x))` of only x = 0: -inf
            faults.append(str(err))
        sims.append(sim)
    for sim, fault in zip(sims[1:], faults[1:], strict=True):
        assert fault == faults[0], sim.backend.name
        assert_same_state([sims[0], sim], prog)


def by_id(sim, col: str) -> np.ndarray:
    """A column ordered by agent id."""
    order = np.argsort(sim.agents.cols["id"])
    return sim.agents.cols[col][order]


def assert_same_outputs(a: Path, b: Path) -> None:
    """Two run folders hold the same recorded run: agent rows, field frames and, when
    the first has them, metrics, all bit for bit."""
    import pyarrow.parquet as pq

    assert pq.read_table(a / "agents.parquet").equals(pq.read_table(b / "agents.parquet"))
    with np.load(a / "fields.npz") as fa, np.load(b / "fields.npz") as fb:
        assert fa.files == fb.files
        for key in fa.files:
            assert np.array_equal(fa[key], fb[key]), key
    if (a / "metrics.parquet").exists():
        assert pq.read_table(a / "metrics.parquet").equals(
            pq.read_table(b / "metrics.parquet"))


TRAIL_SOURCES = ["alpha", "beta", "gamma", "delta", "epsilon"]   # nearest first


def first_links(program: Path, tmp_path, seed: int, steps: int) -> dict[str, int | None]:
    """Run an ant-colony program; the tick its trail first linked the nest to each
    food source (None: never), read from the recorded fields as a reader would."""
    from swarmdsl.analysis.trails import first_linked
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.runner import Run

    out = tmp_path / f"seed{seed}"
    Run(compile_file(program), seed=seed, steps=steps, out=out, every=10).execute()
    return {b: t for (_a, b), t in first_linked(out).items()}


def assert_near_sources_linked_first(links: list[dict]) -> None:
    """Over a few short runs: the two nearest sources always linked, the third in most
    runs, and never a farther one before a nearer one."""
    assert all(r["alpha"] is not None and r["beta"] is not None for r in links), links
    assert sum(r["gamma"] is not None for r in links) >= 2, links
    for r in links:
        assert r["alpha"] <= r["beta"]
        if r["gamma"] is not None:
            assert r["beta"] <= r["gamma"]


def runs_linking_every_source(links: list[dict]) -> list[dict]:
    """The runs whose trails reached all five sources."""
    return [r for r in links if all(r[s] is not None for s in TRAIL_SOURCES)]
