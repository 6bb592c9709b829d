"""Output paths checked before any work, and files put in place whole.

An `--out` under a file, a `--record` onto a folder name, or a folder the user cannot
write must fail at once with the option named (exit 2), not with a traceback after an
hour of ticks. Checking creates nothing: the first existing folder on the path is
probed by creating and removing a hidden file in it, which is the only test that
agrees with the file system (permissions, read-only mounts, ACLs, running as root).

Files are written under a hidden temporary name in their own folder and renamed over
the target (`replace_with`), so a reader, or a run killed at any moment, sees either
the old file or the new one, never half of one.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

from swarmdsl import stopping
from swarmdsl.errors import SwarmOptionError


def _existing_ancestor(path: Path, option: str, shown: Path) -> Path:
    for parent in (path, *path.parents):
        if parent.exists() or parent.is_symlink():
            if not parent.is_dir():
                where = "is" if parent == shown else f"is under {parent}, which is"
                raise SwarmOptionError(f"{option} {shown}: {where} a file, not a folder")
            return parent
    return Path(".")


def _probe(folder: Path, option: str, shown: Path) -> None:
    try:
        with stopping.uncut():      # a stop between creating and removing it left it
            fd, name = tempfile.mkstemp(prefix=".swarmdsl-probe-", dir=folder)
            os.close(fd)
            os.unlink(name)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise SwarmOptionError(f"{option} {shown}: cannot write in {folder} "
                               f"({reason.lower()})") from None


def check_folder(path, option: str) -> Path:
    """`path` is, or can be made, a writable folder; nothing is created."""
    path = Path(path)
    _probe(_existing_ancestor(path, option, path), option, path)
    return path


def make_folder(path, option: str) -> Path:
    """Check `path` as `check_folder` does, then create it (with its parents)."""
    path = check_folder(path, option)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SwarmOptionError(f"{option} {path}: cannot create the folder "
                               f"({(exc.strerror or type(exc).__name__).lower()})") from None
    return path


def check_file(path, option: str, example: str = "out.png") -> Path:
    """`path` can be written as a file: not a folder, its folder writable or creatable."""
    path = Path(path)
    if path.is_dir():
        raise SwarmOptionError(f"{option} {path}: is a folder; give a file name, e.g. "
                               f"{path / example}")
    if path.exists() and not path.is_file():
        raise SwarmOptionError(f"{option} {path}: exists and is not a regular file")
    _probe(_existing_ancestor(path.parent, option, path), option, path)
    return path


def temporary_name(path: Path) -> Path:
    """A hidden name beside `path`; readers of a folder skip names starting with '.'."""
    return path.with_name(f".{path.name}.partial")


def replace_with(path, write: Callable[[Path], None]) -> Path:
    """Call `write(tmp)` for a temporary file beside `path`, then rename it over `path`."""
    replace_together([(path, write)])
    return Path(path)


def replace_together(files: list[tuple[Path, Callable[[Path], None]]]) -> None:
    """`replace_with` for files that belong together (a model's weights and sidecar):
    every one is written under its temporary name before any is renamed, so a failure
    or a stop while writing leaves all the old files (or none), never a new file beside
    an old one it does not match."""
    pairs = [(Path(path), temporary_name(Path(path)), write) for path, write in files]
    try:
        for _path, tmp, write in pairs:
            write(tmp)
        for path, tmp, _write in pairs:
            os.replace(tmp, path)
    finally:
        for _path, tmp, _write in pairs:
            if tmp.exists() or tmp.is_symlink():
                tmp.unlink()
