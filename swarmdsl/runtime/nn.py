"""Safe loading of `nn(...)` models and one batched forward pass per call site.

A model is two files side by side: `NAME.pt`, a torch `state_dict` of plain tensors, and
`NAME.json`, a sidecar naming the architecture, the input/output widths and the
normalisation. The sidecar is plain JSON so the checker can verify call arity without
importing torch (a 2-3 s import); torch is imported only inside `load_model` and the
functions it calls. Weights load with `torch.load(weights_only=True)`, which refuses any
pickle that would construct arbitrary objects, so a model file can never run code.

The forward pass itself is numpy, not torch: every output is the sequential sum
`x[0] * w[0] + x[1] * w[1] + ... + bias`, one elementwise multiply and add per input
column over all rows at once, so a row's result does not depend on how many rows share
the pass. torch's matrix product (MKL's) rounds a row differently by where it falls in
the call (rows past the last multiple of 4 take another kernel), which would make an
agent's output depend on how many agents share its status, and a batch of replicas
(one pass for all of them) differ from its solo runs. The numbers are plain IEEE
multiplies and adds, the same on every machine and BLAS.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

import numpy as np

from swarmdsl.errors import SwarmError
from swarmdsl.files import (
    MAX_SIDECAR_BYTES,
    MAX_WEIGHTS_BYTES,
    ContainmentError,
    check_regular,
    read_json,
)
from swarmdsl.ops import portable, portable_runtime

__all__ = [
    "ACTIVATIONS",
    "SIDECAR_FORMAT",
    "LoadedModel",
    "ModelError",
    "ModelInfo",
    "NonFiniteOutput",
    "build_module",
    "load_model",
    "parse_sidecar",
    "read_model_info",
    "resolve_model_path",
    "sidecar_path",
]

SIDECAR_FORMAT = "swarmdsl-model"
"""Value of the sidecar's `format` key; guards against loading some other JSON file."""

ACTIVATIONS = ("relu", "tanh", "sigmoid")


class ModelError(SwarmError):
    """A model that cannot be used: bad path, bad sidecar, unsafe or mismatched weights.

    The message is complete on its own; the compiler wraps it with the source span of the
    `nn(...)` call that named the model.
    """

    phase = "model"

    def __str__(self) -> str:
        return self.message  # the compiler adds the location of the `nn(...)` call

    def render(self, source: str | None = None) -> str:
        """Shown on its own (the CLI, e.g. `swarmdsl train` saving a model), the message
        still starts with its severity like every other error: `error: ...`."""
        return SwarmError.__str__(self) + super().render(source)[len(str(self)):]


class NonFiniteOutput(ModelError):
    """A forward pass that produced NaN or infinity. Carries the first bad row of the
    batch, so a caller that built the batch (the `nn(...)` call site) can say which agent
    it came from rather than where it sat in the batch."""

    def __init__(self, message: str, row: int, inputs: np.ndarray):
        super().__init__(message)
        self.row = row
        self.inputs = inputs
        self.args = (message, row, inputs)   # so it unpickles (a sweep's worker raising)


# Shapes a sidecar may claim, checked before torch allocates a single layer.
MAX_LAYER_WIDTH = 4096
MAX_HIDDEN_LAYERS = 16
MAX_PARAMETERS = 10_000_000


@dataclass(frozen=True)
class Normalisation:
    """Per-column affine map `(v - shift) / scale`, optionally clipped afterwards.

    Clipping exists for sentinel inputs such as the 2D matrix "ghost" at (6000, 6000):
    clipped to a few units it stays unmistakable to the network without swamping the
    real coordinates, which are then learnt at full precision.
    """

    shift: tuple[float, ...]
    scale: tuple[float, ...]
    clip: tuple[float, float] | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"shift": list(self.shift), "scale": list(self.scale)}
        if self.clip is not None:
            out["clip"] = list(self.clip)
        return out


@dataclass(frozen=True)
class ModelInfo:
    """What the sidecar says about a model; enough to check a call without torch."""

    path: Path
    n_in: int
    n_out: int
    arch: str
    hidden: tuple[int, ...]
    activation: str
    input_norm: Normalisation
    output_norm: Normalisation
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    val_percentage_error: float | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    @property
    def layer_widths(self) -> tuple[int, ...]:
        """Every layer's width, input to output: (2, 4, 1) for the 1D spring model."""
        return (self.n_in, *self.hidden, self.n_out)


def sidecar_path(path: str | Path) -> Path:
    """`models/x.pt` -> `models/x.json`: the sidecar always sits beside the weights."""
    return Path(path).with_suffix(".json")


def resolve_model_path(spec: str, program_dir: Path) -> Path:
    """Resolve the string in `nn("models/x.pt", ...)` against the program's folder.

    A program may use only models at or under its own folder, so that running someone
    else's `.swarm` file cannot make it read arbitrary files: absolute paths, `..`
    components and symlinks that lead outside the folder are refused.

    Args:
        spec: The path as written in the program, relative, with `/` separators.
        program_dir: The folder holding the `.swarm` file.

    Returns:
        The resolved, existing file path.

    Raises:
        ModelError: naming the reason and the fix.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise ModelError("model path is empty; write it relative to the program's folder")
    if "\0" in spec:
        raise ModelError("model path contains a NUL character")
    if not isinstance(program_dir, str | os.PathLike):
        raise ModelError("the program's folder must be a path")
    if (
        PurePosixPath(spec).is_absolute()
        or PureWindowsPath(spec).is_absolute()
        or PureWindowsPath(spec).drive
        or spec.startswith(("/", "\\", "~"))
    ):
        raise ModelError(
            f"model path '{spec}' is absolute; write it relative to the program's folder, "
            "e.g. \"models/x.pt\""
        )
    parts = PureWindowsPath(spec).parts  # splits on both '/' and '\'
    if ".." in parts:
        raise ModelError(
            f"model path '{spec}' contains '..'; models must live at or under the "
            "program's folder"
        )
    base = Path(program_dir).resolve()
    candidate = base.joinpath(*parts)
    resolved = candidate.resolve()
    if not resolved.is_relative_to(base):
        raise ModelError(
            f"model path '{spec}' resolves outside the program's folder (through a "
            f"symlink, to {resolved}); copy the model under the program's folder"
        )
    if not resolved.exists():
        raise ModelError(
            f"model file '{spec}' not found (looked in {base}); "
            "train one with `swarmdsl train`"
        )
    if not resolved.is_file():
        raise ModelError(f"model path '{spec}' is not a file (a regular file is needed)")
    return resolved


def read_model_info(path: str | Path) -> ModelInfo:
    """Read and validate the JSON sidecar beside `path`, without importing torch.

    Args:
        path: The `.pt` weights file (or its `.json` sidecar).

    Raises:
        ModelError: the sidecar is missing, not JSON, or inconsistent.
    """
    path = _model_path(path)
    weights = path.with_suffix(".pt") if path.suffix == ".json" else path
    side = sidecar_path(weights)
    if not side.exists() and not side.is_symlink():
        raise ModelError(
            f"model '{weights.name}' has no sidecar '{side.name}' beside it; the sidecar "
            "holds the architecture and normalisation (`swarmdsl train` writes both)"
        )
    if side.resolve().parent != weights.resolve().parent:
        raise ModelError(f"model sidecar '{side.name}' is a symlink to another folder; "
                         "the sidecar must be a regular file beside the weights")
    data = read_json(side.resolve(), "model sidecar", MAX_SIDECAR_BYTES, ModelError, side.name)
    return parse_sidecar(data, weights, side.name)


def parse_sidecar(data: Any, weights: Path, name: str | None = None) -> ModelInfo:
    """Validate an already-parsed sidecar object (training uses this before saving)."""
    name = name or sidecar_path(weights).name

    def bad(msg: str) -> ModelError:
        return ModelError(f"model sidecar '{name}': {msg}")

    if not isinstance(data, dict):
        raise bad("expected a JSON object")
    if data.get("format") != SIDECAR_FORMAT:
        raise bad(f"'format' must be \"{SIDECAR_FORMAT}\"")
    arch = data.get("arch")
    if arch != "mlp":
        raise bad("unsupported 'arch'; only \"mlp\" is supported")
    n_in, n_out = data.get("n_in"), data.get("n_out")
    for key, val in (("n_in", n_in), ("n_out", n_out)):
        if not _is_pos_int(val):
            raise bad(f"'{key}' must be a positive integer, got {_kind(val)}")
    hidden = data.get("hidden", [])
    if not isinstance(hidden, list) or not all(_is_pos_int(h) for h in hidden):
        raise bad("'hidden' must be a list of positive integers")
    widths = [n_in, *hidden, n_out]
    if len(hidden) > MAX_HIDDEN_LAYERS or max(widths) > MAX_LAYER_WIDTH:
        raise bad(f"at most {MAX_HIDDEN_LAYERS} hidden layers of at most "
                  f"{MAX_LAYER_WIDTH} units are supported")
    if sum((a + 1) * b for a, b in zip(widths, widths[1:], strict=False)) > MAX_PARAMETERS:
        raise bad(f"the layers claim more than {MAX_PARAMETERS:,} parameters")
    activation = data.get("activation", "relu")
    if activation not in ACTIVATIONS:
        raise bad(f"unknown 'activation'; expected one of {', '.join(ACTIVATIONS)}")
    norm = data.get("normalisation", {})
    if not isinstance(norm, dict):
        raise bad("'normalisation' must be an object with 'input' and 'output'")
    in_norm = _parse_norm(norm.get("input"), n_in, "input", bad)
    out_norm = _parse_norm(norm.get("output"), n_out, "output", bad)
    inputs = _names(data.get("inputs", []), n_in, "inputs", bad)
    outputs = _names(data.get("outputs", []), n_out, "outputs", bad)
    val = data.get("val_percentage_error")
    return ModelInfo(
        path=weights,
        n_in=n_in,
        n_out=n_out,
        arch=arch,
        hidden=tuple(hidden),
        activation=activation,
        input_norm=in_norm,
        output_norm=out_norm,
        inputs=inputs,
        outputs=outputs,
        val_percentage_error=float(val) if isinstance(val, int | float) else None,
        extra=data,
    )


def _model_path(path: Any) -> Path:
    if not isinstance(path, str | os.PathLike) or "\0" in os.fspath(path):
        raise ModelError("a model path must be a path without NUL characters")
    return Path(path)


def _kind(v: Any) -> str:
    """What a refused value is, without quoting it (it may be someone's file content)."""
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, int | float):
        return "a number out of range" if isinstance(v, int) else "a fraction"
    return {str: "a string", list: "a list", dict: "an object"}.get(type(v), "null")


def _is_pos_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v > 0


def _parse_norm(spec: Any, width: int, which: str, bad) -> Normalisation:
    if spec is None:
        return Normalisation((0.0,) * width, (1.0,) * width)
    if not isinstance(spec, dict):
        raise bad(f"'normalisation.{which}' must be an object with 'shift' and 'scale'")
    shift = spec.get("shift", [0.0] * width)
    scale = spec.get("scale", [1.0] * width)
    for key, vals in (("shift", shift), ("scale", scale)):
        if (
            not isinstance(vals, list)
            or len(vals) != width
            or not all(isinstance(v, int | float) and math.isfinite(v) for v in vals)
        ):
            raise bad(f"'normalisation.{which}.{key}' must be {width} finite numbers")
    if any(s == 0 for s in scale):
        raise bad(f"'normalisation.{which}.scale' must not contain 0")
    clip = spec.get("clip")
    if clip is not None:
        if (
            not isinstance(clip, list)
            or len(clip) != 2
            or not all(isinstance(v, int | float) for v in clip)
            or not clip[0] < clip[1]
        ):
            raise bad(f"'normalisation.{which}.clip' must be [low, high] with low < high")
        clip = (float(clip[0]), float(clip[1]))
    return Normalisation(
        tuple(float(v) for v in shift), tuple(float(v) for v in scale), clip
    )


def _names(vals: Any, width: int, key: str, bad) -> tuple[str, ...]:
    if vals in (None, []):
        return ()
    if not isinstance(vals, list) or len(vals) != width or not all(
        isinstance(v, str) for v in vals
    ):
        raise bad(f"'{key}' must list {width} names")
    return tuple(vals)


def _import_torch():
    try:
        import torch
    except ImportError:
        raise ModelError(
            "nn() needs torch, which is not installed: pip install 'swarmdsl[nn]'"
        ) from None
    return torch


def build_module(n_in: int, hidden: tuple[int, ...], n_out: int, activation: str = "relu"):
    """The torch module for an `mlp` sidecar: Linear/activation pairs, Linear last.

    Training builds its networks here too, so a saved `state_dict` always has the keys a
    load expects: `0.weight`, `0.bias`, `2.weight`, ... (torch `Sequential` indices).
    """
    torch = _import_torch()
    act = {"relu": torch.nn.ReLU, "tanh": torch.nn.Tanh, "sigmoid": torch.nn.Sigmoid}
    layers: list[Any] = []
    widths = (n_in, *hidden, n_out)
    for i in range(len(widths) - 1):
        layers.append(torch.nn.Linear(widths[i], widths[i + 1]))
        if i < len(widths) - 2:
            layers.append(act[activation]())
    return torch.nn.Sequential(*layers)


class LoadedModel:
    """A model ready for batched inference on float64 numpy rows.

    Normalisation from the sidecar is applied inside `forward`, so callers pass and get
    raw coordinates. The pass is numpy's (`_dense`): torch only loads the weights.
    """

    def __init__(self, info: ModelInfo, module: Any):
        self.info = info
        self.n_in = info.n_in
        self.n_out = info.n_out
        self._module = module
        self._in_shift = np.asarray(info.input_norm.shift, dtype=np.float64)
        self._in_scale = np.asarray(info.input_norm.scale, dtype=np.float64)
        self._out_shift = np.asarray(info.output_norm.shift, dtype=np.float64)
        self._out_scale = np.asarray(info.output_norm.scale, dtype=np.float64)
        self._clip = info.input_norm.clip
        self._layers = _dense_layers(module)
        self._activation = _ACTIVATION[info.activation]

    @property
    def path(self) -> Path:
        return self.info.path

    def __repr__(self) -> str:
        widths = "-".join(str(w) for w in self.info.layer_widths)
        return f"LoadedModel({self.info.path.name}, {widths} {self.info.activation})"

    def forward(self, x: np.ndarray) -> np.ndarray:
        """Run every row through the network in one pass.

        Args:
            x: `(M, n_in)` float64 inputs, raw (un-normalised); M may be 0.

        Returns:
            `(M, n_out)` float64 outputs, de-normalised.

        Raises:
            ModelError: wrong input shape or output shape.
            NonFiniteOutput: an output that is not finite (a `ModelError` naming the
                first bad row).
        """
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.n_in:
            raise ModelError(
                f"model '{self.info.path.name}' takes (M, {self.n_in}) inputs, "
                f"got shape {x.shape}"
            )
        m = x.shape[0]
        if m == 0:
            return np.empty((0, self.n_out), dtype=np.float64)
        z = (x - self._in_shift) / self._in_scale
        if self._clip is not None:
            np.clip(z, self._clip[0], self._clip[1], out=z)
        with np.errstate(all="ignore"):   # a non-finite output is named below
            out = self._mlp(z)
        if out.shape != (m, self.n_out):
            raise ModelError(
                f"model '{self.info.path.name}' returned shape {out.shape}, "
                f"expected ({m}, {self.n_out})"
            )
        y = out * self._out_scale + self._out_shift
        if not np.isfinite(y).all():
            bad = int(np.flatnonzero(~np.isfinite(y).all(axis=1))[0])
            raise NonFiniteOutput(
                f"model '{self.info.path.name}' produced a non-finite output "
                f"(first at row {bad}, input {x[bad].tolist()})", bad, x[bad].copy()
            )
        return y

    __call__ = forward

    def _mlp(self, z: np.ndarray) -> np.ndarray:
        """The network on normalised rows `z`, each row on its own (`_dense`), in
        blocks of BLOCK_ROWS rows (a block's arrays stay in the cache)."""
        if z.shape[0] > BLOCK_ROWS:
            return np.concatenate([self._mlp(z[i:i + BLOCK_ROWS])
                                   for i in range(0, z.shape[0], BLOCK_ROWS)])
        last = len(self._layers) - 1
        h = np.ascontiguousarray(z.T)   # (n_in, M): one input's values contiguous
        for i, (w, b) in enumerate(self._layers):
            h = _dense(h, w, b)
            if i < last:
                h = self._activation(h)
        return h.T


# Rows a forward pass takes at a time: 100,000 rows through the 8-32-32-2 matrix model
# took 70 ms in blocks of 4,096-8,192 rows, 370 ms in one block (torch: 140 ms).
BLOCK_ROWS = 4096


def _dense_layers(module) -> list[tuple[np.ndarray, np.ndarray]]:
    """The `Linear` layers of a `build_module` network as float64 arrays: (weights
    transposed, `(n_in, n_out)` C-ordered so that `w[k]` is input k's row; bias)."""
    layers = []
    for layer in module:
        weight = getattr(layer, "weight", None)
        if weight is not None:
            w = weight.detach().cpu().double().numpy().T
            b = layer.bias.detach().cpu().double().numpy()
            layers.append((np.ascontiguousarray(w), b.copy()))
    return layers


def _dense(h: np.ndarray, w: np.ndarray, b: np.ndarray) -> np.ndarray:
    """`(w.T @ h + b)` as sequential sums over the inputs, in input order: `(n_out, M)`
    from `(n_in, M)`. Each element is the same chain of IEEE multiplies and adds for any
    M (no BLAS kernel choosing by the row count), one multiply and one add over all rows
    per input."""
    if w.size * h.shape[1] <= SMALL_PRODUCTS:   # every product in one multiply
        terms = w[:, :, None] * h[:, None, :]
        acc = terms[0]
        for k in range(1, w.shape[0]):
            acc += terms[k]
    else:
        acc = w[0][:, None] * h[0]
        term = np.empty_like(acc)
        for k in range(1, w.shape[0]):
            np.multiply(w[k][:, None], h[k], out=term)
            acc += term
    acc += b[:, None]
    return acc


# Up to this many products (a 32-32 layer over 64 rows) a layer computes them all at once
# and then only adds: half the numpy calls of a small pass, the same numbers.
SMALL_PRODUCTS = 65_536


def _sigmoid(h: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + portable.exp_array(-h))


_ACTIVATION = {"relu": lambda h: np.maximum(h, 0.0), "tanh": portable_runtime.tanh_array,
               "sigmoid": _sigmoid}


def load_model(path: str | Path) -> LoadedModel:
    """Load `path` (a resolved `.pt`) and its sidecar into a `LoadedModel`.

    Only a `state_dict` of tensors is accepted. `torch.load(weights_only=True)` refuses any
    pickle that names a callable, so a crafted file fails here before anything runs.

    Raises:
        ModelError: missing torch, unsafe or unreadable file, or weights that do not
            match the sidecar's architecture.
    """
    path = _model_path(path)
    info = read_model_info(path)
    try:
        check_regular(path, "model file", MAX_WEIGHTS_BYTES, path.name)   # resolved
    except ContainmentError as exc:
        raise ModelError(exc.message) from None
    torch = _import_torch()
    import pickle
    import warnings

    try:
        with warnings.catch_warnings():
            # torch warns about pickle protocols it did not write, then refuses the file
            # anyway if it is unsafe; the refusal below is the message users need.
            warnings.simplefilter("ignore")
            state = torch.load(path, weights_only=True, map_location="cpu")
    except FileNotFoundError:
        raise ModelError(f"model file '{path.name}' not found") from None
    except (pickle.UnpicklingError, RuntimeError, EOFError, ValueError, AttributeError,
            TypeError, OSError) as exc:
        # torch's own message suggests loading with weights_only=False, which would run
        # whatever code the file names: never repeat it.
        raise ModelError(
            f"refusing to load model '{path.name}': it is not a plain tensor state_dict "
            f"({type(exc).__name__}). Save weights with "
            "torch.save(model.state_dict(), path), never a pickled model or object"
        ) from None
    if not isinstance(state, dict) or not all(
        isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state.items()
    ):
        raise ModelError(
            f"model '{path.name}' does not hold a state_dict (a mapping of names to "
            f"tensors); got {type(state).__name__}"
        )
    module = build_module(info.n_in, info.hidden, info.n_out, info.activation)
    _check_state(module.state_dict(), state, path.name, info)
    module.load_state_dict(state, strict=True)
    module = module.double().eval()
    # Checked after the copy into the module's float32 layers, where a float64 weight
    # beyond float32's range turns infinite; named, as docs/nn.md says: which layer.
    for key, p in module.named_parameters():
        p.requires_grad_(False)
        if not torch.isfinite(p).all():
            raise ModelError(f"model '{path.name}' has non-finite weights in '{key}'")
    return LoadedModel(info, module)


def _check_state(expected: dict, got: dict, name: str, info: ModelInfo) -> None:
    """Explain a sidecar/weights mismatch in terms of layers, not torch's key dump."""
    widths = "-".join(str(w) for w in info.layer_widths)
    missing = sorted(set(expected) - set(got))
    unexpected = sorted(set(got) - set(expected))
    if missing or unexpected:
        raise ModelError(
            f"model '{name}' does not match its sidecar ({widths} mlp): "
            f"missing {missing or 'nothing'}, unexpected {unexpected or 'nothing'}"
        )
    for key, tensor in expected.items():
        if tuple(got[key].shape) != tuple(tensor.shape):
            raise ModelError(
                f"model '{name}' does not match its sidecar ({widths} mlp): '{key}' has "
                f"shape {tuple(got[key].shape)}, the sidecar implies {tuple(tensor.shape)}"
            )
