"""Containment for every file a program or a training spec names.

A `.swarm` file or a training spec may come from someone else, so the files it names
(model weights, their JSON sidecars, a spec's `out`) must stay at or under its own
folder: no absolute paths, no `..`, no symlink that leads out. A file read must be a
regular file (a FIFO would hang the reader, `/dev/zero` would fill memory) and small
enough. Refusals name the path and the rule, never the file's content.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path, PurePosixPath, PureWindowsPath

from swarmdsl.errors import SwarmError

MAX_PROGRAM_BYTES = 10 * 2**20      # a `.swarm` file; generated ones stay far below
MAX_SIDECAR_BYTES = 1 * 2**20       # a sidecar is a few kilobytes of JSON
MAX_SPEC_BYTES = 1 * 2**20          # a training spec likewise
MAX_WEIGHTS_BYTES = 1 * 2**30       # the weights of a small network, with room to spare


class ContainmentError(SwarmError):
    """A named file outside its folder, not a regular file, or too large."""

    phase = "file"


def contained_path(spec: str, base: Path, what: str) -> Path:
    """Resolve `spec` (relative, `/` separators) at or under `base`, or refuse it.

    The file need not exist yet (a training spec's `out`); symlinks along the way are
    followed and must stay under `base`.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise ContainmentError(f"{what} is empty; write a path relative to its folder")
    if "\0" in spec:
        raise ContainmentError(f"{what} contains a NUL character")
    if (PurePosixPath(spec).is_absolute() or PureWindowsPath(spec).is_absolute()
            or PureWindowsPath(spec).drive or spec.startswith(("/", "\\", "~"))):
        raise ContainmentError(f"{what} '{_short(spec)}' is absolute; write it relative to "
                               "its folder, e.g. \"models/x.pt\"")
    parts = PureWindowsPath(spec).parts  # splits on both '/' and '\'
    if ".." in parts:
        raise ContainmentError(f"{what} '{_short(spec)}' contains '..'; it must stay at or "
                               "under its folder")
    root = Path(base).resolve()
    resolved = root.joinpath(*parts).resolve()
    if not resolved.is_relative_to(root):
        raise ContainmentError(f"{what} '{_short(spec)}' leads outside its folder through a "
                               "symlink; copy the file under the folder instead")
    return resolved


def check_inside(path: Path, base: Path, what: str, name: str | None = None) -> Path:
    """`path` with symlinks resolved, refused unless it lies at or under `base`."""
    resolved = Path(path).resolve()
    if not resolved.is_relative_to(Path(base).resolve()):
        raise ContainmentError(f"{what} '{_label(path, name)}' leads outside the program's "
                               "folder through a symlink; copy the file under the folder")
    return resolved


def read_regular(path: Path, what: str, max_bytes: int, name: str | None = None) -> bytes:
    """Read a regular file of at most `max_bytes`, never blocking on a FIFO or device.
    A refusal names the file as `name`, else `path` as passed (see `_label`)."""
    label = _label(path, name)
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise ContainmentError(f"{what} '{label}' not found") from None
    except OSError as exc:
        raise ContainmentError(f"cannot read {what} '{label}': {exc.strerror}") from None
    with os.fdopen(fd, "rb") as fh:
        _refuse_irregular(os.fstat(fh.fileno()), what, label, max_bytes)
        data = fh.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise ContainmentError(f"{what} '{label}' grew past {max_bytes:,} bytes")
    return data


def read_json(path: Path, what: str, max_bytes: int, error: type[SwarmError],
              name: str | None = None):
    """The JSON value of a regular file of at most `max_bytes` (read as `read_regular`
    does). Every refusal is an `error` naming the file as `what 'name'` (`path` as
    passed unless given) and the rule it broke, never its content."""
    label = _label(path, name)
    try:
        text = read_regular(path, what, max_bytes, label).decode("utf-8")
    except ContainmentError as exc:
        raise error(exc.message) from None
    except UnicodeDecodeError:
        raise error(f"{what} '{label}' is not UTF-8 text") from None
    try:
        return json.loads(text)
    except RecursionError:
        raise error(f"{what} '{label}' nests too deeply") from None
    except json.JSONDecodeError as exc:
        raise error(f"{what} '{label}' is not valid JSON (line {exc.lineno}: {exc.msg})"
                    ) from None


def check_regular(path: Path, what: str, max_bytes: int, name: str | None = None) -> None:
    """Refuse anything but a regular file of at most `max_bytes` (before a reader opens it)."""
    try:
        info = os.stat(path)
    except OSError as exc:
        raise ContainmentError(f"cannot read {what} '{_label(path, name)}': "
                               f"{exc.strerror}") from None
    _refuse_irregular(info, what, _label(path, name), max_bytes)


def _refuse_irregular(info: os.stat_result, what: str, name: str, max_bytes: int) -> None:
    if not stat.S_ISREG(info.st_mode):
        raise ContainmentError(f"{what} '{name}' is not a regular file")
    if info.st_size > max_bytes:
        raise ContainmentError(f"{what} '{name}' is {info.st_size:,} bytes; at most "
                               f"{max_bytes:,} are read")


def _label(path, name: str | None) -> str:
    """How a refusal names a file: as its user wrote it (`name`), else as the caller
    passed it. Not its base name: `swarmdsl run /dev/null` said 'null', which names no
    file the user can find; a caller holding only a resolved path passes a `name`
    rather than show a path the user never wrote."""
    return str(path) if name is None else name


def _short(text: str, n: int = 80) -> str:
    return text if len(text) <= n else text[:n] + "..."
