"""Every ```swarm example in the language documentation compiles and runs."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from swarmdsl.compiler import compile_source
from swarmdsl.runtime.simulation import Simulation

DOCS = Path(__file__).resolve().parent.parent / "docs"


def _examples():
    for path in sorted(DOCS.glob("language*.md")):
        for i, block in enumerate(re.findall(r"```swarm\n(.*?)```", path.read_text(), re.S)):
            yield pytest.param(path, block, id=f"{path.stem}-{i}")


EXAMPLES = list(_examples())


def test_language_reference_has_examples():
    assert len(EXAMPLES) >= 7


@pytest.mark.parametrize("path, source", EXAMPLES)
def test_doc_example_runs(path, source):
    # examples run as if saved in programs/, beside the shipped models
    program = compile_source(source, f"{path.name}-example.swarm",
                             program_dir=DOCS.parent / "programs")
    sim = Simulation(program, seed=0)
    sim.run(10)
    assert np.isfinite(sim.agents.cols["pos"]).all()
