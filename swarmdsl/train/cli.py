"""The `swarmdsl train` subcommand: options, training-spec files, progress output.

`register(subparsers)` adds the subcommand to the main CLI's argparse tree; the main CLI
calls `args.func(args)` and turns any `SwarmError` into exit code 2.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path
from typing import Any

from swarmdsl import stopping
from swarmdsl.command_args import path_arg
from swarmdsl.errors import SwarmOptionError, did_you_mean
from swarmdsl.files import MAX_SPEC_BYTES, contained_path, read_json
from swarmdsl.train.data import TASKS

SPEC_KEYS = {
    "task": str,
    "name": str,
    "out": str,
    "hidden": list,
    "activation": str,
    "lr": (int, float),
    "lr_schedule": str,
    "epochs": int,
    "batch_size": int,
    "samples": int,
    "val_fraction": (int, float),
    "seed": int,
    "input_clip": (int, float),
    "sampling": dict,
    "rule_params": dict,
}
"""Keys a training-spec JSON file may hold, with their JSON types (see docs/nn.md)."""


def register(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add `train` to the main CLI's subcommands; returns its parser."""
    p = subparsers.add_parser(
        "train",
        help="train an nn() model from a built-in rule or a training-spec file",
        description=(
            "Train a small network from a hard-coded rule and save NAME.pt (weights) and "
            "NAME.json (architecture, normalisation, held-out error) side by side. "
            f"TARGET is a built-in task ({', '.join(TASKS)}) or a training-spec .json file."
        ),
    )
    p.add_argument("target", metavar="TARGET", help="spring1d | matrix2d | SPEC.json")
    p.add_argument("--out", metavar="PATH", type=path_arg("--out", "a file name, e.g. model.pt"),
                   help="weights file to write (default models/NAME.pt)")
    p.add_argument("--seed", type=int, help="seed for data, weights and batch order")
    p.add_argument("--epochs", type=int, help="passes over the training rows")
    p.add_argument("--samples", type=int, help="rows to generate (a fifth are held out)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a model already at the output path (default: refuse, "
                   "before training)")
    p.set_defaults(func=run_train)
    return p


def run_train(args: argparse.Namespace) -> int:
    """Train as `args` say, write the model and print a one-line summary; exit code."""
    spec, base = _load_target(args.target)
    spec_file = None if args.target in TASKS else Path(args.target)
    overrides = _overrides(args)
    config_kwargs = {**spec, **overrides}
    task = config_kwargs.pop("task")
    out = config_kwargs.pop("out", None)
    from swarmdsl.train.fit import TrainConfig, train

    # Every setting is checked before the output path is made from them (an empty
    # 'name' is a bad name, not a bad --out) and before torch is imported.
    config = TrainConfig.for_task(task, **config_kwargs)
    given = "--out" if args.out is not None else "the training spec's 'out'"
    if args.out is not None:
        out_path = Path(args.out)  # the user's own choice on the command line
    elif out is not None:
        out_path = contained_path(out, base, given)
    else:
        out_path = contained_path(f"models/{config.name}.pt", base, "the model name")
    if out_path.suffix != ".pt":    # (a model name always gives one)
        raise SwarmOptionError(f"{given} must name a .pt file, got '{out_path}'")
    from swarmdsl.runtime.outputs import check_file

    check_file(out_path, "--out", example="model.pt")
    check_file(out_path.with_suffix(".json"), "--out", example="model.pt")
    _refuse_existing(out_path, spec_file, args.overwrite)
    try:
        import torch  # noqa: F401
    except ImportError:
        raise SwarmOptionError("swarmdsl train needs torch: pip install 'swarmdsl[nn]'") from None
    label = f"training {config.name}"
    try:
        with _Progress(label) as progress:
            result = train(config, progress)
    except (ValueError, TypeError) as exc:
        raise SwarmOptionError(f"cannot train {config.name}: {exc}") from None
    with stopping.deferred():      # a stop while saving waits for whole files
        try:
            path = result.save(out_path)
        except OSError as exc:          # a full disk: the old model stays as it was
            reason = (exc.strerror or type(exc).__name__).lower()
            raise SwarmOptionError(f"{out_path}: cannot write the model ({reason})"
                                   ) from None
    print(
        f"wrote {path} and {path.with_suffix('.json').name}: held-out percentage error "
        f"{result.val_percentage_error:.4f} %, {result.seconds:.1f} s"
    )
    return 0


def _refuse_existing(out: Path, spec_file: Path | None, overwrite: bool) -> None:
    """Refuse, before training, to replace a model unless `--overwrite` says so: a
    trained model can take an hour to make again, and re-running a command should not
    cost it. The weights and the sidecar are a pair, so either one being there counts.
    A sidecar that would land on the training spec itself is refused even then."""
    sidecar = out.with_suffix(".json")
    if spec_file is not None and sidecar.resolve() == spec_file.resolve():
        raise SwarmOptionError(f"{out}: its sidecar {sidecar} would replace the training "
                               "spec itself; name the model differently ('out' in the "
                               "spec, or --out)")
    if overwrite:
        return
    for path in (out, sidecar):
        if path.exists() or path.is_symlink():
            what = "a model" if path == out else "the sidecar of a model"
            raise SwarmOptionError(f"{path}: {what} is already there; give --overwrite to "
                                   "replace it, or --out for another file")


def _load_target(target: str) -> tuple[dict[str, Any], Path]:
    """A task name gives `{"task": name}`; a .json path gives its validated contents."""
    if target in TASKS:
        return {"task": target}, Path(".")
    path = Path(target)
    if path.suffix != ".json":
        hint = did_you_mean(target, TASKS)
        raise SwarmOptionError(
            f"unknown training target '{target}': expected one of {', '.join(TASKS)} "
            "or a training-spec .json file",
            hint=hint,
        )
    data = read_json(path, "training spec", MAX_SPEC_BYTES, SwarmOptionError, target)
    return _validate_spec(data, path), path.parent


def _validate_spec(data: Any, path: Path) -> dict[str, Any]:
    where = f"training spec '{path}'"
    if not isinstance(data, dict):
        raise SwarmOptionError(f"{where}: expected a JSON object")
    for key, val in data.items():
        if key not in SPEC_KEYS:
            shown = f"'{key}'" if re.fullmatch(r"[A-Za-z_]{1,40}", key) else "(unreadable)"
            raise SwarmOptionError(
                f"{where}: unknown key {shown}", hint=did_you_mean(key, SPEC_KEYS)
            )
        want = SPEC_KEYS[key]
        if isinstance(val, bool) or not isinstance(val, want):
            raise SwarmOptionError(f"{where}: '{key}' must be {_json_type(want)}, got "
                                   f"{_json_type(type(val))}")
    task = data.get("task")
    if task not in TASKS:
        raise SwarmOptionError(
            f"{where}: 'task' must be one of {', '.join(TASKS)}",
            hint=did_you_mean(str(task), TASKS),
        )
    t = TASKS[task]
    for key, allowed in (("sampling", t.sampling), ("rule_params", t.rule_params)):
        for sub in data.get(key, {}):
            if sub not in allowed and not (key == "sampling" and sub == "pattern_weights"
                                           and task == "matrix2d"):
                raise SwarmOptionError(
                    f"{where}: unknown {key} key '{sub}' for task {task} "
                    f"(known: {', '.join(allowed) or 'none'})",
                    hint=did_you_mean(sub, allowed),
                )
    spec = dict(data)
    spec.setdefault("name", path.stem)
    return spec


def _json_type(kind) -> str:
    """A JSON type as the spec's author wrote it ("a whole number", "an object"), not
    Python's name for it ("a int", "got dict")."""
    if isinstance(kind, tuple):
        return "a number"
    return {bool: "true or false", int: "a whole number", float: "a fraction",
            str: "a string", list: "a list", dict: "an object"}.get(kind, "null")


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    """`--seed`, `--epochs` and `--samples`, each within the range a spec's key has,
    refused naming the option: checked with the spec's keys, a value past the top was
    blamed on the key (`'epochs' must be ...`), which the user never wrote."""
    from swarmdsl.train.config_check import NUMBER_RANGES

    out: dict[str, Any] = {}
    for opt in ("seed", "epochs", "samples"):
        val = getattr(args, opt, None)
        if val is None:
            continue
        low, high, _whole = NUMBER_RANGES[opt]
        if val < low:
            raise SwarmOptionError(f"--{opt} must be at least {low}, got {val}")
        if val > high:
            raise SwarmOptionError(f"--{opt} must be at most {high:,}, got {val:,}")
        out[opt] = val
    return out


class _Progress:
    """A rich bar on a terminal; otherwise a plain line to stderr about every 10 %.

    Rich shows nothing until the end when stderr is not a terminal (CI logs), so plain
    lines are the only useful output there.
    """

    def __init__(self, label: str):
        self.label = label
        self.tty = sys.stderr.isatty()
        self._bar = None
        self._task = None
        self._last = 0.0

    def __enter__(self) -> _Progress:
        if self.tty:
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

            self._bar = Progress(
                TextColumn("{task.description}"),
                BarColumn(),
                TextColumn("epoch {task.completed}/{task.total}"),
                TextColumn("loss {task.fields[loss]:.3g}"),
                TimeRemainingColumn(),
                console=Console(stderr=True),
                transient=True,
            )
            self._bar.__enter__()
        self._start = time.perf_counter()
        return self

    def __call__(self, epoch: int, epochs: int, loss: float) -> None:
        if self._bar is not None:
            if self._task is None:
                self._task = self._bar.add_task(self.label, total=epochs, loss=loss)
            self._bar.update(self._task, completed=epoch, loss=loss)
            return
        step = max(1, epochs // 10)
        if epoch % step == 0 or epoch == epochs:
            elapsed = time.perf_counter() - self._start
            print(
                f"{self.label}: epoch {epoch}/{epochs}, loss {loss:.3g}, {elapsed:.1f} s",
                file=sys.stderr,
                flush=True,
            )

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)
