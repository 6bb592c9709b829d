"""Where the analysed grammar is cached between processes, so start-up skips building it.

Building the LALR tables from `grammar.lark` costs ~150 ms in every process; lark can
save them and load them back in ~10 ms. The cache lives in the user's cache folder
(`$SWARMDSL_CACHE_DIR`, else `$XDG_CACHE_HOME/swarmdsl`, else `~/.cache/swarmdsl`), never
in a shared temporary folder where another user could plant a file. Only swarmdsl writes
it, and nothing from a `.swarm` file reaches it: its content is lark's tables for our own
grammar. Lark checks a digest of the grammar, its options and the lark and Python
versions stored in the file and rebuilds on any mismatch or unreadable file, so a stale or
corrupt cache costs one rebuild, never an error or a message; so does a half-written
file read by a process starting while another writes it (sweep workers). An unwritable
folder means no cache. `SWARMDSL_CACHE_DIR=""` turns the cache off.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path


def cache_dir() -> Path | None:
    """The folder for swarmdsl's caches, or None when caching is turned off."""
    configured = os.environ.get("SWARMDSL_CACHE_DIR")
    if configured is not None:
        return Path(configured) if configured.strip() else None
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg and os.path.isabs(xdg):
        return Path(xdg) / "swarmdsl"
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "swarmdsl" / "cache"
    try:
        return Path.home() / ".cache" / "swarmdsl"
    except RuntimeError:  # no home folder to be found
        return None


def build_cached(build, name: str):
    """`build(cache=...)` with lark's cache in the user's cache folder, if one is usable.

    `build` is a function taking lark's `cache` option (a file path, or False) and
    returning the `Lark` instance; `name` names the cache file.
    """
    from lark import __version__ as lark_version

    folder = cache_dir()
    if folder is None:
        return build(cache=False)
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError:
        return build(cache=False)
    path = folder / f"{name}-lark{lark_version}-py{sys.version_info[0]}{sys.version_info[1]}"
    return build(cache=str(path))  # lark rebuilds (and rewrites) a stale or bad file
