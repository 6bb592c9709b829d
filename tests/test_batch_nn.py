"""`nn()` in a batch of replicas: one forward pass for the whole batch, each replica
bit-identical to its solo run.

A batch hands the network every replica's rows at once, so a row's output must not
depend on how many rows share the pass. torch's matrix product does not give that
(MKL rounds the rows past the last multiple of 4 with another kernel); the forward pass
(`runtime/nn.py`) sums each row on its own, and these tests hold it to that.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl import load_program
from swarmdsl.compiler.lang_nn import EXTRA_KEY
from swarmdsl.runtime.batch import BatchedSimulation, batch_refusal
from swarmdsl.runtime.metrics import MetricLog
from swarmdsl.runtime.simulation import Simulation

pytest.importorskip("torch")

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
MODELS = PROGRAMS / "models"
NOISY = {"turn_noise": 0.1, "pace_noise": 0.1}   # replicas that differ from each other
# program -> (params, ticks): short runs that reach the network in most ticks (the
# matrix's middle rows adjust from `shift_at` on)
RUNS = {"spring1d_nn": (NOISY, 14), "matrix2d_nn": ({**NOISY, "shift_at": 8}, 24)}
SEEDS = [3, 7, 2**40 + 5]


def _spy_on_models(program) -> list[int]:
    """Record the row count of every forward pass of `program`'s models."""
    calls: list[int] = []
    models = program.info.extra[EXTRA_KEY]
    for path in models.uses:
        model = models.model(path)
        forward = model.forward

        def spy(x, forward=forward):
            calls.append(x.shape[0])
            return forward(x)
        model.forward = spy
    return calls


@pytest.mark.parametrize("name", sorted(RUNS))
def test_nn_programs_batch_to_their_solo_runs(name, backend):
    params, ticks = RUNS[name]
    program = load_program(PROGRAMS / f"{name}.swarm", params)
    assert batch_refusal(program) is None
    batch = BatchedSimulation(program, SEEDS, backend=backend)
    calls = _spy_on_models(program)
    batch.run(ticks)
    passes = len(calls)
    assert passes > ticks // 2   # the network ran in most ticks, once for all replicas
    rows = batch.metric_rows()
    for r, seed in enumerate(SEEDS):
        solo = Simulation(program, seed, backend=backend)
        solo.run(ticks)
        view = batch.replica(r)
        for col, values in solo.agents.cols.items():
            got = view.agents.cols[col]
            assert got.dtype == values.dtype and got.tobytes() == values.tobytes(), \
                f"replica {r} (seed {seed}): column {col} differs"
        log = MetricLog(program)
        log.sample(solo)
        assert log.pending()[1].reshape(-1).tobytes() == rows[r].tobytes()
        assert view.status_counts() == solo.status_counts()
    solo_rows = sum(calls[passes:])
    # the batch's passes held every replica's rows: as many rows as the solo runs' passes
    assert sum(calls[:passes]) == solo_rows
    assert len(calls) - passes > passes   # the solo runs took more passes for them


def test_rows_not_a_multiple_of_four_reach_the_batch_too():
    """The replicas' rows in one pass come in counts torch's kernel rounds apart (rows
    past the last multiple of 4): the runs above would differ if the pass were torch's."""
    params, ticks = RUNS["matrix2d_nn"]
    program = load_program(PROGRAMS / "matrix2d_nn.swarm", params)
    batch = BatchedSimulation(program, SEEDS, backend="numpy")
    calls = _spy_on_models(program)
    batch.run(ticks)
    assert any(n % 4 for n in calls)


@pytest.fixture(scope="module")
def models():
    from swarmdsl.runtime.nn import load_model

    return {name: load_model(MODELS / f"{name}.pt") for name in ("matrix2d", "spring1d")}


@settings(max_examples=40, deadline=None)
@given(name=st.sampled_from(["matrix2d", "spring1d"]), m=st.integers(1, 300),
       cut=st.lists(st.integers(0, 300), max_size=4), seed=st.integers(0, 2**16))
def test_a_row_gets_the_same_bits_in_any_pass(models, name, m, cut, seed):
    """Rows split into passes of any sizes give the bits of one pass over them all."""
    model = models[name]
    x = np.random.default_rng(seed).uniform(-20, 220, size=(m, model.n_in))
    x[::7] = 6000.0   # the matrix's ghost neighbours (clipped inputs)
    whole = model.forward(x)
    edges = sorted({0, m, *(c % (m + 1) for c in cut)})
    parts = [model.forward(x[a:b]) for a, b in zip(edges, edges[1:], strict=False)]
    assert np.concatenate(parts).tobytes() == whole.tobytes()


def test_the_pass_is_the_network_torch_runs(models):
    """The same network as the torch module it was loaded into, to rounding."""
    import torch

    for model in models.values():
        x = np.random.default_rng(1).uniform(-20, 220, size=(500, model.n_in))
        z = (x - model._in_shift) / model._in_scale
        if model._clip is not None:
            z = np.clip(z, *model._clip)
        with torch.no_grad():
            want = model._module(torch.from_numpy(z)).numpy()
        want = want * model._out_scale + model._out_shift
        np.testing.assert_allclose(model.forward(x), want, rtol=1e-12, atol=1e-10)


def test_a_batch_without_nn_imports_no_torch():
    code = ("import sys\n"
            "from swarmdsl import load_program\n"
            "from swarmdsl.runtime.batch import BatchedSimulation\n"
            f"p = load_program({str(PROGRAMS / 'spring1d.swarm')!r})\n"
            "BatchedSimulation(p, [1, 2], backend='numpy').run(2)\n"
            "assert 'torch' not in sys.modules, 'torch imported'\n")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
