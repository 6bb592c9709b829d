"""The names of a sweep's run folders (`--runs`): its params and seed, readable.

`runs/eta=0.5_seed=3/` is found by eye and by glob (`runs/eta=0.5_seed=*`); the run's
hash key (`sweep/worker.run_key`) stays its identity in `runs.jsonl`, so a sweep
started again finds its finished runs by key, as before. A name keeps the value as
typed (`0.50` is not `0.5`: two runs), escapes anything but letters, digits and
`. + -` as `%XX` (UTF-8 bytes), so it is safe on every filesystem and no two values
share a name; `_` joins the parts, `=` ends each name. Where a name would be taken by
another run of the same folder (another program or `--steps` run into the same DIR,
or a name differing only by case, one folder on a case-insensitive filesystem) the
run's key is appended. Sweeps written before this kept `runs/KEY/`: those folders stay
where they are, and their runs are found by key like any other.
"""

from __future__ import annotations

import hashlib

_SAFE = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.+-")
MAX_NAME = 180      # bytes; filesystems allow 255, and the key may be appended


def _escape(text: str) -> str:
    return "".join(c if c in _SAFE else "".join(f"%{b:02X}" for b in c.encode())
                   for c in str(text))


def run_folder(params, seed: int) -> str:
    """`eta=0.5_n=100_seed=3`: the params in `--set` order, then the seed. A name
    longer than MAX_NAME keeps its start and the seed, with a hash of the whole."""
    parts = [f"{_escape(name)}={_escape(value)}" for name, value in params]
    tail = f"seed={int(seed)}"
    name = "_".join([*parts, tail])
    if len(name) > MAX_NAME:
        digest = hashlib.sha256(name.encode()).hexdigest()[:12]
        name = f"{name[:MAX_NAME - len(tail) - 15]}~{digest}_{tail}"
    return name


def is_folder_name(name: str) -> bool:
    """Whether `name` (read back from runs.jsonl) is one this module makes: a plain
    name of safe characters, never a path (`..`, `/`) out of DIR/runs/."""
    return bool(name) and "=" in name and set(name) <= _SAFE | set("=_%~")


def assign(runs, earlier) -> dict[str, str]:
    """{key: folder name} for `runs` ((key, params, seed) each), unique among them and
    against `earlier` ({folder name: key} of the log's runs that have one), compared
    ignoring case. A run already in the log keeps its folder."""
    earlier = {name: key for name, key in earlier.items() if is_folder_name(name)}
    taken = {name.lower(): key for name, key in earlier.items()}
    mine = {key: name for name, key in earlier.items()}
    names: dict[str, str] = {}
    for key, params, seed in runs:
        if key in mine:
            names[key] = mine[key]
            continue
        name = run_folder(params, seed)
        if taken.get(name.lower(), key) != key:
            name = f"{name}_{key[:12]}"
        taken[name.lower()] = key
        names[key] = name
    return names


__all__ = ["assign", "run_folder"]
