"""nn() in programs: checking without torch, one batched pass per call site, safe loading,
located runtime errors. (Static errors also live in tests/data/errors/nn_*.swarm.)"""

from __future__ import annotations

import difflib
import json
import pickle
import re
import subprocess
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.compiler import compile_file, compile_source
from swarmdsl.compiler.errors import SwarmError, SwarmRuntimeError
from swarmdsl.runtime.simulation import Simulation

ROOT = Path(__file__).resolve().parents[1]


def _torch():
    return pytest.importorskip("torch")


def write_model(folder: Path, name: str, n_in: int, n_out: int, hidden=(6,), seed=1
                ) -> Path:
    """A small random MLP and its sidecar, saved the way `swarmdsl train` saves one."""
    torch = _torch()
    from swarmdsl.runtime.nn import build_module

    folder.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(seed)
    module = build_module(n_in, tuple(hidden), n_out)
    pt = folder / f"{name}.pt"
    torch.save(module.state_dict(), pt)
    side = {"format": "swarmdsl-model", "arch": "mlp", "n_in": n_in, "n_out": n_out,
            "hidden": list(hidden), "activation": "relu",
            "normalisation": {"input": {"shift": [50.0] * n_in, "scale": [30.0] * n_in},
                              "output": {"shift": [5.0] * n_out, "scale": [2.0] * n_out}}}
    (folder / f"{name}.json").write_text(json.dumps(side))
    return pt


def write_program(folder: Path, text: str, name: str = "p.swarm") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def loaded(program, name: str):
    """The LoadedModel a compiled program uses for `models/NAME.pt`."""
    models = program.info.extra["nn"]
    path = next(p for p in models.uses if p.name == f"{name}.pt")
    return models.model(path)


@pytest.fixture
def models(tmp_path):
    write_model(tmp_path / "models", "one", 2, 1)
    write_model(tmp_path / "models", "two", 3, 2, seed=2)
    return tmp_path


AGENT_PROGRAM = """world {{ size 100 x 100 }}
agent a {{
  count {n}
  var out = 0
  var v = (0, 0)
  status s {{
    out = nn("models/one.pt", pos.x, pos.y)
    v = nn("models/two.pt", pos, pos.x * 0.5)
  }}
}}
"""

PAIR_PROGRAM = """world {{ size 100 x 100 }}
agent a {{
  count {n}
  var v = (0, 0)
  status s {{
    v = sum(neighbors(30) : nn("models/two.pt", other.pos - pos, dist))
  }}
}}
"""


# ---- checking ------------------------------------------------------------------------


def test_types_number_and_vector(models):
    prog = compile_file(write_program(models, AGENT_PROGRAM.format(n=3)))
    assert [p.name for p in prog.info.extra["nn"].uses] == ["one.pt", "two.pt"]


def test_check_does_not_import_torch(models):
    paths = [write_program(models, AGENT_PROGRAM.format(n=3)),
             ROOT / "programs" / "spring1d_nn.swarm", ROOT / "programs" / "matrix2d_nn.swarm"]
    code = ("import sys; from swarmdsl.cli import main\n"
            "for path in sys.argv[1:]: assert main(['check', path]) == 0, path\n"
            "assert 'torch' not in sys.modules, 'torch imported'")
    out = subprocess.run([sys.executable, "-c", code, *map(str, paths)], capture_output=True,
                         text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr


def test_missing_model_is_located(models):
    src = AGENT_PROGRAM.format(n=3).replace("models/one.pt", "models/none.pt")
    with pytest.raises(SwarmError) as info:
        compile_file(write_program(models, src))
    assert (info.value.span.line, info.value.span.col) == (7, 14)
    assert "model file 'models/none.pt' not found" in info.value.message


def test_symlink_out_of_folder_is_refused(tmp_path):
    outside = write_model(tmp_path / "elsewhere", "one", 2, 1)
    (tmp_path / "prog" / "models").mkdir(parents=True)
    (tmp_path / "prog" / "models" / "one.pt").symlink_to(outside)
    (tmp_path / "prog" / "models" / "one.json").symlink_to(outside.with_suffix(".json"))
    src = AGENT_PROGRAM.format(n=3).replace('    v = nn("models/two.pt", pos, pos.x * 0.5)\n',
                                            "")
    with pytest.raises(SwarmError) as info:
        compile_file(write_program(tmp_path / "prog", src))
    assert (info.value.span.line, info.value.span.col) == (7, 14)
    assert "resolves outside the program's folder" in info.value.message


def test_model_resolves_against_the_program_folder_not_cwd(models, tmp_path, monkeypatch):
    path = write_program(models, AGENT_PROGRAM.format(n=3))
    monkeypatch.chdir(tmp_path.parent)
    assert compile_file(path).info.extra["nn"].uses


@settings(max_examples=40)
@given(spec=st.text(st.characters(exclude_characters='"\\\n'), max_size=300)
       | st.builds(lambda n: "a" * n + ".pt", st.integers(200, 5000)))
@example(spec="a\x00b.pt")
@example(spec="a" * 5000 + ".pt")
@example(spec="models/../../x.pt")
def test_any_path_string_gives_a_located_error_not_a_crash(tmp_path_factory, spec):
    folder = tmp_path_factory.mktemp("paths")
    src = f'agent a {{\n  count 1\n  status s {{ velocity = (nn("{spec}", 1, 2), 0) }}\n}}\n'
    try:
        compile_source(src, str(folder / "p.swarm"))
    except SwarmError as err:
        assert err.span is not None
    assert sorted(p.name for p in folder.iterdir()) == []


def test_weights_file_must_be_pt(models):
    src = AGENT_PROGRAM.format(n=3).replace("models/one.pt", "models/one.json")
    with pytest.raises(SwarmError, match="must be a `.pt` weights file"):
        compile_file(write_program(models, src))


# ---- batching --------------------------------------------------------------------------


def _per_row(model, x: np.ndarray) -> np.ndarray:
    return np.array([model.forward(x[i : i + 1])[0] for i in range(x.shape[0])]
                    ).reshape(x.shape[0], model.n_out)


@settings(max_examples=25)
@given(n=st.integers(0, 40), seed=st.integers(0, 2**16))
def test_batched_equals_per_agent(backend, tmp_path_factory, n, seed):
    folder = tmp_path_factory.mktemp("agents")
    write_model(folder / "models", "one", 2, 1)
    write_model(folder / "models", "two", 3, 2, seed=2)
    prog = compile_file(write_program(folder, AGENT_PROGRAM.format(n=n)))
    sim = Simulation(prog, seed)
    pos = sim.agents.cols["pos"].copy()
    sim.step()
    one, two = loaded(prog, "one"), loaded(prog, "two")
    want_out = _per_row(one, pos)[:, 0] if n else np.zeros(0)
    x2 = np.column_stack([pos, pos[:, 0] * 0.5])
    want_v = _per_row(two, x2) if n else np.zeros((0, 2))
    # bit for bit: a row's output does not depend on how many rows share its pass
    assert sim.agents.cols["out"].tobytes() == want_out.tobytes()
    assert sim.agents.cols["v"].tobytes() == want_v.tobytes()


@settings(max_examples=20)
@given(n=st.integers(0, 40), seed=st.integers(0, 2**16))
def test_batched_over_pairs_equals_per_pair(backend, tmp_path_factory, n, seed):
    folder = tmp_path_factory.mktemp("pairs")
    write_model(folder / "models", "two", 3, 2, seed=2)
    prog = compile_file(write_program(folder, PAIR_PROGRAM.format(n=n)))
    sim = Simulation(prog, seed)
    pos = sim.agents.cols["pos"].copy()
    sim.step()
    two = loaded(prog, "two")
    want = np.zeros((n, 2))
    for i in range(n):  # the oracle: brute-force pairs, one forward per pair
        for j in range(n):
            d = float(np.hypot(*(pos[j] - pos[i])))
            if i != j and d <= 30:
                want[i] += two.forward(np.array([[*(pos[j] - pos[i]), d]]))[0]
    np.testing.assert_allclose(sim.agents.cols["v"], want, rtol=1e-10, atol=1e-9)


class _Spy:
    """Wraps a LoadedModel's forward to record the batch size of every call."""

    def __init__(self, model):
        self.model, self.calls = model, []
        self._forward = model.forward
        model.forward = self

    def __call__(self, x):
        self.calls.append(x.shape[0])
        return self._forward(x)


def test_one_forward_per_call_site_per_tick_over_reaching_agents(backend, models):
    src = """world { size 100 x 100 }
agent a {
  count 30
  place (index * 3, 50)
  var out = 0
  status s {
    when pos.x < 45 -> t
    out = nn("models/one.pt", pos.x, pos.y) + nn("models/one.pt", pos.y, pos.x)
  }
  status t { }
}
"""
    prog = compile_file(write_program(models, src))
    sim = Simulation(prog, 0)
    spy = _Spy(loaded(prog, "one"))
    sim.run(3)
    # tick 0: agents 15..29 reach both sites; later ticks the same agents (status s)
    assert spy.calls == [15] * 6
    out = sim.agents.cols["out"]
    assert np.all(out[:15] == 0)
    x = sim.agents.cols["pos"][15:]
    want = _per_row(spy.model, x)[:, 0] + _per_row(spy.model, x[:, ::-1])[:, 0]
    np.testing.assert_allclose(out[15:], want, rtol=1e-12)


def test_model_loads_once_per_program(backend, models, monkeypatch):
    import swarmdsl.runtime.nn as nnmod

    loads = []
    real = nnmod.load_model
    monkeypatch.setattr(nnmod, "load_model", lambda p: loads.append(p) or real(p))
    src = AGENT_PROGRAM.format(n=5).replace("models/two.pt", "./models//two.pt")
    src = src.replace("out = nn(", "out = nn(\"models/one.pt\", 1, 2) + nn(")
    prog = compile_file(write_program(models, src))
    assert loads == []  # compiling loads nothing
    Simulation(prog, 0).run(2)
    Simulation(prog, 1).run(2)
    assert sorted(p.name for p in loads) == ["one.pt", "two.pt"]


def test_same_seed_bit_identical(backend, models):
    prog = compile_file(write_program(models, PAIR_PROGRAM.format(n=40)))
    a, b = Simulation(prog, 7), Simulation(prog, 7)
    a.run(3)
    b.run(3)
    assert np.array_equal(a.agents.cols["v"], b.agents.cols["v"])


def test_nn_in_placement_and_shipped_models(backend):
    src = """world { size 300 x 300 }
agent a {
  count 4
  place (nn("models/spring1d.pt", index * 40, index * 40 + 80), 100)
  var t = (0, 0)
  status s {
    t = nn("models/matrix2d.pt", (6000, 6000), pos + (0, -40), pos - (40, 0), pos + (40, 0))
  }
}
"""
    _torch()
    prog = compile_source(src, "ship.swarm", program_dir=ROOT / "programs")
    sim = Simulation(prog, 0)
    np.testing.assert_allclose(sim.agents.cols["pos"][:, 0], [40, 80, 120, 160], atol=1.0)
    sim.step()
    # top row of a block at rest: target = own position (rest is a fixed point)
    np.testing.assert_allclose(sim.agents.cols["t"], sim.agents.cols["pos"], atol=1.5)


# ---- unsafe or broken models, runtime faults --------------------------------------------


class _Evil:
    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def test_pickle_with_code_is_refused_with_a_located_error(backend, models, capsys):
    marker = models / "pwned"
    (models / "models" / "one.pt").write_bytes(pickle.dumps({"0.weight": _Evil(marker)}))
    path = write_program(models, AGENT_PROGRAM.format(n=3))
    prog = compile_file(path)  # the sidecar is fine: checking passes
    with pytest.raises(SwarmRuntimeError) as info:
        Simulation(prog, 0)
    assert not marker.exists()
    err = info.value
    assert (err.span.line, err.span.col) == (7, 11)
    assert err.message.startswith("cannot load model 'models/one.pt': refusing to load")
    assert main(["run", str(path), "--headless", "--steps", "1"]) == 2
    lines = capsys.readouterr().err.splitlines()
    at = next(i for i, line in enumerate(lines) if ": error: " in line)
    assert lines[at].startswith(f"{path}:7:11: error: cannot load model 'models/one.pt'")
    assert lines[at + 2].index("^") == len("   7 | ") + 10
    assert not marker.exists()


def test_missing_torch_is_a_clear_error(backend, models, monkeypatch):
    prog = compile_file(write_program(models, AGENT_PROGRAM.format(n=3)))
    monkeypatch.setitem(sys.modules, "torch", None)
    with pytest.raises(SwarmError, match=r"pip install 'swarmdsl\[nn\]'"):
        Simulation(prog, 0)


def test_nan_input_names_call_site_kind_and_status(backend, models):
    src = AGENT_PROGRAM.format(n=3).replace("pos.x, pos.y)", "pos.x, sqrt(pos.y - 200))")
    prog = compile_file(write_program(models, src))
    with pytest.raises(SwarmRuntimeError) as info:
        Simulation(prog, 0).step()
    err = info.value
    assert (err.span.line, err.span.col) == (7, 11)
    assert "input 2 of nn(\"models/one.pt\") is NaN for agent 0" in err.message
    assert "kind `a`, status `s`, tick 0" in err.message


def test_non_finite_output_names_call_site(backend, models):
    prog = compile_file(write_program(models, AGENT_PROGRAM.format(n=3)))
    sim = Simulation(prog, 0)
    loaded(prog, "one")._mlp = lambda z: z[:, :1] * float("nan")  # a network gone bad
    with pytest.raises(SwarmRuntimeError) as info:
        sim.step()
    assert (info.value.span.line, info.value.span.col) == (7, 11)
    assert "kind `a`, status `s`" in info.value.message
    assert "non-finite" in info.value.message


def test_wrong_output_shape_names_call_site(backend, models):
    prog = compile_file(write_program(models, AGENT_PROGRAM.format(n=3)))
    sim = Simulation(prog, 0)
    model = loaded(prog, "two")
    model.forward = lambda x: np.zeros((x.shape[0], 3))
    with pytest.raises(SwarmRuntimeError) as info:
        sim.step()
    assert (info.value.span.line, info.value.span.col) == (8, 9)
    assert "returned shape (3, 3), expected (3, 2)" in info.value.message


# Six agents at x = 5, 15, ..., 55; the one at x = 35 is the bad one. Agent 0 is removed
# before the run, agent 1 starts in another status and agent 2 leaves the body before
# the call, so the bad agent's row in the batch (0), in the frame (1) and in the store
# (2) all differ from its id.
SHUFFLED = """world {{ size 100 x 100 }}
agent a {{
  count 6
  place (10 * index + 5, 50)
  initial if index == 1 then aside else s
  var out = 0
  status s {{
    when pos.x < 30 -> aside
    out = {call}
  }}
  status aside {{ }}
}}
"""


def _bad_agent_id(sim) -> int:
    cols = sim.agents.cols
    return int(cols["id"][np.flatnonzero(cols["pos"][:, 0] == 35)[0]])


def _fault(models, call: str, backend: str, break_model=False) -> tuple[str, int]:
    """The run-time message of `call` in SHUFFLED, and the bad agent's id."""
    prog = compile_file(write_program(models, SHUFFLED.format(call=call)))
    sim = Simulation(prog, 0, backend=backend)
    sim.agents.remove(sim.agents.cols["id"] == 0)
    if break_model:   # a network gone bad for one input: x = 35, -0.5 once normalised
        loaded(prog, "one")._mlp = lambda z: np.where(
            z[:, :1] == -0.5, float("nan"), z[:, :1])
    with pytest.raises(SwarmRuntimeError) as info:
        sim.step()
    return info.value.message, _bad_agent_id(sim)


def test_a_non_finite_output_names_the_agent_not_its_row_in_the_batch(models, backend):
    message, bad = _fault(models, 'nn("models/one.pt", pos.x, pos.y)', backend,
                          break_model=True)
    assert re.search(r"for agent (\d+) \(", message).group(1) == str(bad)
    assert "row" not in message
    assert "kind `a`, status `s`, tick 0" in message
    assert "from input 1 = 35, input 2 = 50" in message


def test_a_non_finite_input_names_the_agent_not_its_row(models, backend):
    message, bad = _fault(models, 'nn("models/one.pt", sqrt(pos.x - 36), pos.y)', backend)
    assert f"input 1 of nn(\"models/one.pt\") is NaN for agent {bad} (" in message


def test_over_pairs_it_names_the_agent_and_its_neighbour(backend, models):
    call = 'sum(neighbors(15) : nn("models/one.pt", pos.x, other.pos.y))'
    message, bad = _fault(models, call, backend, break_model=True)
    got = re.search(r"for agent (\d+) and its neighbour (\d+) \(", message)
    assert got.group(1) == str(bad) and got.group(2) != str(bad)


def test_the_model_error_keeps_its_row_for_callers_of_forward(backend, models):
    """Used from Python, the batch is the caller's own: the row is the useful part."""
    prog = compile_file(write_program(models, AGENT_PROGRAM.format(n=3)))
    Simulation(prog, 0)
    model = loaded(prog, "one")
    model._mlp = lambda z: np.where(z[:, :1] == -0.5, float("nan"), z[:, :1])
    from swarmdsl.runtime.nn import NonFiniteOutput

    with pytest.raises(NonFiniteOutput) as info:
        model.forward(np.array([[10.0, 0.0], [35.0, 0.0], [35.0, 1.0]]))
    assert info.value.row == 1 and info.value.inputs.tolist() == [35, 0]
    assert "first at row 1" in info.value.message
    again = pickle.loads(pickle.dumps(info.value))
    assert (again.row, again.message) == (1, info.value.message)


# ---- the documented example -------------------------------------------------------------


def test_docs_example_runs_and_settles(backend):
    _torch()
    doc = (ROOT / "docs" / "language-nn.md").read_text()
    src = doc.split("```swarm\n", 1)[1].split("```", 1)[0]
    prog = compile_source(src, "beads.swarm", program_dir=ROOT / "programs")
    sim = Simulation(prog, 0)
    sim.run(prog.world.steps)
    x = np.sort(sim.agents.cols["pos"][sim.agents.cols["kind"] == 1][:, 0])
    np.testing.assert_allclose(x, [38, 76, 114, 152], atol=2.0)


# ---- the experiment programs: network versions of the hard-coded ones --------------------

PAIRS = {"spring1d": "spring1d_nn", "matrix2d": "matrix2d_nn"}


def _rule_hunk(plain: str, nn: str):
    """The one changed block between a program and its network version: (removed, added).

    Besides it the network version may only add comment lines (its header)."""
    a, b = plain.splitlines(), nn.splitlines()
    hunks = [op for op in difflib.SequenceMatcher(a=a, b=b, autojunk=False).get_opcodes()
             if op[0] != "equal"]
    rule = [h for h in hunks if not (h[0] == "insert" and all(
        line.lstrip().startswith("#") for line in b[h[3]:h[4]]))]
    assert len(rule) == 1, f"expected one changed block, got {rule}"
    _tag, i1, i2, j1, j2 = rule[0]
    return a[i1:i2], b[j1:j2]


def _code(lines):
    return [line for line in lines if line.strip() and not line.lstrip().startswith("#")]


@pytest.mark.parametrize("plain, nn", PAIRS.items())
def test_nn_program_differs_only_in_the_rule(plain, nn):
    plain_src = (ROOT / "programs" / f"{plain}.swarm").read_text()
    nn_src = (ROOT / "programs" / f"{nn}.swarm").read_text()
    removed, added = _rule_hunk(plain_src, nn_src)
    # added: one line computing the target with the network (plus comments)
    (call,) = _code(added)
    assert re.fullmatch(rf'(\s*)let target = nn\("models/{plain}\.pt", [\w, ]+\)', call), call
    indent = len(call) - len(call.lstrip())
    # removed: the rule, `let`s (with continuation lines) ending in `let target = ...`,
    # whose helper names nothing in the network version reads
    lets = []
    for line in _code(removed):
        if len(line) - len(line.lstrip()) > indent:
            continue  # continuation of a multi-line `let`
        m = re.match(r"let (\w+) =", line.strip())
        assert m, f"not part of the rule: {line!r}"
        lets.append(m[1])
    assert lets[-1] == "target"
    rest = "\n".join(_code(nn_src.splitlines()))
    for name in set(lets) - {"target"}:
        assert not re.search(rf"\b{name}\b", rest), f"`{name}` is still read"


@cache
def _final(name: str):
    """Final true positions by id, and status counts, of a shipped program (seed 0)."""
    prog = compile_file(ROOT / "programs" / f"{name}.swarm")
    sim = Simulation(prog, 0)
    sim.run(prog.world.steps)
    order = np.argsort(sim.agents.cols["id"])
    return sim.agents.cols["pos"][order], sim.status_counts()


def test_spring1d_nn_ends_where_the_hard_coded_run_ends(backend):
    _torch()
    plain, plain_counts = _final("spring1d")
    nn, nn_counts = _final("spring1d_nn")
    assert nn_counts == plain_counts
    # Tolerance 1.5 units (4 % of the 38-unit spacing; measured 1.27). The network's mean
    # error is ~0.2 units, and at the chain's fixed point a robot's offset sums its
    # neighbours' errors with the gain of a 4-robot chain between fixed ends (up to ~6).
    np.testing.assert_allclose(nn[:, 0], plain[:, 0], atol=1.5)
    np.testing.assert_array_equal(nn[:, 1], plain[:, 1])
    gaps = np.diff(np.sort(nn[:, 0]))
    np.testing.assert_allclose(gaps, 38, atol=1.5)


def _rows(pos, agents, ys):
    """`agents` grouped into rows by their (hard-coded run's) y."""
    return [agents[np.abs(pos[agents, 1] - y) < 5] for y in ys]


def test_matrix2d_nn_ends_within_tolerance_of_the_hard_coded_run(backend):
    _torch()
    plain, plain_counts = _final("matrix2d")
    nn, nn_counts = _final("matrix2d_nn")
    assert nn_counts == plain_counts
    moved = np.flatnonzero(np.abs(plain - nn).max(axis=1) > 0)
    middle_ys = sorted({round(float(y), 2) for y in plain[moved, 1]})
    assert len(middle_ys) == 2  # only the two adjust rows differ
    for row in _rows(plain, moved, middle_ys):
        assert row.size == 3
        # Each robot's y and each row's width (how far the side columns moved inward)
        # within 1 unit (2.5 % of the spacing; measured 0.77 and 0.51). The hard-coded
        # run narrows each row by 6.2 units, and the network run too:
        np.testing.assert_allclose(nn[row, 1], plain[row, 1], atol=1.0)
        width = np.ptp(nn[row, 0])
        assert abs(width - np.ptp(plain[row, 0])) < 1.0 and width < 80 - 5
        assert nn[row, 1].min() > plain[row, 1].min() - 1
    # Whole positions within 3 units (measured 2.2): the rule leaves a middle row free to
    # slide sideways (midpoints and side offsets are translation-invariant), so the
    # network's small position-dependent error picks where along that slide it rests.
    np.testing.assert_allclose(nn, plain, atol=3.0)
