"""The compiled Program: status closures and initialisers per agent kind, ready to run."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import BOOL, NUM, VEC
from swarmdsl.compiler.info import VALUE_DEFAULT, ProgramInfo
from swarmdsl.compiler.lowering import REFERENCE, Lowering

# Extension hooks run after the kinds are compiled: fn(info, program, codegen). They add
# runtime plug-in factories to `program.extensions` (fields, regions, messaging, ...).
PROGRAM_HOOKS: list = []

_DTYPES = {NUM: ((), np.float64), BOOL: ((), np.bool_), VEC: ((2,), np.float64)}


@dataclass
class CompiledStatus:
    name: str
    code: int
    run: object                      # closure(frame)


@dataclass
class CompiledKind:
    name: str
    index: int
    count: int
    robot: str
    sense: float
    statuses: list[CompiledStatus]
    place: object | None             # closure(frame) -> (M, 2), or None = uniform
    place_region: str | None
    velocity: object | None
    heading: object | None
    max_speed: object | None
    initial: object | None            # closure(frame) -> status name ids
    vars: list[tuple[str, str, object]]   # (name, type, init closure)
    option_spans: dict = field(default_factory=dict)    # option name, "var NAME" -> span
    # ("option", place|velocity|heading|max_speed) and ("var", NAME) steps in the order
    # they run (compiler/init_order.py); None: the options, then the variables
    init_order: list | None = None


@dataclass
class Program:
    info: ProgramInfo
    source: str
    filename: str
    program_dir: Path
    kinds: list[CompiledKind] = field(default_factory=list)
    status_display: list[str] = field(default_factory=list)   # per global status code
    status_name_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    var_specs: dict = field(default_factory=dict)
    var_types: dict = field(default_factory=dict)
    pair_radius: float = 0.0
    extensions: list = field(default_factory=list)   # runtime plug-ins (fields, regions)
    # The lowering its closures were compiled with; None: none was asked for (the
    # reference closures, until the backend of a run lowers them: `lower`).
    lowering: Lowering | None = None
    built_extensions: int = 0        # how many of `extensions` compiling added

    def lower(self, lowering: Lowering) -> None:
        """Compile this program's closures again with `lowering`, in place, unless it
        was compiled with a lowering already: what a backend asks when a run starts (the
        lowered closures run on every backend, so other runs are not affected). Plug-ins
        added since it was compiled (`run --check`'s) stay."""
        if self.lowering is not None:
            return
        fresh = build_program(self.info, self.source, self.program_dir, lowering)
        added = self.extensions[self.built_extensions:]
        vars(self).update(vars(fresh))
        self.extensions = [*fresh.extensions, *added]

    def batch_refusal(self) -> str | None:
        """Why R replicas of this program cannot run as one batch, each bit-identical to
        its solo run, or None: read off its constructs' rows (`compiler/batching.py`)."""
        from swarmdsl.compiler.batching import batch_refusal

        return batch_refusal(self)

    @property
    def metrics(self) -> list:
        """The compiled `metric`s (`lang_metrics.CompiledMetric`), top-level ones first,
        for the run's metric log."""
        return list(self.info.extra.get("compiled_metrics", []))

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.source.encode()).hexdigest()

    @property
    def params(self) -> dict:
        return dict(self.info.params)

    @property
    def world(self):
        return self.info.world

    def status_code(self, kind: str, status: str) -> int:
        k = self.info.kind(kind)
        offset = sum(len(x.statuses) for x in self.info.kinds[: k.index])
        return offset + k.statuses.index(status)


def build_program(info: ProgramInfo, source: str, program_dir: Path,
                  lowering: Lowering | None = None) -> Program:
    """Compile every kind's statuses and initialisers into closures, handing each part
    a backend may run its own way to `lowering` (`compiler/lowering.py`; None: the
    reference closures, left for a backend to lower)."""
    from swarmdsl.compiler.codegen import CodeGen

    prog = Program(info, source, info.filename, program_dir, lowering=lowering)
    multi = len(info.kinds) > 1
    codes = []
    for k in info.kinds:
        for s in k.statuses:
            prog.status_display.append(f"{k.name}.{s}" if multi else s)
            codes.append(info.status_name_id(s))
    prog.status_name_ids = np.asarray(codes, dtype=np.int32)
    for name, t in info.var_types().items():
        tail, dtype = _DTYPES[t]
        prog.var_specs[name] = (tail, dtype, VALUE_DEFAULT[t])
        prog.var_types[name] = t
    gen = CodeGen(info, prog, lowering or REFERENCE)
    for k in info.kinds:
        statuses = [CompiledStatus(s, prog.status_code(k.name, s),
                                   gen.status_body(k, k.status_decls[s]))
                    for s in k.statuses]
        opts = k.options

        def opt_expr(name, vtype, _opts=opts):
            o = _opts.get(name)
            if o is None or not o.args:
                return None
            return gen.init_value(o.args[0], vtype, f"`{name}`", inf_ok=name == "max_speed")

        place, region = None, None
        p = opts.get("place")
        if p is not None:
            if p.has_in:
                region = getattr(p.args[0], "id", None)
            elif not (isinstance(p.args[0], ast.Name) and p.args[0].id == "uniform"):
                place = gen.init_value(p.args[0], VEC, "`place`")
        initial = None
        if "initial" in opts:
            initial = gen.init_value(opts["initial"].args[0], "status")
        vars_ = [(v.name, v.type, gen.init_value(v.decl.value, v.type,
                                                 f"the initial value of `{v.name}`"))
                 for v in k.vars.values()]
        sense = k.sense if k.sense is not None else 0.0
        prog.kinds.append(CompiledKind(
            k.name, k.index, k.count, k.robot, sense, statuses, place, region,
            opt_expr("velocity", VEC), opt_expr("heading", NUM), opt_expr("max_speed", NUM),
            initial, vars_, {**{n: o.span for n, o in opts.items()},
                             **{f"var {v.name}": v.decl.span for v in k.vars.values()}},
            info.extra.get("init_order", {}).get(k.name)))
        if k.uses_neighbors:
            prog.pair_radius = max(prog.pair_radius, sense)
    for hook in PROGRAM_HOOKS:
        hook(info, prog, gen)
    prog.built_extensions = len(prog.extensions)
    return prog
