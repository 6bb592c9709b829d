"""swarmdsl: a declarative language and vectorised runtime for swarm-robot behaviour."""

from swarmdsl.version import __version__

_ERRORS = ("SwarmCheckError", "SwarmError", "SwarmOptionError", "SwarmRuntimeError",
           "SwarmSyntaxError")


def __getattr__(name):
    # The error classes load on first use: `import swarmdsl` stays nearly free, so the
    # command can take over Ctrl-C within milliseconds of starting (swarmdsl.stopping).
    if name in _ERRORS:
        from swarmdsl import errors

        return getattr(errors, name)
    if name in ("Batch", "RunResult"):     # many seeds as batched replicas (batch_runner.py)
        from swarmdsl.runtime import batch_runner

        return getattr(batch_runner, name)
    raise AttributeError(f"module 'swarmdsl' has no attribute {name!r}")

__all__ = ["Batch", "RunResult", "SwarmCheckError", "SwarmError", "SwarmOptionError", "SwarmRuntimeError",
           "SwarmSyntaxError", "__version__", "load_program", "show"]


def show(target, *, seed=None, width=560):
    """The studio's view of `target` in a notebook cell: a `.swarm` path, a Program from
    `load_program`, or a `Run` (with the plots of its `metrics.parquet` once it has run
    with `out=`). Returns an anywidget with the page's controls, sliders and live plots
    (docs/studio.md); needs the `studio` extra."""
    try:
        import anywidget  # noqa: F401
    except ImportError:
        from swarmdsl.errors import SwarmOptionError

        raise SwarmOptionError("swarmdsl.show needs anywidget: pip install "
                               "'swarmdsl[studio]'") from None
    from swarmdsl.studio.widget import show as studio_show

    return studio_show(target, seed=seed, width=width)


def load_program(path, overrides=None):
    """Parse, check and compile the `.swarm` file at `path` into a Program.

    `overrides` maps param names to values (numbers, booleans or their text), as
    `--set NAME=VALUE` does. Every failure is a `SwarmError` (see docs/api.md).
    """
    from swarmdsl.compiler import compile_file
    from swarmdsl.errors import SwarmOptionError
    from swarmdsl.runtime.arguments import param_text, required_path

    path = required_path("the program path", path, "load_program needs a .swarm file")
    if overrides is None:
        overrides = {}
    if not isinstance(overrides, dict) or not all(isinstance(k, str) for k in overrides):
        raise SwarmOptionError("overrides must map param names to values, "
                               "e.g. {\"n\": 200}")
    import numbers

    import numpy as np

    texts = {}
    for name, value in overrides.items():
        if not isinstance(value, bool | np.bool_ | str | numbers.Real):   # numpy too
            raise SwarmOptionError(f"override {name}: expected a number, a boolean or text, "
                                   f"got {type(value).__name__}")
        texts[name] = param_text(value)
    try:
        return compile_file(path, texts)
    except SwarmOptionError as err:
        raise _as_override(err, overrides, texts) from None


def _as_override(err, overrides: dict, texts: dict):
    """The checker words a bad override as the command line gives it (`--set n=abc:
    ...`); a caller of `load_program` gave `overrides`, so name that instead. The
    override is found by the exact text the checker quotes, not by parsing it: a name
    or value may hold `=`, `:` or spaces (`{"n=3": 5}`, `{"n": "5: x"}`)."""
    from swarmdsl.errors import SwarmOptionError

    heads = {f"--set {name}: ": name for name in overrides}
    heads.update({f"--set {name}={texts[name]}: ": name for name in overrides})
    for head in sorted(heads, key=len, reverse=True):   # the value's head first
        if err.message.startswith(head):
            name = heads[head]
            named = f"overrides[{name!r}] = {overrides[name]!r}"
            return SwarmOptionError(f"{named}: {err.message[len(head):]}", hint=err.hint)
    return err
