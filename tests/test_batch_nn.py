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
from test_batch import assert_replicas_are_solo_runs

from swarmdsl import load_program
from swarmdsl.compiler.lang_nn import EXTRA_KEY
from swarmdsl.runtime.batch import BatchedSimulation, batch_refusal
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
    calls = _spy_on_models(program)
    batch = BatchedSimulation(program, SEEDS, backend=backend)
    batch.run(ticks)
    passes = len(calls)
    assert passes > ticks // 2   # the network ran in most ticks, once for all replicas
    assert_replicas_are_solo_runs(program, SEEDS, backend, ticks)
    # the second batch's passes, then the solo runs': as many rows, in fewer passes
    assert calls[passes:2 * passes] == calls[:passes]
    solo = calls[2 * passes:]
    assert sum(solo) == sum(calls[:passes]) and len(solo) > passes


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


# ---- objectives toward another kind's agents: searched per replica ----

# Hunters chase the nearest prey, prey flee the nearest hunter, hunters keep an eye on
# the nearest other hunter; at tick 0 hunter 0 is as far from prey 0 as from prey 1 (a
# tie the search breaks as the solo run's does).
_HUNT = """world {{ size 100 x 100; edges {edges} }}
agent hunter {{
  count 4
  place (25 + 20 * index, 50)
  var seen = (0, 0)
  objective quarry = prey
  objective pal = hunter
  status chase {{
    velocity = approach(quarry, 2) + toward(quarry) * uniform(0, 0.3)
    seen = target(pal)
    when arrived(quarry, 3) -> rest
  }}
  status rest {{ when chance(0.3) -> chase }}
}}
agent prey {{
  count 5
  place (15 + 20 * index, 50 + uniform(-1, 1) * min(index, 1))
  objective threat = hunter
  metric spread = mean(length(target(threat) - pos))
  status run {{ velocity = toward(threat) * -1.5 + (normal(0, 0.5), normal(0, 0.5)) }}
}}
"""


@pytest.mark.parametrize("edges", ["wall", "wrap"])
def test_objectives_toward_another_kind_batch_to_their_solo_runs(edges, backend):
    from swarmdsl.compiler import compile_source

    program = compile_source(_HUNT.format(edges=edges), "hunt.swarm")
    assert batch_refusal(program) is None
    assert_replicas_are_solo_runs(program, [1, 4, 2**33 + 9], backend, 25)
    # the runs differ, so a search across replicas would have found other agents
    seen = []
    for seed in (1, 4):
        solo = Simulation(program, seed, backend=backend)
        solo.run(25)
        seen.append(solo.agents.cols["seen"].tobytes())
    assert seen[0] != seen[1]


# Objectives toward a region and a region kind (the nearest point of the nearest one):
# per agent, regions being shapes the same in every replica.
_HOME = _HUNT.replace("objective pal = hunter", "objective pal = nest").replace(
    "objective threat = hunter", "objective threat = hunter\n  objective hide = den") + """
nest den = rect(0, 0, 10, 10)
nest far = circle(80, 20, 8)
"""


@pytest.mark.parametrize("edges", ["wall", "wrap"])
def test_objectives_toward_regions_batch_to_their_solo_runs(edges, backend):
    from swarmdsl.compiler import compile_source

    src = _HOME.format(edges=edges).replace(
        "velocity = toward(threat) * -1.5", "velocity = toward(threat) * -1.5 + "
        "approach(hide, 0.5)")
    program = compile_source(src, "home.swarm")
    assert batch_refusal(program) is None
    assert_replicas_are_solo_runs(program, [2, 5, 2**35 + 1], backend, 25)


# nn() over neighbour pairs (one pass over every replica's pairs), and an input that is
# NaN for the agents `chance` picks: a fault in some seeds only.
_PAIRS = """world {{ size 60 x 60; edges wrap }}
agent a {{
  count 9
  var pull = 0
  status s {{
    pull = sum(neighbors(25) : nn("models/matrix2d.pt", other.pos, pos, other.pos - pos, pos).x)
    velocity = (clamp(pull / 500, -1, 1), uniform(-1, 1)){bad}
  }}
}}
"""


def test_nn_over_neighbour_pairs_batches_to_its_solo_runs(backend):
    from swarmdsl.compiler import compile_source

    program = compile_source(_PAIRS.format(bad=""), "pairs.swarm", program_dir=PROGRAMS)
    assert batch_refusal(program) is None
    calls = _spy_on_models(program)
    assert_replicas_are_solo_runs(program, [1, 2, 3], backend, 8)
    # the batch: one pass a tick over every replica's pairs; then each solo run's own
    assert len(calls) == 4 * 8 and sum(calls[:8]) == sum(calls[8:]) > 0


def test_an_nn_fault_in_one_replica_is_its_solo_fault(backend):
    from swarmdsl.compiler import compile_source
    from swarmdsl.errors import SwarmRuntimeError
    from swarmdsl.runtime.batch import ReplicaFault

    bad = "\n    let odd = nn(\"models/spring1d.pt\", sqrt(if chance(0.1) then -1 else 1), 0)"
    program = compile_source(_PAIRS.format(bad=bad), "pairs.swarm", program_dir=PROGRAMS)
    faults = {}
    for seed in range(12):
        try:
            Simulation(program, seed, backend=backend).step()
            faults[seed] = None
        except SwarmRuntimeError as err:
            faults[seed] = str(err)
    good = [s for s, f in faults.items() if f is None]
    failing = [s for s, f in faults.items() if f is not None]
    assert good and failing
    batch = BatchedSimulation(program, [good[0], failing[0]], backend=backend)
    with pytest.raises(ReplicaFault) as got:
        batch.step()
    assert got.value.replica == 1 and str(got.value.error) == faults[failing[0]]
