"""Checkpoints: everything a run needs to continue bit for bit, saved between ticks.

What is saved is generic so features added later are covered without touching this
module: every `AgentStore` column wholesale (with its declared mask), the tick, the
random source's state, and each runtime extension's `state_dict(sim)` (arrays go into
the `.npz`, everything else into JSON; no pickle anywhere, so loading a checkpoint can
never run code). An extension without `state_dict` makes saving fail loudly rather than
write a checkpoint that resumes differently.

A checkpoint names the program (source text and resolved params) and the swarmdsl
version that wrote it; loading refuses any other.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import zipfile
from pathlib import Path

import numpy as np

from swarmdsl.errors import SwarmOptionError, SwarmRuntimeError
from swarmdsl.runtime.randomness import RNG_NAME
from swarmdsl.version import __version__

FORMAT = 1
FOLDER = "checkpoint"


def program_hash(program, params: dict | None = None) -> str:
    """The program's identity for resuming: its text and its resolved params (`params`:
    other values for them, to ask whether only the params differ)."""
    values = program.params if params is None else params
    text = json.dumps({k: repr(v) for k, v in sorted(values.items())})
    return hashlib.sha256((program.source + "\0" + text).encode()).hexdigest()


def _ext_name(i: int, ext) -> str:
    return f"{i}:{type(ext).__name__}"


def state(sim) -> tuple[dict[str, np.ndarray], dict]:
    """What a run needs to continue bit for bit, as a checkpoint keeps it: the arrays
    (`col/NAME` every agent column, `declared/NAME` its declared mask, `ext/I:TYPE/KEY`
    each extension's arrays) and the plain values (`tick`, `rng`: the random source's
    state, `extensions`: each extension's other values). The arrays are the
    simulation's own, not copies."""
    arrays: dict[str, np.ndarray] = {}
    for name, col in sim.agents.cols.items():
        arrays[f"col/{name}"] = col
    for name, mask in sim.agents.declared.items():
        arrays[f"declared/{name}"] = mask
    ext_json = {}
    for i, ext in enumerate(sim.extensions):
        state_dict = getattr(ext, "state_dict", None)
        if state_dict is None:
            raise SwarmRuntimeError(f"cannot checkpoint this run: the runtime extension "
                                    f"`{type(ext).__name__}` does not save its state")
        plain = {}
        for key, value in state_dict(sim).items():
            if isinstance(value, np.ndarray):
                arrays[f"ext/{_ext_name(i, ext)}/{key}"] = value
            else:
                plain[key] = value
        ext_json[_ext_name(i, ext)] = plain
    return arrays, {"tick": int(sim.tick), "rng": sim.rng.state(), "extensions": ext_json}


def save(sim, folder: Path, extra: dict | None = None,
         arrays_extra: dict | None = None) -> Path:
    """Write `folder` atomically (a new folder renamed over the old one)."""
    folder = Path(folder)
    arrays, values = state(sim)
    for key, value in (arrays_extra or {}).items():
        arrays[f"extra/{key}"] = np.asarray(value)
    meta = {
        "format": FORMAT, "version": __version__, "program": str(sim.program.filename),
        "program_hash": program_hash(sim.program), "seed": sim.seed, "tick": values["tick"],
        "rng": values["rng"], "generator": RNG_NAME, "extensions": values["extensions"],
        "n_agents": int(sim.agents.n),
        **(extra or {}),
    }
    tmp = folder.with_name(folder.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    with open(tmp / "state.npz", "wb") as fh:
        np.savez(fh, **arrays)
    (tmp / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    old = folder.with_name(folder.name + ".old")
    shutil.rmtree(old, ignore_errors=True)
    if folder.exists():
        folder.rename(old)
    tmp.rename(folder)
    shutil.rmtree(old, ignore_errors=True)
    return folder


def read_meta(folder: Path) -> dict:
    folder = Path(folder)
    try:
        meta = json.loads((folder / "meta.json").read_text())
    except FileNotFoundError:
        raise SwarmOptionError(f"--resume {folder.parent}: no checkpoint there (run with "
                               "--out DIR --checkpoint-every K to write one)") from None
    except (OSError, ValueError) as exc:
        raise SwarmOptionError(f"--resume {folder.parent}: the checkpoint is unreadable "
                               f"({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise SwarmOptionError(f"--resume {folder.parent}: not a checkpoint this swarmdsl "
                               "can read")
    return meta


def check_compatible(meta: dict, program, where) -> None:
    if meta.get("version") != __version__:
        raise SwarmOptionError(f"--resume {where}: the checkpoint was written by swarmdsl "
                               f"{meta.get('version')}, this is {__version__}; resuming "
                               "could not be bit-identical, so it is refused")
    # a checkpoint from before the generator did not record it: v1 (draws keyed by line)
    if meta.get("generator", "swarmdsl-counter-v1") != RNG_NAME:
        raise SwarmOptionError(f"--resume {where}: the checkpoint's random draws are "
                               f"{meta.get('generator', 'swarmdsl-counter-v1')}'s, this "
                               f"swarmdsl draws {RNG_NAME}'s; resuming could not be "
                               "bit-identical, so it is refused (run it again from the "
                               "start)")
    if meta.get("program_hash") != program_hash(program):
        raise SwarmOptionError(f"--resume {where}: the checkpoint is of another program "
                               f"({meta.get('program')}) or other --set values; resume "
                               "with the same file and params")


def load(sim, folder: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """Put the checkpoint's state into a freshly built Simulation of the same program."""
    try:
        return _load(sim, Path(folder))
    except (KeyError, TypeError) as exc:
        raise SwarmOptionError(f"--resume {Path(folder).parent}: the checkpoint is "
                               f"incomplete (missing {exc})") from None


def _load(sim, folder: Path) -> tuple[dict, dict[str, np.ndarray]]:
    meta = read_meta(folder)
    check_compatible(meta, sim.program, folder.parent)
    try:
        with open(folder / "state.npz", "rb") as fh, np.load(fh, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise SwarmOptionError(f"--resume {folder.parent}: the checkpoint's arrays are "
                               f"unreadable ({exc})") from None
    put(sim, arrays, meta, f"--resume {folder.parent}")
    extra = {k[6:]: v for k, v in arrays.items() if k.startswith("extra/")}
    return meta, extra


def put(sim, arrays: dict[str, np.ndarray], values: dict, where: str) -> None:
    """Give `sim`, a freshly built Simulation, the state `state` took (`arrays` and
    `values`, as read back from a checkpoint); `where` begins the refusal's message."""
    agents = sim.agents
    cols = {k[4:]: v for k, v in arrays.items() if k.startswith("col/")}
    if set(cols) != set(agents.cols):
        raise SwarmOptionError(f"{where}: the checkpoint's agent columns differ from this "
                               "program's")
    for name, col in cols.items():
        agents.cols[name] = col.astype(agents.cols[name].dtype, copy=True)
    for name in agents.declared:
        agents.declared[name] = arrays[f"declared/{name}"].astype(bool, copy=True)
    agents.check_lengths()
    sim.tick = int(values["tick"])
    sim.rng.set_state(values["rng"])
    sim.pairs = None
    for i, ext in enumerate(sim.extensions):
        name = _ext_name(i, ext)
        prefix = f"ext/{name}/"
        got = dict(values["extensions"].get(name, {}))
        got.update({k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)})
        getattr(ext, "load_state", lambda sim, d: None)(sim, got)


def carry(old, new):
    """`new`, a freshly built Simulation (another program's params, or another
    backend), given `old`'s state between ticks exactly as a checkpoint of `old` saved
    and loaded into it would be (its plain values through JSON, its arrays copied), so
    a run carried over in memory (the studio's param change, a switch of backend)
    continues as `run --resume` of that checkpoint would. Refuses state that does not
    fit `new` (other columns or column shapes, other extensions): SwarmOptionError."""
    arrays, values = state(old)
    names = [_ext_name(i, ext) for i, ext in enumerate(new.extensions)]
    if names != list(values["extensions"]):
        raise SwarmOptionError("the run's state does not fit: its extensions differ")
    for name, col in new.agents.cols.items():
        got = arrays.get(f"col/{name}")
        if got is not None and got.shape[1:] != col.shape[1:]:
            raise SwarmOptionError(f"the run's state does not fit: column {name} changed "
                                   "shape")
    try:
        values = json.loads(json.dumps(values))
    except (TypeError, ValueError) as exc:     # what a checkpoint could not save either
        raise SwarmOptionError(f"the run's state cannot be carried ({exc})") from None
    arrays = {k: np.array(v, copy=True) for k, v in arrays.items()}
    put(new, arrays, values, "the run's state")
    return new
