"""Fitting a task's network, scoring it on held-out data, and saving weights + sidecar.

Training is reproducible for a seed: data come from `numpy.random.default_rng(seed)`,
weights and batch order from `torch.manual_seed(seed)` inside `torch.random.fork_rng`
(the caller's global torch RNG is left untouched), deterministic algorithms and a fixed
thread count (1 by default). The caller's torch settings are restored afterwards.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swarmdsl.runtime.nn import (
    SIDECAR_FORMAT,
    LoadedModel,
    ModelInfo,
    build_module,
    parse_sidecar,
    sidecar_path,
)
from swarmdsl.train import rules
from swarmdsl.train.data import TASKS, Task

PERCENTAGE_ERROR_DEFINITION = (
    "100 * mean over outputs k of [ mean_i |pred_ik - target_ik| / "
    "(max_i target_ik - min_i target_ik) ], on held-out rows"
)

INPUT_CLIP = 5.0
"""Normalised inputs are clipped to +-this when the task has ghost sentinels."""

ProgressFn = Callable[[int, int, float], None]
"""`progress(epoch, epochs, train_loss)` after each epoch (epoch counts from 1)."""


def percentage_error(pred: np.ndarray, target: np.ndarray) -> float:
    """Mean absolute error relative to the spread of the targets, in percent.

    The thesis quotes "percentage error" without a definition. Dividing each output's
    mean absolute error by the range its targets span (max - min) makes the figure
    independent of where the coordinate origin is (a relative error |e|/|y| is not:
    it explodes near 0) and reads as "how far off, as a share of the working area".
    Outputs are averaged with equal weight.
    """
    pred = np.asarray(pred, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if pred.shape != target.shape or target.ndim != 2 or target.shape[0] < 2:
        raise ValueError(f"need matching (M>=2, k) arrays, got {pred.shape}, {target.shape}")
    spread = target.max(axis=0) - target.min(axis=0)
    spread = np.where(spread > 0, spread, 1.0)
    return float(100.0 * np.mean(np.abs(pred - target).mean(axis=0) / spread))


@dataclass
class TrainConfig:
    """Everything that determines a trained network (with the seed, its exact weights)."""

    task: str
    name: str
    hidden: list[int]
    activation: str
    lr: float
    epochs: int
    batch_size: int
    samples: int
    seed: int = 0
    val_fraction: float = 0.2
    threads: int = 1
    lr_schedule: str = "constant"
    input_clip: float = INPUT_CLIP
    sampling: dict[str, Any] = field(default_factory=dict)
    rule_params: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def for_task(cls, task: str, **overrides: Any) -> TrainConfig:
        """The task's defaults (the thesis' hyperparameters), with `overrides` on top."""
        from dataclasses import fields

        from swarmdsl.errors import SwarmOptionError, did_you_mean
        from swarmdsl.train.config_check import check_config

        if not isinstance(task, str) or task not in TASKS:
            raise SwarmOptionError(f"unknown training task; expected one of "
                                   f"{', '.join(TASKS)}", hint=did_you_mean(str(task), TASKS))
        known = {f.name for f in fields(cls)} - {"task"}
        for key in overrides:
            if key not in known:
                raise SwarmOptionError(f"unknown training setting '{key}'",
                                       hint=did_you_mean(key, known))
        t = TASKS[task]
        values: dict[str, Any] = {"task": task, "name": task, **t.defaults}
        values["sampling"] = dict(t.sampling)
        values["rule_params"] = dict(t.rule_params)
        for key, val in overrides.items():
            if val is None:
                continue
            if key in ("sampling", "rule_params"):
                if not isinstance(val, dict):
                    raise SwarmOptionError(f"'{key}' must be a mapping of settings")
                values[key] = {**values[key], **val}
            else:
                values[key] = val
        config = cls(**values)
        check_config(config)
        return config


@dataclass
class TrainResult:
    """A trained network: its weights, sidecar and held-out score."""

    config: TrainConfig
    state_dict: dict[str, Any]
    sidecar: dict[str, Any]
    val_percentage_error: float
    seconds: float
    model: LoadedModel

    def save(self, out: str | Path) -> Path:
        """Write `out` (state_dict only) and the sidecar beside it; return the `.pt` path.

        Both are written under temporary names and renamed into place only once both
        are whole: a failure or a stop while saving leaves the previous model as it was,
        never half a weights file or new weights beside the old sidecar.
        """
        import torch

        out = Path(out)
        if out.suffix != ".pt":
            out = out.with_suffix(".pt")
        from swarmdsl.runtime.outputs import replace_together

        out.parent.mkdir(parents=True, exist_ok=True)
        text = json.dumps(self.sidecar, indent=2) + "\n"
        replace_together([(out, lambda tmp: torch.save(self.state_dict, tmp)),
                          (sidecar_path(out), lambda tmp: tmp.write_text(text, "utf-8"))])
        return out


def make_data(
    task: Task, config: TrainConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sample `config.samples` rows for the seed and split off the held-out tail."""
    from swarmdsl.train.config_check import split_sizes

    rng = np.random.default_rng(config.seed)
    x, y = task.make(config.samples, rng, config.sampling, config.rule_params)
    _, n_val = split_sizes(config.samples, config.val_fraction)
    return x[:-n_val], y[:-n_val], x[-n_val:], y[-n_val:]


def _normalisation(x: np.ndarray, y: np.ndarray, task: Task, clip: float) -> dict[str, Any]:
    """Standardise each column; ghost values are left out of the statistics and clipped."""
    shift, scale = [], []
    for k in range(x.shape[1]):
        col = x[:, k]
        if task.ghost_threshold is not None:
            col = col[col < task.ghost_threshold]
        if col.size == 0:
            col = np.zeros(1)
        shift.append(float(col.mean()))
        scale.append(float(col.std()) or 1.0)
    inp: dict[str, Any] = {"shift": shift, "scale": scale}
    if task.ghost_threshold is not None:
        inp["clip"] = [-clip, clip]
    out = {
        "shift": [float(v) for v in y.mean(axis=0)],
        "scale": [float(v) or 1.0 for v in y.std(axis=0)],
    }
    return {"input": inp, "output": out}


def train(config: TrainConfig, progress: ProgressFn | None = None) -> TrainResult:
    """Train `config.task`'s network and score it on the held-out split.

    Raises:
        SwarmOptionError: an unknown task or a setting out of range (a config built
            directly, not through `for_task`, is checked here).
    """
    import torch

    from swarmdsl.errors import SwarmOptionError
    from swarmdsl.train.config_check import check_config

    if not isinstance(config, TrainConfig) or config.task not in TASKS:
        raise SwarmOptionError("train needs a TrainConfig of a known task: "
                               "TrainConfig.for_task(task, ...)")
    check_config(config)
    task = TASKS[config.task]
    start = time.perf_counter()
    x_tr, y_tr, x_val, y_val = make_data(task, config)
    norm = _normalisation(x_tr, y_tr, task, config.input_clip)
    sidecar = _sidecar(task, config, norm)
    info = parse_sidecar(sidecar, Path(f"{config.name}.pt"))

    prev_threads = torch.get_num_threads()
    prev_det = torch.are_deterministic_algorithms_enabled()
    det_mod = torch.utils.deterministic
    prev_fill = det_mod.fill_uninitialized_memory
    try:
        torch.set_num_threads(config.threads)
        torch.use_deterministic_algorithms(True)
        # Filling every new tensor with NaN (the deterministic default) halves speed;
        # our ops never read uninitialised memory, so it buys nothing here.
        det_mod.fill_uninitialized_memory = False
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(config.seed)
            module = _fit(torch, task, info, config, x_tr, y_tr, progress)
    finally:
        torch.set_num_threads(prev_threads)
        torch.use_deterministic_algorithms(prev_det)
        det_mod.fill_uninitialized_memory = prev_fill

    state = {k: v.detach().clone().contiguous() for k, v in module.state_dict().items()}
    model = LoadedModel(info, module.double().eval())
    val_pe = percentage_error(model.forward(x_val), y_val)
    seconds = time.perf_counter() - start
    sidecar["val_percentage_error"] = round(val_pe, 6)
    sidecar["training"]["seconds"] = round(seconds, 2)
    return TrainResult(config, state, sidecar, val_pe, seconds, model)


def _fit(torch, task: Task, info: ModelInfo, config: TrainConfig,
         x_tr: np.ndarray, y_tr: np.ndarray, progress: ProgressFn | None):
    inorm, onorm = info.input_norm, info.output_norm
    z = (x_tr - np.asarray(inorm.shift)) / np.asarray(inorm.scale)
    if inorm.clip is not None:
        np.clip(z, *inorm.clip, out=z)
    t = (y_tr - np.asarray(onorm.shift)) / np.asarray(onorm.scale)
    xt = torch.from_numpy(z.astype(np.float32))
    yt = torch.from_numpy(t.astype(np.float32))
    module = build_module(info.n_in, info.hidden, info.n_out, info.activation)
    opt = torch.optim.Adam(module.parameters(), lr=config.lr, fused=True)
    loss_fn = torch.nn.MSELoss()
    n, bs = xt.shape[0], config.batch_size
    sched = None
    if config.lr_schedule == "cosine":
        steps = config.epochs * ((n + bs - 1) // bs)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=steps)
    for epoch in range(1, config.epochs + 1):
        perm = torch.randperm(n)
        xs, ys = xt[perm], yt[perm]  # one gather per epoch; batches are then views
        total = 0.0
        for i in range(0, n, bs):
            xb, yb = xs[i : i + bs], ys[i : i + bs]
            opt.zero_grad(set_to_none=True)
            loss = loss_fn(module(xb), yb)
            loss.backward()
            opt.step()
            if sched is not None:
                sched.step()
            total += loss.detach() * xb.shape[0]
        if progress is not None:
            progress(epoch, config.epochs, float(total) / n)
    return module


def _sidecar(task: Task, config: TrainConfig, norm: dict[str, Any]) -> dict[str, Any]:
    import torch

    cfg = asdict(config)
    training = {
        "task": task.name,
        "optimizer": "adam",
        "loss": "mse",
        **{
            k: cfg[k]
            for k in ("lr", "lr_schedule", "epochs", "batch_size", "samples", "val_fraction",
                      "seed", "threads", "input_clip", "sampling", "rule_params")
        },
        "torch": torch.__version__.split("+")[0],
    }
    out = {
        "format": SIDECAR_FORMAT,
        "format_version": 1,
        "name": config.name,
        "description": task.description,
        "arch": "mlp",
        "n_in": task.n_in,
        "n_out": task.n_out,
        "hidden": list(config.hidden),
        "activation": config.activation,
        "inputs": list(task.inputs),
        "outputs": list(task.outputs),
        "normalisation": norm,
        "training": training,
        "percentage_error_definition": PERCENTAGE_ERROR_DEFINITION,
        "val_percentage_error": None,
    }
    if task.ghost_threshold is not None:
        out["ghost"] = {"value": rules.GHOST, "threshold": task.ghost_threshold}
    return out
