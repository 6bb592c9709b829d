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

from swarmdsl.errors import SwarmOptionError
from swarmdsl.limits import upper
from swarmdsl.runtime.arguments import param_text  # noqa: F401  (its callers import it here)
from swarmdsl.runtime.json_checks import MAX_WHOLE, Refuse, finite, known_keys, shown, whole
from swarmdsl.runtime.layout import Layout, check_fit

FORMAT = "swarmdsl-example-1"


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


# What a saved example holds; `program` and `failure` only describe it.
_REQUIRED = ("params", "seed", "steps", "layout")
_ENTRIES = ("format", "program", "sha256", *_REQUIRED, "properties", "failure")
MAX_SEED = MAX_WHOLE


def load_example(path: Path) -> tuple[Example, dict]:
    """(Example, the whole file as a dict) from a saved example.

    Every entry the replay uses is checked here (the layout by `Layout.from_json`), so a
    damaged or hand-edited file is an option error naming `--example FILE` and the
    entry, never a traceback; `check_example` then checks it against the program.
    """
    where = f"--example {path}"
    if not isinstance(path, str | os.PathLike) or not str(path).strip():
        raise SwarmOptionError(f"{where}: the path must be a non-empty file name")
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise SwarmOptionError(f"{where}: cannot read: {exc.strerror}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise SwarmOptionError(f"{where}: not JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise SwarmOptionError(f"{where}: not a saved example (no \"format\": \"{FORMAT}\")")
    bad = Refuse(where)
    known_keys(bad, data, _ENTRIES, "", "an example has")
    for key in _REQUIRED:
        if key not in data:
            bad(f"no \"{key}\" entry (a saved example has {', '.join(_ENTRIES)})")
    seed = whole(bad, data["seed"], "\"seed\"", 0, MAX_SEED)
    steps = whole(bad, data["steps"], "\"steps\"", 0, upper("steps"))
    for key in ("program", "sha256"):
        if data.get(key) is not None and not isinstance(data[key], str):
            bad(f"\"{key}\" must be text, got {shown(data[key])}")
    if not isinstance(data["params"], dict):
        bad(f"\"params\" must be an object of name: value, got {shown(data['params'])}")
    params = []
    for name, value in data["params"].items():
        if isinstance(value, bool | int | float) and not finite(value):
            bad(f"param {name}={shown(value)}: not a finite number")
        if not isinstance(value, str | bool | int | float):
            bad(f"param {name}: {shown(value)} is not a param value (a number or a "
                "boolean)")
        params.append((name, value if isinstance(value, str) else param_text(value)))
    props = data.get("properties")
    if props is not None and (not isinstance(props, list)
                              or not all(isinstance(p, str) for p in props)):
        bad(f"\"properties\" must be a list of property names, got {shown(props)}")
    layout = data["layout"]
    if layout is not None:
        layout = Layout.from_json(layout, where)
    return Example(tuple(params), seed, steps, layout), data


def check_example(example: Example, data: dict, program, where: str,
                  hint: str | None = None) -> None:
    """The example against the compiled program: its layout must fit it (the rules a
    `Simulation` applies, here named after the file) and its properties must exist."""
    if example.layout is not None:
        check_fit(example.layout, program, where, hint)
    props = data.get("properties")
    if props:
        from swarmdsl.compiler.lang_properties import properties_of

        refuse = Refuse(where, hint)
        infos = [p.info for p in properties_of(program)]
        for name in props:
            if not any(name in (info.qualified, info.name) for info in infos):
                refuse(f"properties: no property \"{name}\" in {program.filename} (the "
                       f"program has: {', '.join(i.qualified for i in infos) or 'none'})")


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


class Replay:
    """`swarmdsl run --example FILE`: the loaded example and how it reached the options,
    so that a value the file brought in is blamed on the file, not on a `--set` or
    `--property` the user never typed."""

    def __init__(self, path: Path, example: Example, data: dict, params: dict[str, str],
                 hint: str | None):
        self.where = f"--example {path}"
        self.example = example
        self.data = data
        self.params = params            # the params the file set (the user gave no --set)
        self.hint = hint                # when saved for another program: both hashes
        self.seed = example.seed
        self.steps: int | None = None          # the ticks to run
        self.properties: list | None = None    # the properties to check (None: all)

    def compile(self, compile_args):
        """`compile_args()` (the CLI's compile), its param errors naming the file."""
        try:
            return compile_args()
        except SwarmOptionError as err:
            for name, value in self.params.items():
                for prefix in (f"--set {name}={value}: ", f"--set {name}: "):
                    if err.message.startswith(prefix):
                        rest = err.message[len(prefix):]
                        raise SwarmOptionError(f"{self.where}: param {name}={value}: {rest}",
                                               hint=err.hint or self.hint) from None
            raise

    def layout(self, program) -> Layout | None:
        """The example's swarm, once it is known to fit `program` (`check_example`)."""
        check_example(self.example, self.data, program, self.where, self.hint)
        return self.example.layout


def replay_example(path, program_file, seed: int | None, sets: dict[str, str],
                   steps: int | None, properties: list | None, resuming: bool) -> Replay:
    """What `swarmdsl run --example FILE` runs, given the options the user typed.

    The file gives the seed, params, ticks and properties; `steps` and `properties`
    may override them, a different `seed` or `--set` value may not (that would not be
    a replay). The replay checks properties; warns when the program is not the one the
    example was saved for (its text, by sha256). The command applies the result to its
    own options (`Replay.seed`, `.params`, `.steps`, `.properties`).
    """
    import sys

    example, data = load_example(path)
    if resuming:
        raise SwarmOptionError("--example starts a run from its own tick 0; leave out "
                               "--resume")
    if seed is not None and seed != example.seed:
        raise SwarmOptionError(f"--seed {seed}: the example was found with seed "
                               f"{example.seed}; leave out --seed")
    for name, value in example.params:
        if name in sets and sets[name] != value:
            raise SwarmOptionError(f"--set {name}={sets[name]}: the example has "
                                   f"{name}={value}; leave out this --set")
    from_file = {k: v for k, v in example.params if k not in sets}
    if properties is None and data.get("properties"):
        properties = data["properties"]
    else:                               # the file's names are not the ones checked
        data = {**data, "properties": None}
    hint = _other_program(program_file, data)
    if hint is not None:
        print(f"warning: --example {path} was saved for another version of the "
              f"program; the replay may differ ({hint})", file=sys.stderr)
        hint = f"the example was saved for another program ({hint})"
    replay = Replay(path, example, data, from_file, hint)
    replay.steps = example.steps if steps is None else steps
    replay.properties = properties
    return replay


def _other_program(program_file, data: dict) -> str | None:
    """Both hashes, briefly, when the program is not the text the example was saved
    for; None when it is (or cannot be read: compiling reports that)."""
    try:    # the bytes: the saved hash is over the text as compiled, CRLF and all
        text = Path(program_file).read_bytes()
    except OSError:
        return None
    now, saved = hashlib.sha256(text).hexdigest(), data.get("sha256")
    if now == saved:
        return None
    was = f"sha256 {saved[:12]}" if saved else "no sha256"
    named = data.get("program")
    if named and named != Path(program_file).name:
        was += f" of {named}"
    return f"it records {was}, {Path(program_file).name} has sha256 {now[:12]}"
