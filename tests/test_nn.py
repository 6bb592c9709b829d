"""Model runtime: path rules, sidecars, safe loading, batched forward."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.runtime.nn import (
    ModelError,
    load_model,
    read_model_info,
    resolve_model_path,
)

torch = pytest.importorskip("torch")

MODELS = Path(__file__).resolve().parents[1] / "programs" / "models"


def _write_model(folder: Path, name: str = "m", n_in: int = 3, hidden=(5,), n_out: int = 2,
                 state=None, extra: dict | None = None) -> Path:
    """A small random MLP saved the way `swarmdsl train` saves one."""
    from swarmdsl.runtime.nn import build_module

    folder.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(1)
    module = build_module(n_in, tuple(hidden), n_out)
    pt = folder / f"{name}.pt"
    torch.save(module.state_dict() if state is None else state, pt)
    data = {
        "format": "swarmdsl-model",
        "arch": "mlp",
        "n_in": n_in,
        "n_out": n_out,
        "hidden": list(hidden),
        "activation": "relu",
        "normalisation": {
            "input": {"shift": [1.0] * n_in, "scale": [2.0] * n_in},
            "output": {"shift": [10.0] * n_out, "scale": [3.0] * n_out},
        },
        **(extra or {}),
    }
    (folder / f"{name}.json").write_text(json.dumps(data))
    return pt


# --- paths -------------------------------------------------------------------------


def test_resolve_relative_path(tmp_path):
    pt = _write_model(tmp_path / "models")
    assert resolve_model_path("models/m.pt", tmp_path) == pt.resolve()


@pytest.mark.parametrize("spec", ["/etc/passwd", "\\\\server\\share\\m.pt", "C:\\m.pt", "~/m.pt"])
def test_resolve_refuses_absolute(tmp_path, spec):
    with pytest.raises(ModelError, match="absolute"):
        resolve_model_path(spec, tmp_path)


@pytest.mark.parametrize("spec", ["../m.pt", "models/../../m.pt", "models/../m.pt", "..\\m.pt"])
def test_resolve_refuses_dotdot(tmp_path, spec):
    _write_model(tmp_path)
    with pytest.raises(ModelError, match=r"'\.\.'"):
        resolve_model_path(spec, tmp_path / "prog")


def test_resolve_refuses_symlink_outside(tmp_path):
    outside = _write_model(tmp_path / "elsewhere")
    prog = tmp_path / "prog"
    (prog / "models").mkdir(parents=True)
    os.symlink(outside, prog / "models" / "m.pt")
    with pytest.raises(ModelError, match="outside the program's folder"):
        resolve_model_path("models/m.pt", prog)
    os.symlink(tmp_path / "elsewhere", prog / "linkdir")
    with pytest.raises(ModelError, match="outside the program's folder"):
        resolve_model_path("linkdir/m.pt", prog)


def test_resolve_symlink_inside_is_fine(tmp_path):
    pt = _write_model(tmp_path / "models")
    os.symlink(pt, tmp_path / "alias.pt")
    assert resolve_model_path("alias.pt", tmp_path) == pt.resolve()


def test_resolve_missing_and_empty(tmp_path):
    with pytest.raises(ModelError, match="not found"):
        resolve_model_path("models/nope.pt", tmp_path)
    with pytest.raises(ModelError, match="empty"):
        resolve_model_path("  ", tmp_path)
    (tmp_path / "adir").mkdir()
    with pytest.raises(ModelError, match="not a file"):
        resolve_model_path("adir", tmp_path)


# --- sidecar -----------------------------------------------------------------------


def test_read_model_info_does_not_import_torch():
    code = (
        "import sys; import swarmdsl.runtime.nn as nn; "
        f"info = nn.read_model_info({str(MODELS / 'matrix2d.pt')!r}); "
        "assert (info.n_in, info.n_out) == (8, 2), info; "
        "assert 'torch' not in sys.modules, 'torch imported'"
    )
    env = {**os.environ, "PYTHONPATH": str(MODELS.parents[1])}
    subprocess.run([sys.executable, "-c", code], check=True, env=env)


def test_shipped_sidecars():
    s = read_model_info(MODELS / "spring1d.pt")
    assert (s.n_in, s.n_out, s.hidden, s.activation) == (2, 1, (4,), "relu")
    m = read_model_info(MODELS / "matrix2d.json")  # the sidecar path works too
    assert (m.n_in, m.n_out, m.hidden) == (8, 2, (32, 32))
    assert m.inputs[0] == "up.x" and m.layer_widths == (8, 32, 32, 2)


@pytest.mark.parametrize(
    "patch, match",
    [
        ({"format": "other"}, "'format'"),
        ({"arch": "cnn"}, "unsupported 'arch'"),
        ({"n_in": 0}, "'n_in' must be a positive integer"),
        ({"n_out": "2"}, "'n_out' must be a positive integer"),
        ({"hidden": [4, -1]}, "'hidden'"),
        ({"activation": "gelu"}, "unknown 'activation'"),
        ({"normalisation": {"input": {"shift": [0.0], "scale": [1.0, 1.0, 1.0]}}}, "3 finite"),
        ({"normalisation": {"output": {"scale": [0.0, 1.0]}}}, "must not contain 0"),
        ({"normalisation": {"input": {"clip": [3, 1]}}}, "low < high"),
        ({"inputs": ["a"]}, "'inputs' must list 3 names"),
    ],
)
def test_bad_sidecar(tmp_path, patch, match):
    pt = _write_model(tmp_path, extra=patch)
    with pytest.raises(ModelError, match=match):
        read_model_info(pt)


def test_missing_or_broken_sidecar(tmp_path):
    pt = _write_model(tmp_path)
    pt.with_suffix(".json").write_text("{not json")
    with pytest.raises(ModelError, match="not valid JSON"):
        read_model_info(pt)
    pt.with_suffix(".json").unlink()
    with pytest.raises(ModelError, match="no sidecar 'm.json'"):
        load_model(pt)


# --- safe loading ------------------------------------------------------------------


class _Evil:
    """Unpickling this would create a file: proof that code ran."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def test_refuses_pickle_with_code(tmp_path):
    marker = tmp_path / "pwned"
    pt = _write_model(tmp_path)
    pt.write_bytes(pickle.dumps({"0.weight": _Evil(marker)}))
    with pytest.raises(ModelError, match="refusing to load model 'm.pt'") as err:
        load_model(pt)
    assert not marker.exists()
    assert "weights_only=False" not in str(err.value)  # torch's advice would run the code


def test_refuses_torch_saved_object_with_code(tmp_path):
    marker = tmp_path / "pwned"
    pt = _write_model(tmp_path)
    torch.save({"0.weight": _Evil(marker)}, pt)
    assert not marker.exists()  # saving pickles the recipe, it does not run it
    with pytest.raises(ModelError, match="refusing to load"):
        load_model(pt)
    assert not marker.exists()


def test_refuses_whole_pickled_module(tmp_path):
    from swarmdsl.runtime.nn import build_module

    pt = _write_model(tmp_path)
    torch.save(build_module(3, (5,), 2), pt)
    with pytest.raises(ModelError, match="refusing to load"):
        load_model(pt)


def test_refuses_non_state_dict(tmp_path):
    pt = _write_model(tmp_path, state=[torch.zeros(2)])
    with pytest.raises(ModelError, match="does not hold a state_dict"):
        load_model(pt)


def test_refuses_garbage_file(tmp_path):
    pt = _write_model(tmp_path)
    pt.write_bytes(b"\x00not a torch file at all")
    with pytest.raises(ModelError, match="refusing to load"):
        load_model(pt)


def test_sidecar_state_mismatch(tmp_path):
    pt = _write_model(tmp_path, hidden=(5,))
    side = json.loads(pt.with_suffix(".json").read_text())
    side["hidden"] = [6]
    pt.with_suffix(".json").write_text(json.dumps(side))
    with pytest.raises(ModelError, match=r"does not match its sidecar \(3-6-2 mlp\).*shape"):
        load_model(pt)
    side["hidden"] = [5, 5]
    pt.with_suffix(".json").write_text(json.dumps(side))
    with pytest.raises(ModelError, match="missing"):
        load_model(pt)


def test_non_finite_weights(tmp_path):
    from swarmdsl.runtime.nn import build_module

    sd = build_module(3, (5,), 2).state_dict()
    sd["0.bias"][0] = float("nan")
    pt = _write_model(tmp_path, state=sd)
    with pytest.raises(ModelError, match="non-finite weights in '0.bias'"):
        load_model(pt)


def test_weights_beyond_float32_are_non_finite(tmp_path):
    """A float64 weight past float32's range turns infinite in the module's layers."""
    from swarmdsl.runtime.nn import build_module

    sd = {k: v.double() for k, v in build_module(3, (5,), 2).state_dict().items()}
    sd["2.weight"][0, 0] = 1e300
    pt = _write_model(tmp_path, state=sd)
    with pytest.raises(ModelError, match="non-finite weights in '2.weight'"):
        load_model(pt)


# --- forward -----------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_model(tmp_path_factory):
    return load_model(_write_model(tmp_path_factory.mktemp("m")))


def test_forward_applies_normalisation(small_model):
    x = np.array([[1.0, 2.0, 3.0], [0.0, -1.0, 5.0]])
    with torch.no_grad():
        raw = small_model._module(torch.from_numpy((x - 1.0) / 2.0)).numpy()
    np.testing.assert_allclose(small_model.forward(x), raw * 3.0 + 10.0)


@settings(max_examples=25, deadline=None)
@given(m=st.integers(0, 300), seed=st.integers(0, 2**16))
def test_batched_equals_per_row(small_model, m, seed):
    x = np.random.default_rng(seed).uniform(-100, 100, size=(m, 3))
    out = small_model.forward(x)
    assert out.shape == (m, 2) and out.dtype == np.float64
    rows = [small_model.forward(x[i : i + 1]) for i in range(m)]
    expected = np.concatenate(rows) if rows else np.empty((0, 2))
    assert out.tobytes() == expected.tobytes()   # bit for bit, for any batch size


def test_forward_shape_errors(small_model):
    with pytest.raises(ModelError, match=r"takes \(M, 3\) inputs, got shape \(4, 2\)"):
        small_model.forward(np.zeros((4, 2)))
    with pytest.raises(ModelError, match="got shape"):
        small_model.forward(np.zeros(3))
    assert small_model.forward(np.zeros((0, 3))).shape == (0, 2)


def test_forward_nan_raises(small_model):
    x = np.zeros((3, 3))
    x[1, 0] = np.nan
    with pytest.raises(ModelError, match="non-finite output.*row 1"):
        small_model.forward(x)


def test_clip_is_applied(tmp_path):
    pt = _write_model(tmp_path, extra={"normalisation": {"input": {"clip": [-1.0, 1.0]}}})
    model = load_model(pt)
    np.testing.assert_allclose(
        model.forward(np.array([[5.0, 0.2, -9.0]])),
        model.forward(np.array([[1.0, 0.2, -1.0]])),
    )


def test_shipped_models_load():
    s = load_model(MODELS / "spring1d.pt")
    np.testing.assert_allclose(s.forward(np.array([[0.0, 76.0]])), [[38.0]], atol=0.5)
    m = load_model(MODELS / "matrix2d.pt")
    assert m.forward(np.zeros((1, 8))).shape == (1, 2)
    assert "2-4-1" in repr(s)
