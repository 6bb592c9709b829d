"""One drawn run of a program, as `swarmdsl test` finds it and `swarmdsl run --example`
replays it: params, seed, ticks and the initial swarm (a `Layout`), saved as JSON.

The file holds everything the run depends on, so the replay is exact: the program's
hash (a changed program is flagged, not silently replayed), the param values (drawn and
fixed ones), the seed, the number of ticks, which properties were checked, every agent's
id, index, position and drawn initial values, and what failed (property, tick, agents).
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
from dataclasses import dataclass
from pathlib import Path

from swarmdsl.compiler.errors import SwarmOptionError
from swarmdsl.runtime.layout import Layout

FORMAT = "swarmdsl-example-1"


def param_text(v) -> str:
    """A param value as `--set` writes it."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and v.is_integer():
        return repr(v)
    return str(v)


@dataclass(frozen=True)
class Example:
    """One run: param values (every drawn or fixed one), seed, ticks and initial swarm."""

    params: tuple[tuple[str, object], ...]
    seed: int
    steps: int
    layout: Layout | None = None

    def overrides(self) -> dict[str, object]:
        return dict(self.params)

    def agent_count(self, program) -> int:
        """How many agents the run starts with."""
        if self.layout is None:
            return sum(k.count for k in program.kinds)
        covered = set(self.layout.kinds)
        return len(self.layout.agents) + sum(k.count for k in program.kinds
                                             if k.name not in covered)

    def to_json(self, program, properties: list[str] | None = None,
                failure: dict | None = None) -> dict:
        return {
            "format": FORMAT,
            "program": Path(program.filename).name,
            "sha256": hashlib.sha256(program.source.encode("utf-8")).hexdigest(),
            "params": {k: param_text(v) for k, v in self.params},
            "seed": self.seed,
            "steps": self.steps,
            "properties": properties,
            "layout": self.layout.to_json() if self.layout is not None else None,
            "failure": failure,
        }

    def save(self, path: Path, program, properties=None, failure=None,
             option: str | None = "--save-example") -> None:
        """Write the example as JSON, creating missing folders; an OSError becomes an
        option error naming `option` (or only the path, when None)."""
        data = self.to_json(program, properties, failure)
        try:
            from swarmdsl.runtime.outputs import replace_with

            text = json.dumps(data, indent=1) + "\n"
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            replace_with(Path(path), lambda tmp: tmp.write_text(text, encoding="utf-8"))
        except OSError as exc:
            where = f"{option} {path}" if option else str(path)
            raise SwarmOptionError(f"{where}: cannot write: {exc.strerror}") from None


def load_example(path: Path) -> tuple[Example, dict]:
    """(Example, the whole file as a dict) from a saved example; bad files are option
    errors."""
    where = f"--example {path}"
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise SwarmOptionError(f"{where}: cannot read: {exc.strerror}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise SwarmOptionError(f"{where}: not JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise SwarmOptionError(f"{where}: not a saved example (no \"format\": \"{FORMAT}\")")
    try:
        params = tuple((str(k), str(v)) for k, v in (data.get("params") or {}).items())
        seed, steps = int(data["seed"]), int(data["steps"])
        props = data.get("properties")
        if props is not None:
            data["properties"] = [str(p) for p in props]
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise SwarmOptionError(f"{where}: malformed ({exc!r})") from None
    layout = data.get("layout")
    layout = Layout.from_json(layout, where) if layout is not None else None
    return Example(params, seed, steps, layout), data


def example_command(filename: str, path: Path | str, properties=None) -> str:
    """The `swarmdsl run` command that replays a saved example with checks on."""
    parts = ["swarmdsl", "run", filename, "--headless", "--example", os.fspath(path)]
    for name in properties or ():
        parts += ["--property", name]
    return shlex.join(parts)


def cache_folder() -> Path:
    """Where examples go when no `--save-example` is given: the user's cache folder
    (`$XDG_CACHE_HOME/swarmdsl/examples`, else `~/.cache/swarmdsl/examples`)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "swarmdsl" / "examples"


def apply_example(args):
    """Fill `swarmdsl run`'s options from `--example FILE`; returns its Layout.

    The file gives the seed, params, ticks and properties; `--steps` and `--property`
    may override them, a different `--seed` or `--set` value may not (that would not be
    a replay). Turns checking on; warns when the program changed since the save.
    """
    import sys

    from swarmdsl.cli import parse_sets

    example, data = load_example(args.example)
    if args.resume is not None:
        raise SwarmOptionError("--example starts a run from its own tick 0; leave out "
                               "--resume")
    if args.seed is not None and args.seed != example.seed:
        raise SwarmOptionError(f"--seed {args.seed}: the example was found with seed "
                               f"{example.seed}; leave out --seed")
    sets = parse_sets(args.set)
    for name, value in example.params:
        if name in sets and sets[name] != value:
            raise SwarmOptionError(f"--set {name}={sets[name]}: the example has "
                                   f"{name}={value}; leave out this --set")
    args.set = [*args.set, *(f"{k}={v}" for k, v in example.params if k not in sets)]
    args.seed = example.seed
    if args.steps is None:
        args.steps = example.steps
    if args.properties is None and data.get("properties"):
        args.properties = data["properties"]
    args.check = True
    try:
        text = Path(args.file).read_text(encoding="utf-8").encode("utf-8")
    except (OSError, UnicodeDecodeError):
        text = None                  # compiling reports the missing file
    if text is not None and hashlib.sha256(text).hexdigest() != data.get("sha256"):
        print(f"{args.file}: warning: the program changed since the example was saved; "
              "the replay may differ", file=sys.stderr)
    return example.layout
