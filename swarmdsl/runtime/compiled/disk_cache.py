"""Composed kernels kept on disk between runs, under a key of everything they are made of.

The aggregate and statement kernels are closures over other jitted functions, built per
expression shape. numba's own `cache=True` cannot keep them: its key for a closure
includes its cells pickled, and a pickled dispatcher carries a fresh id in every
process, so each run compiles them again (seconds: boids' kernels take 3-5 s). Here the
key is instead a fingerprint of what decides the machine code: the bytecode, constants
and names of the kernel and of every function it reaches through its cells and its
globals, recursively, and the values of the numbers, strings and arrays among them.
numba adds the signature, its version and the CPU. A kernel with anything else in
reach is not kept on disk (it still compiles as before), so a key never stands for two
different kernels; a change to any source the kernel reaches changes its key.

Loading kernels compiled in several processes into one is safe only because no two
processes give machine code the same name (`jit.py`); a kernel is kept on disk only when
that holds. The files live where numba keeps its own (`NUMBA_CACHE_DIR`, else the
package's `__pycache__` when writable, else the user's cache folder);
`SWARMDSL_KERNEL_CACHE=0` turns this off.
"""

from __future__ import annotations

import hashlib
import os
import types
import warnings

import numpy as np

_ATOMS = (bool, int, float, complex, str, bytes, type(None))
# Part of every key: 2 since machine-code names are distinct between processes (kernels
# kept before that may share names with each other, so they are never loaded).
KEY_VERSION = 2
# Kernels this process built that are not kept on disk (no fingerprint, no folder for
# them, or the cache turned off): while there is one, `warm.note_compiled` marks nothing.
not_kept = 0


class _Unkeyable(Exception):
    """Something in a kernel's reach whose identity cannot be written down."""


def fingerprint(fn) -> str | None:
    """A hex digest naming the compiled code of dispatcher or function `fn`, or None
    when something in its reach has no stable description."""
    try:
        parts: list = []
        _value(fn, parts, {})       # a dispatcher's options too (parallel, error model)
    except _Unkeyable:
        return None
    return hashlib.sha256(repr(parts).encode()).hexdigest()


def _function(fn, parts: list, seen: dict) -> None:
    """Describe `fn` once (later mentions by number: recursion and sharing are fine)."""
    if id(fn) in seen:
        parts.append(("again", seen[id(fn)]))
        return
    seen[id(fn)] = len(seen)
    parts.append(("fn", fn.__module__, fn.__qualname__))
    code = fn.__code__
    _code(code, parts)
    for cell in fn.__closure__ or ():
        try:
            contents = cell.cell_contents
        except ValueError:      # a cell not filled yet: nothing to describe it by
            raise _Unkeyable("empty cell") from None
        _value(contents, parts, seen)
    for value in (*(fn.__defaults__ or ()), *sorted((fn.__kwdefaults__ or {}).items())):
        _value(value, parts, seen)
    scope = fn.__globals__
    names = sorted(_names(code))
    for name in names:
        if name in scope:
            parts.append(("global", name))
            _value(scope[name], parts, seen)
            if isinstance(scope[name], types.ModuleType) and \
                    scope[name].__name__.startswith("swarmdsl."):
                # `module.CONSTANT`: what the attribute holds, not only its name
                for attr in names:
                    if hasattr(scope[name], attr):
                        parts.append(("attribute", attr))
                        _value(getattr(scope[name], attr), parts, seen)


def _names(code) -> set[str]:
    """Every global or attribute name `code` and the code nested in it use."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _names(const)
    return names


def _code(code, parts: list) -> None:
    parts.append(("code", code.co_name, code.co_code.hex(), code.co_argcount,
                  code.co_varnames, code.co_freevars, code.co_names))
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            _code(const, parts)
        elif isinstance(const, frozenset):     # `x in {...}`: repr order varies by run
            parts.append(("const", "frozenset", sorted(repr(c) for c in const)))
        else:
            parts.append(("const", type(const).__name__, repr(const)))


def _value(value, parts: list, seen: dict) -> None:
    """Describe one value a kernel reaches (a cell, a default or a global)."""
    py_func = getattr(value, "py_func", None)
    if isinstance(value, _ATOMS):
        parts.append((type(value).__name__, repr(value)))
    elif py_func is not None and isinstance(py_func, types.FunctionType):
        parts.append(("jit", repr(sorted(getattr(value, "targetoptions", {}).items()))))
        _function(py_func, parts, seen)
    elif isinstance(value, types.FunctionType):
        _function(value, parts, seen)
    elif isinstance(value, types.ModuleType):
        parts.append(("module", value.__name__))
    elif isinstance(value, (types.BuiltinFunctionType, np.ufunc, type)):
        parts.append(("named", getattr(value, "__module__", None),
                      getattr(value, "__qualname__", None) or value.__name__))
    elif isinstance(value, np.dtype):
        parts.append(("dtype", value.str))
    elif isinstance(value, np.generic):
        parts.append(("scalar", value.dtype.str, value.tobytes().hex()))
    elif isinstance(value, np.ndarray):
        parts.append(("array", value.dtype.str, value.shape,
                      hashlib.sha256(np.ascontiguousarray(value).tobytes()).hexdigest()))
    elif isinstance(value, tuple):
        parts.append(("tuple", len(value)))
        for item in value:
            _value(item, parts, seen)
    else:
        raise _Unkeyable(type(value).__name__)


def enabled() -> bool:
    """Whether kernels are kept on disk: unless `SWARMDSL_KERNEL_CACHE` says no (read
    without importing numba, for the default backend's choice at start-up)."""
    setting = os.environ.get("SWARMDSL_KERNEL_CACHE", "1").strip().lower()
    return setting not in ("0", "no", "off", "false")


def keep_on_disk(dispatcher):
    """Let numba load `dispatcher`'s compiled code from disk, and save it there, under
    its fingerprint; returns the dispatcher. Without a fingerprint, or where numba
    cannot keep files, it is left to compile in memory as before."""
    global not_kept
    from swarmdsl.runtime.compiled import jit

    key = fingerprint(dispatcher) if enabled() and jit.distinct_names else None
    if key is None:
        not_kept += 1
        return dispatcher
    try:
        dispatcher._cache = _cache_class()(dispatcher.py_func, key)
    except Exception:      # no writable folder for it, or another numba's internals
        not_kept += 1
    return dispatcher


def on_disk(dispatcher) -> bool:
    """Whether machine code of `dispatcher` (made by `keep_on_disk`) is kept on disk
    for this numba and CPU, so its first call loads rather than compiles it."""
    cache = getattr(dispatcher, "_cache", None)
    key = getattr(cache, "_fingerprint", None)
    if key is None:
        return False
    try:
        from numba.core import codegen   # noqa: F401  (the target's magic tuple below)

        index = cache._cache_file._load_index()
        magic = dispatcher.targetctx.codegen().magic_tuple()
    except Exception:       # no index yet, or another numba's internals
        return False
    return any(k[1] == magic and k[2][2] == key for k in index)


_CLASS = None


def _cache_class():
    """numba's per-function cache with the fingerprint as the closure's key (made on
    first use: numba is imported only by runs that compile)."""
    global _CLASS
    if _CLASS is None:
        from numba.core.caching import FunctionCache, IndexDataCacheFile

        class KeyedFiles(IndexDataCacheFile):
            """One data file per key, named by the key's hash. numba numbers them in
            turn instead, which is a race between processes (a sweep's workers, say)
            saving two kernels of one index at once: both take the next number, one
            file overwrites the other, and the index left behind may then send one
            kernel's key to the other's code. With names of their own, a race can
            only lose an index entry: the kernel is compiled again."""

            def save(self, key, data):
                digest = hashlib.sha256(repr(key).encode()).hexdigest()[:32]
                name = f"{self._index_name[:-len('.nbi')]}.{digest}.nbc"
                self._save_data(name, data)         # before the index points at it
                overloads = self._load_index()
                if overloads.get(key) != name:
                    overloads[key] = name
                    self._save_index(overloads)

        class FingerprintCache(FunctionCache):
            def __init__(self, py_func, key):
                super().__init__(py_func)
                self._fingerprint = key
                old = self._cache_file
                self._cache_file = KeyedFiles(old._cache_path,
                                              old._index_name[:-len(".nbi")],
                                              old._source_stamp)

            def _index_key(self, sig, codegen):
                return (sig, codegen.magic_tuple(), ("swarmdsl", KEY_VERSION, self._fingerprint))

            def save_overload(self, sig, data):
                with warnings.catch_warnings():    # "cannot cache": compiled in memory
                    warnings.simplefilter("ignore")
                    super().save_overload(sig, data)

        FingerprintCache.files = KeyedFiles
        _CLASS = FingerprintCache
    return _CLASS
