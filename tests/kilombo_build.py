"""Kilombo (the C Kilobot simulator, MIT) built headless for the export tests: from
`SWARMDSL_KILOMBO` when it names an installed prefix, otherwise by the documented
`make kilombo-local` (the repository's Makefile) from the copy of its headless sources in
`third_party/kilombo`, once per test process. The build needs only a C compiler, make
and the jansson headers (Debian `libjansson-dev`), not CMake or SDL."""

from __future__ import annotations

import atexit
import functools
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _compiler_has_jansson(cc: str) -> bool:
    probe = subprocess.run([cc, "-E", "-x", "c", "-"], input="#include <jansson.h>\n",
                           capture_output=True, text=True)
    return probe.returncode == 0


@functools.cache
def missing() -> str | None:
    """Why Kilombo cannot be had here, or None when it can (nothing is built yet)."""
    if os.environ.get("SWARMDSL_KILOMBO"):
        return None
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        return "no C compiler for the host"
    if not shutil.which("make"):
        return "no make"
    if not _compiler_has_jansson(cc):
        return "the jansson headers are missing (Debian: libjansson-dev)"
    return None


@functools.cache
def prefix() -> str:
    """The prefix Kilombo is installed into (`include/kilombo.h`, `lib/libheadless.a`),
    building it from `third_party/kilombo` the first time it is asked for."""
    given = os.environ.get("SWARMDSL_KILOMBO")
    if given:
        return given
    root = Path(tempfile.mkdtemp(prefix="kilombo-"))
    atexit.register(shutil.rmtree, root, True)
    subprocess.run(["make", "-s", "-C", str(REPO), "kilombo-local", f"KILOMBO_PREFIX={root}"],
                   check=True, capture_output=True)
    return str(root)
