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
import math
import os
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

from swarmdsl.compiler.builtins import BOOL, NUM, VEC
from swarmdsl.compiler.errors import SwarmOptionError
from swarmdsl.compiler.limits import upper
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


# What a saved example holds; `program` and `failure` only describe it.
_REQUIRED = ("params", "seed", "steps", "layout")
_ENTRIES = ("format", "program", "sha256", *_REQUIRED, "properties", "failure")
_AGENT_ENTRIES = ("kind", "id", "index", "pos", "vars")
MAX_SEED = 2**63 - 1


def load_example(path: Path) -> tuple[Example, dict]:
    """(Example, the whole file as a dict) from a saved example.

    Every entry the replay uses is checked here, so a damaged or hand-edited file is an
    option error naming `--example FILE` and the entry, never a traceback and never an
    agent or value quietly dropped; `check_example` then checks it against the program.
    """
    where = f"--example {path}"
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise SwarmOptionError(f"{where}: cannot read: {exc.strerror}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise SwarmOptionError(f"{where}: not JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise SwarmOptionError(f"{where}: not a saved example (no \"format\": \"{FORMAT}\")")
    bad = _Bad(where)
    _known_keys(bad, data, _ENTRIES, "", "an example has")
    for key in _REQUIRED:
        if key not in data:
            bad(f"no \"{key}\" entry (a saved example has {', '.join(_ENTRIES)})")
    seed = _whole(bad, data["seed"], "\"seed\"", 0, MAX_SEED)
    steps = _whole(bad, data["steps"], "\"steps\"", 0, upper("steps"))
    for key in ("program", "sha256"):
        if data.get(key) is not None and not isinstance(data[key], str):
            bad(f"\"{key}\" must be text, got {_shown(data[key])}")
    if not isinstance(data["params"], dict):
        bad(f"\"params\" must be an object of name: value, got {_shown(data['params'])}")
    params = []
    for name, value in data["params"].items():
        if isinstance(value, bool | int | float) and not _finite(value):
            bad(f"param {name}={_shown(value)}: not a finite number")
        if not isinstance(value, str | bool | int | float):
            bad(f"param {name}: {_shown(value)} is not a param value (a number or a "
                "boolean)")
        params.append((name, value if isinstance(value, str) else param_text(value)))
    props = data.get("properties")
    if props is not None and (not isinstance(props, list)
                              or not all(isinstance(p, str) for p in props)):
        bad(f"\"properties\" must be a list of property names, got {_shown(props)}")
    layout = data["layout"]
    if layout is not None:
        _check_layout_json(bad, layout)
        layout = Layout.from_json(layout, where)
    return Example(tuple(params), seed, steps, layout), data


class _Bad:
    """Raises option errors naming the example file (and a hint, once one is known)."""

    def __init__(self, where: str, hint: str | None = None):
        self.where = where
        self.hint = hint

    def __call__(self, message: str) -> NoReturn:
        raise SwarmOptionError(f"{self.where}: {message}", hint=self.hint)


def _shown(value) -> str:
    """A JSON value as the file spells it, cut short."""
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _finite(value) -> bool:
    """A bool, or a number a float holds (a JSON integer can be any length)."""
    try:
        return isinstance(value, bool) or math.isfinite(float(value))
    except OverflowError:
        return False


def _number(value) -> bool:
    """A JSON number (true and false are not numbers here)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and _finite(value)


def _whole(bad: _Bad, value, what: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        bad(f"{what}: {_shown(value)} is not a whole number from {lo:,} to {hi:,}")
    return value


def _known_keys(bad: _Bad, obj: dict, known, prefix: str, has: str) -> None:
    for key in obj:
        if key not in known:
            bad(f"{prefix}unknown entry \"{key}\" ({has} {', '.join(known)})")


def _check_layout_json(bad: _Bad, layout) -> None:
    """The layout's shape and types; what only the program can judge (kinds, variables,
    counts, the world's bounds) is `check_example`'s."""
    if not isinstance(layout, dict):
        bad(f"\"layout\" must be an object with \"kinds\" and \"agents\", got "
            f"{_shown(layout)}")
    _known_keys(bad, layout, ("kinds", "agents"), "layout: ", "a layout has")
    kinds, agents = layout.get("kinds"), layout.get("agents")
    if not isinstance(kinds, list) or not all(isinstance(k, str) for k in kinds):
        bad(f"layout.kinds must be a list of kind names, got {_shown(kinds)}")
    if len(set(kinds)) != len(kinds):
        bad(f"layout.kinds lists a kind twice: {_shown(kinds)}")
    if not isinstance(agents, list):
        bad(f"layout.agents must be a list of agents, got {_shown(agents)}")
    ids: dict[int, int] = {}
    for i, a in enumerate(agents):
        at = f"layout.agents[{i}]"
        if not isinstance(a, dict):
            bad(f"{at} must be an object, got {_shown(a)}")
        _known_keys(bad, a, _AGENT_ENTRIES, f"{at}: ", "an agent has")
        for key in ("kind", "id"):
            if key not in a:
                bad(f"{at}: no \"{key}\" entry")
        if not isinstance(a["kind"], str):
            bad(f"{at}: \"kind\" must be a kind name, got {_shown(a['kind'])}")
        if a["kind"] not in kinds:
            bad(f"{at}: kind \"{a['kind']}\" is not in layout.kinds ({', '.join(kinds)})")
        _whole(bad, a["id"], f"{at}: \"id\"", 0, MAX_SEED)
        if a["id"] in ids:
            bad(f"{at}: id {a['id']} is also layout.agents[{ids[a['id']]}]'s; agent ids "
                "must be distinct")
        ids[a["id"]] = i
        if a.get("index") is not None:
            _whole(bad, a["index"], f"{at}: \"index\"", 0, MAX_SEED)
        if a.get("pos") is not None and not _vector(a["pos"]):
            bad(f"{at}: \"pos\" must be two finite numbers [x, y], got {_shown(a['pos'])}")
        values = a.get("vars")
        if values is not None and not isinstance(values, dict):
            bad(f"{at}: \"vars\" must be an object of name: value, got {_shown(values)}")
        for name, v in (values or {}).items():
            if not (isinstance(v, bool) or _number(v) or _vector(v)):
                bad(f"{at}: variable {name}: {_shown(v)} is not a value (a finite "
                    "number, true or false, or [x, y])")


def _vector(value) -> bool:
    return isinstance(value, list) and len(value) == 2 and all(_number(x) for x in value)


def check_example(example: Example, data: dict, program, where: str,
                  hint: str | None = None) -> None:
    """The example against the compiled program: every kind, variable, index and
    position of its layout must fit it (an agent of a kind the program lacks would
    otherwise vanish from the replay), and its properties must exist."""
    bad = _Bad(where, hint)
    kinds = {k.name: k for k in program.kinds}
    names = ", ".join(kinds) or "none"
    layout = example.layout
    for name in layout.kinds if layout is not None else ():
        if name not in kinds:
            bad(f"layout.kinds: no agent kind \"{name}\" in {program.filename} (kinds: "
                f"{names})")
    w = program.world
    seen: dict[tuple[str, int], int] = {}
    for i, a in enumerate(layout.agents if layout is not None else ()):
        kind, at = kinds[a.kind], f"layout.agents[{i}] (id {a.id}, {a.kind})"
        if a.index is not None and a.index >= kind.count:
            bad(f"{at}: index {a.index} is not below the count of `{a.kind}`, "
                f"{kind.count}")
        if a.index is not None and (a.kind, a.index) in seen:
            bad(f"{at}: index {a.index} is also layout.agents[{seen[a.kind, a.index]}]'s")
        if a.index is not None:
            seen[a.kind, a.index] = i
        if a.pos is not None and not (0 <= a.pos[0] <= w.width and 0 <= a.pos[1] <= w.height):
            bad(f"{at}: pos [{a.pos[0]:g}, {a.pos[1]:g}] is outside the world "
                f"({w.width:g} x {w.height:g})")
        declared = {name: t for name, t, _init in kind.vars}
        for name, value in a.values:
            if name not in declared:
                bad(f"{at}: \"{name}\" is not a variable of `{a.kind}` (its variables: "
                    f"{', '.join(declared) or 'none'})")
            if not _fits(declared[name], value):
                bad(f"{at}: variable {name} is a {declared[name]}, not "
                    f"{_shown(_json_value(value))}")
    for name in kinds.keys() & set(layout.kinds if layout is not None else ()):
        n, count = len(layout.of(name)), kinds[name].count
        if n > count:
            bad(f"layout: {n} agents of `{name}`, the program places at most {count}")
    props = data.get("properties")
    if props:
        from swarmdsl.compiler.lang_properties import properties_of

        infos = [p.info for p in properties_of(program)]
        for name in props:
            if not any(name in (info.qualified, info.name) for info in infos):
                bad(f"properties: no property \"{name}\" in {program.filename} (the "
                    f"program has: {', '.join(i.qualified for i in infos) or 'none'})")


def _fits(var_type: str, value) -> bool:
    if var_type == BOOL:
        return isinstance(value, bool)
    if var_type == VEC:
        return isinstance(value, tuple)
    return var_type == NUM and not isinstance(value, bool | tuple)


def _json_value(value):
    return list(value) if isinstance(value, tuple) else value


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


def apply_example(args) -> Replay:
    """Fill `swarmdsl run`'s options from `--example FILE`.

    The file gives the seed, params, ticks and properties; `--steps` and `--property`
    may override them, a different `--seed` or `--set` value may not (that would not be
    a replay). Turns checking on; warns when the program is not the one the example was
    saved for (its text, by sha256).
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
    from_file = {k: v for k, v in example.params if k not in sets}
    args.set = [*args.set, *(f"{k}={v}" for k, v in from_file.items())]
    args.seed = example.seed
    if args.steps is None:
        args.steps = example.steps
    if args.properties is None and data.get("properties"):
        args.properties = data["properties"]
    else:                               # the file's names are not the ones checked
        data = {**data, "properties": None}
    args.check = True
    hint = _other_program(args, data)
    if hint is not None:
        print(f"warning: --example {args.example} was saved for another version of the "
              f"program; the replay may differ ({hint})", file=sys.stderr)
        hint = f"the example was saved for another program ({hint})"
    return Replay(args.example, example, data, from_file, hint)


def _other_program(args, data: dict) -> str | None:
    """Both hashes, briefly, when the program is not the text the example was saved
    for; None when it is (or cannot be read: compiling reports that)."""
    try:    # the bytes: the saved hash is over the text as compiled, CRLF and all
        text = Path(args.file).read_bytes()
    except OSError:
        return None
    now, saved = hashlib.sha256(text).hexdigest(), data.get("sha256")
    if now == saved:
        return None
    was = f"sha256 {saved[:12]}" if saved else "no sha256"
    named = data.get("program")
    if named and named != Path(args.file).name:
        was += f" of {named}"
    return f"it records {was}, {Path(args.file).name} has sha256 {now[:12]}"
