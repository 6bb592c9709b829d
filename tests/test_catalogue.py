"""The catalogue of real bugs (`tests/data/catalogue/`, documented in
docs/language-properties.md): for each buggy program a plain checked run fails,
`swarmdsl test` finds the failure within its default budget and shrinks it to a
checked 1-minimal case, and the fixed version (`NAME_fixed.swarm`) passes.

CI checks a few of them, the fixed versions with a short hunt; `-m slow` checks every
one with the default budget (`python -m benchmarks.bench_catalogue` times them).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from swarmdsl.testing import run_program, search
from swarmdsl.testing.runner import load
from swarmdsl.testing.search import horizon

CATALOGUE = Path(__file__).parent / "data" / "catalogue"
DOCS = Path(__file__).parent.parent / "docs" / "language-properties.md"
BUGGY = sorted(p.stem for p in CATALOGUE.glob("*.swarm") if not p.stem.endswith("_fixed"))
FAST = ["collector", "lost_trail"]      # two kinds interacting, fields


def test_every_catalogue_program_is_documented_and_has_a_fixed_version():
    text = DOCS.read_text()
    section = text.split("## A catalogue of real bugs", 1)[1].split("\n## ", 1)[0]
    documented = sorted(set(re.findall(r"^\| `(\w+)\.swarm` \|", section, re.M)))
    assert documented == BUGGY and len(BUGGY) >= 12
    for name in BUGGY:
        assert (CATALOGUE / f"{name}_fixed.swarm").exists(), name


def _assert_plain_run_fails(name: str) -> None:
    """A plain checked run (`swarmdsl run FILE --check --seed S`, S = 0, 1, 2: the
    seeds the hunt runs the program as written at) fails; of the fixed version, none."""
    prog = load(CATALOGUE / f"{name}.swarm")
    steps, _ = horizon(prog, None, 0)
    assert any(not run_program(prog, steps, seed=s).ok for s in range(3)), \
        f"{name}: plain runs pass"
    fixed = load(CATALOGUE / f"{name}_fixed.swarm")
    assert all(run_program(fixed, steps, seed=s).ok for s in range(3)), \
        f"{name}_fixed: a plain run fails"


def _assert_found_minimal(name: str, **options) -> None:
    report = search(CATALOGUE / f"{name}.swarm", hypothesis_seed_value=0, **options)
    ce = report.counterexample
    assert ce is not None, f"{name}: no counterexample"
    assert ce.minimal, ce.describe(name)
    assert "1-minimal: " in ce.describe(name)


def _assert_fixed_passes(name: str, **options) -> None:
    report = search(CATALOGUE / f"{name}_fixed.swarm", hypothesis_seed_value=0, **options)
    assert report.counterexample is None, report.counterexample.describe(name)
    assert report.unexercised() == [], name


@pytest.mark.parametrize("name", FAST)
def test_a_catalogue_bug_is_found_minimal_and_its_fix_passes(backend, name):
    _assert_plain_run_fails(name)
    _assert_found_minimal(name)
    _assert_fixed_passes(name, max_examples=8)


@pytest.mark.slow
@pytest.mark.parametrize("name", BUGGY)
def test_every_catalogue_bug_is_found_minimal_and_its_fix_passes_long(backend, name):
    _assert_plain_run_fails(name)
    _assert_found_minimal(name)
    _assert_fixed_passes(name)
