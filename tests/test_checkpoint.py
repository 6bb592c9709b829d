"""Checkpoints: a resumed run is bit-identical to an uninterrupted one, for every shipped
program; checkpoints of another program or version are refused; outputs continue."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.compiler import compile_file
from swarmdsl.compiler.errors import SwarmOptionError
from swarmdsl.runtime import checkpoint
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
SHIPPED = sorted(p.name for p in PROGRAMS.glob("*.swarm"))


@functools.cache
def _program(name):
    return compile_file(PROGRAMS / name)


def _state(sim) -> dict:
    out = {f"col/{k}": v for k, v in sim.agents.cols.items()}
    out.update({f"declared/{k}": v for k, v in sim.agents.declared.items()})
    for i, ext in enumerate(sim.extensions):
        for k, v in ext.state_dict(sim).items():
            out[f"ext/{i}/{k}"] = v
    out["tick"] = sim.tick
    out["rng"] = json.dumps(sim.rng.state(), sort_keys=True)
    return out


def _assert_identical(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], np.ndarray):
            assert a[k].dtype == b[k].dtype, k
            assert a[k].tobytes() == b[k].tobytes(), f"{k} differs after resuming"
        else:
            assert a[k] == b[k], k


@pytest.mark.parametrize("name", SHIPPED)
@settings(max_examples=4)
@given(stop=st.integers(0, 12), more=st.integers(1, 10), seed=st.integers(0, 1000))
def test_resumed_run_is_bit_identical(tmp_path_factory, name, stop, more, seed):
    program = _program(name)
    whole = Simulation(program, seed)
    whole.run(stop + more)
    first = Simulation(program, seed)
    first.run(stop)
    folder = tmp_path_factory.mktemp("ck") / "checkpoint"
    checkpoint.save(first, folder)
    resumed = Simulation(program, 12345)         # the checkpoint's seed wins
    checkpoint.load(resumed, folder)
    resumed.run(more)
    _assert_identical(_state(whole), _state(resumed))


def test_checkpoint_of_another_program_or_params_is_refused(tmp_path):
    sim = Simulation(_program("vicsek.swarm"), 1)
    sim.run(2)
    checkpoint.save(sim, tmp_path / "checkpoint")
    other = Simulation(compile_file(PROGRAMS / "vicsek.swarm", {"eta": "2"}), 1)
    with pytest.raises(SwarmOptionError, match="another program .* or other --set values"):
        checkpoint.load(other, tmp_path / "checkpoint")
    with pytest.raises(SwarmOptionError, match="another program"):
        checkpoint.load(Simulation(_program("boids.swarm"), 1), tmp_path / "checkpoint")


def test_checkpoint_of_another_version_is_refused(tmp_path):
    sim = Simulation(_program("vicsek.swarm"), 1)
    checkpoint.save(sim, tmp_path / "checkpoint")
    meta = json.loads((tmp_path / "checkpoint" / "meta.json").read_text())
    meta["version"] = "0.0.1"
    (tmp_path / "checkpoint" / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(SwarmOptionError, match="written by swarmdsl 0.0.1"):
        checkpoint.load(Simulation(_program("vicsek.swarm"), 1), tmp_path / "checkpoint")
