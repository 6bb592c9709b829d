"""`nn("models/x.pt", inputs...)`: a small torch network as an expression.

Checker: the first argument is a string literal naming a model file at or under the
program's folder; its JSON sidecar (read without importing torch) fixes the input width
(a number counts 1, a vector 2: x then y) and the result type (1 output: a number, 2
outputs: a vector; any other width is an error). Codegen: one closure per call site that
stacks its inputs into `(M, n_in)` rows and runs them through the model in one batched
forward pass, so a call site costs one pass per frame per tick (all agents of a status,
or all neighbour pairs inside an aggregate). Runtime: models load when a Simulation is
created (never while only checking), once per program and resolved path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from swarmdsl.compiler import ast, codegen, program, typing_rules
from swarmdsl.compiler.batching import per_replica
from swarmdsl.compiler.builtins import BOOL, NUM, STR, TYPE_TEXT, VEC, declare_calls
from swarmdsl.errors import Span, SwarmRuntimeError

# `runtime.nn` loads where a program calls `nn`: checking one that does not skips it.
if TYPE_CHECKING:
    from swarmdsl.runtime.nn import ModelError, ModelInfo

ERR = "error"
EXTRA_KEY = "nn"
EXAMPLE = 'e.g. nn("models/spring1d.pt", left.x, right.x)'


@dataclass
class ModelUse:
    """One model file a program calls: its sidecar, where it is first called, and the
    loaded network once a run needs it."""

    spec: str                  # the path as written in the program
    info: ModelInfo
    span: Span                 # the first call site naming it
    loaded: object | None = None


@dataclass
class ProgramModels:
    """Every model a program calls, keyed by resolved path: the per-program cache."""

    uses: dict[Path, ModelUse] = field(default_factory=dict)

    def add(self, path: Path, spec: str, info: ModelInfo, span: Span) -> None:
        self.uses.setdefault(path, ModelUse(spec, info, span))

    def model(self, path: Path):
        """The LoadedModel for `path`, loading it (and importing torch) on first use."""
        use = self.uses[path]
        if use.loaded is None:
            from swarmdsl.runtime.nn import ModelError, load_model

            try:
                model = load_model(path)
            except ModelError as exc:
                raise SwarmRuntimeError(f"cannot load model '{use.spec}': {exc}", use.span,
                                        _load_hint(exc)) from None
            if (model.n_in, model.n_out) != (use.info.n_in, use.info.n_out):
                raise SwarmRuntimeError(  # pragma: no cover - sidecar changed meanwhile
                    f"model '{use.spec}' changed since the program was checked; check it "
                    "again", use.span)
            use.loaded = model
        return use.loaded

    def load_all(self, source: str) -> None:
        for path in self.uses:
            try:
                self.model(path)
            except SwarmRuntimeError as err:
                raise err.with_source(source) from None


def _load_hint(exc: ModelError) -> str | None:
    text = str(exc)
    if "pip install" in text:
        return None
    if "refusing" in text:
        return "only plain weight files written by `swarmdsl train` can be loaded"
    return None


# ---- checker ----


def _program_dir(chk) -> Path:
    pd = getattr(chk, "program_dir", None)
    return Path(pd) if pd is not None else Path(chk.filename).resolve().parent


def check_nn(chk, e: ast.Call, scope) -> str:
    """Type rule of `nn(...)`: path, sidecar, input width, result type."""
    inputs = e.args[1:]
    types = [chk.expr(a, scope) for a in inputs]
    if e.each is not None or e.default is not None:
        return chk.fail("`nn` does not take `:` or `else`", e.span, EXAMPLE)
    if not e.args:
        return chk.fail("`nn` needs a model file and its inputs", e.span, EXAMPLE)
    path_arg = e.args[0]
    if not isinstance(path_arg, ast.StrLit):
        # not typed: `nn(models/x.pt, ...)` would also be "unknown name `models`", `x`
        return chk.fail("the first argument of `nn` must be a string literal naming the "
                        "model file", path_arg.span, EXAMPLE)
    chk.facts.set_type(path_arg, STR)
    spec = path_arg.value
    if not spec.endswith(".pt"):
        return chk.fail(f"model file '{spec}' must be a `.pt` weights file", path_arg.span,
                        "name the weights; their `.json` sidecar sits beside them")
    from swarmdsl.runtime.nn import ModelError, read_model_info, resolve_model_path

    try:
        path = resolve_model_path(spec, _program_dir(chk))
        info = read_model_info(path)
    except ModelError as exc:
        return chk.fail(str(exc), path_arg.span)
    except (OSError, ValueError) as exc:  # a name the file system cannot take
        reason = getattr(exc, "strerror", None) or str(exc)
        return chk.fail(f"model path '{spec[:60]}{'...' * (len(spec) > 60)}' cannot be "
                        f"used: {reason}", path_arg.span)
    if info.n_out not in (1, 2):
        return chk.fail(f"model '{spec}' has {info.n_out} outputs; `nn` returns a number "
                        "(1 output) or a vector (2 outputs)", path_arg.span,
                        "train one model per number, or one with 2 outputs for a vector")
    width, bad = 0, False
    for a, t in zip(inputs, types, strict=True):
        if t == VEC:
            width += 2
        elif t == NUM:
            width += 1
        elif t == ERR:
            bad = True
        else:
            bad = True
            hint = "write `if c then 1 else 0`" if t == BOOL else None
            chk.fail(f"an input of `nn` must be a number or a vector, got "
                     f"{TYPE_TEXT.get(t, t)}", a.span, hint)
    if bad:
        return ERR
    if width != info.n_in:
        got = f"{width}" + (" (a vector counts as 2)" if VEC in types else "")
        names = f": {', '.join(info.inputs)}" if info.inputs else ""
        return chk.fail(f"model '{spec}' takes {info.n_in} input"
                        f"{'' if info.n_in == 1 else 's'}, got {got}", e.span,
                        f"its inputs are{names or ' ' + str(info.n_in) + ' numbers'}")
    models = chk.extra.setdefault(EXTRA_KEY, ProgramModels())
    models.add(path, spec, info, e.span)
    chk.facts.set_name(e, ("nn", path))
    return NUM if info.n_out == 1 else VEC


# ---- codegen ----


def _active_rows(f):
    """Rows of the frame that reach the call: agents still running this status body; in
    a pair frame, the pairs of such agents. None when every row does."""
    active = getattr(f, "active", None)
    if active is None:
        owner = getattr(f, "owner", None)
        owner_active = getattr(owner, "active", None)
        if owner_active is None:
            return None
        active = owner_active[f.seg]
    if active.all():
        return None
    return np.flatnonzero(active)


def _who(f, row: int) -> str:
    """The agent a frame row belongs to, by id (rows move as agents change status or
    leave; ids do not): `agent 7`, or in a pair frame `agent 7 and its neighbour 2`."""
    ids = f.sim.agents.cols["id"]
    owner = getattr(f, "owner", None)
    if owner is not None and hasattr(f, "seg"):
        return (f"agent {int(ids[owner.idx[f.seg[row]]])} and its neighbour "
                f"{int(ids[f.j[row]])}")
    return f"agent {int(ids[f.idx[row]])}"


def _inputs_text(labels, x_row) -> str:
    return ", ".join(f"{name} = {float(v):g}" for name, v in zip(labels, x_row,
                                                                  strict=True))


def _where(f) -> str:
    kind = getattr(getattr(f, "kind", None), "name", "?")
    status = getattr(f, "status_name", None)
    if status is None:
        return f"kind `{kind}`, while placing agents"
    return f"kind `{kind}`, status `{status}`, tick {f.tick}"


def compile_nn(gen, e: ast.Call):
    """Closure for one `nn(...)` call site: one forward pass over the frame's rows."""
    from swarmdsl.runtime.nn import ModelError, NonFiniteOutput

    path = gen.facts.name_of(e)[1]
    models: ProgramModels = gen.info.extra[EXTRA_KEY]
    use = models.uses[path]
    spec, n_in, n_out = use.spec, use.info.n_in, use.info.n_out
    inputs = [gen.expr(a) for a in e.args[1:]]
    types = [gen.type_of(a) for a in e.args[1:]]
    labels = list(use.info.inputs) or [f"input {i + 1}" for i in range(n_in)]
    span = e.span

    def nn_call(f):
        n = f.n
        cols = []
        for fn, t in zip(inputs, types, strict=True):
            v = np.asarray(fn(f), dtype=np.float64)
            cols.append(np.broadcast_to(v, (n, 2)) if t == VEC
                        else np.broadcast_to(v, (n,))[:, None])
        x = np.concatenate(cols, axis=1)
        rows = _active_rows(f)
        if rows is not None:
            x = x[rows]
        def frame_row(r) -> int:   # a row of the batch, as a row of the frame
            return int(rows[r]) if rows is not None else int(r)

        def non_finite_output(r):
            return SwarmRuntimeError(
                f"nn(\"{spec}\") produced a non-finite output for "
                f"{_who(f, frame_row(r))} ({_where(f)}), from {_inputs_text(labels, x[r])}",
                span, "check the inputs lie in the range the model was trained on")

        finite = np.isfinite(x)
        if not finite.all():
            r, c = np.argwhere(~finite)[0]
            what = "NaN" if np.isnan(x[r, c]) else "infinite"
            raise SwarmRuntimeError(
                f"input {labels[c]} of nn(\"{spec}\") is {what} for "
                f"{_who(f, frame_row(r))} ({_where(f)})", span,
                "guard the value, e.g. with `if ... then ... else`")
        try:
            y = models.model(path).forward(x)
        except NonFiniteOutput as exc:
            raise non_finite_output(exc.row) from None
        except ModelError as exc:
            raise SwarmRuntimeError(f"nn(\"{spec}\") failed ({_where(f)}): {exc}",
                                    span) from None
        want = (x.shape[0], n_out)
        if y.shape != want:
            raise SwarmRuntimeError(f"nn(\"{spec}\") returned shape {y.shape}, expected "
                                    f"{want} ({_where(f)})", span)
        bad = ~np.isfinite(y).all(axis=1)
        if bad.any():
            raise non_finite_output(int(np.flatnonzero(bad)[0]))
        if rows is not None:
            full = np.zeros((n, n_out), dtype=np.float64)
            full[rows] = y
            y = full
        return y[:, 0] if n_out == 1 else y
    return nn_call


# ---- runtime ----


class _Loader:
    """Runtime plug-in: loads the program's models when a Simulation starts."""

    def __init__(self, sim, models: ProgramModels):
        models.load_all(sim.program.source)

    def state_dict(self, sim) -> dict:
        """Models are read-only during a run: loading them again is their state."""
        return {}

def program_hook(info, prog, gen) -> None:
    models = info.extra.get(EXTRA_KEY)
    if models is not None and models.uses:
        prog.extensions.append(per_replica(lambda sim, _m=models: _Loader(sim, _m),
                                           "its `nn()` models run"))


typing_rules.CALL_RULES["nn"] = check_nn
# one forward pass for a batch, each row on its own: the same bits for any row count
declare_calls(("nn",), batch=True, kilobot=True)
codegen.CALL_CODEGEN["nn"] = compile_nn
if program_hook not in program.PROGRAM_HOOKS:
    program.PROGRAM_HOOKS.append(program_hook)

__all__ = ["ModelUse", "ProgramModels", "check_nn", "compile_nn", "program_hook"]
