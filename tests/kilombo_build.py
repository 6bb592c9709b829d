"""Kilombo (the C Kilobot simulator, MIT) built headless for the export tests: from
`SWARMDSL_KILOMBO` when it names an installed prefix, otherwise from the copy of its
headless sources in `third_party/kilombo`, compiled once per test process. The build needs
only a C compiler and the jansson headers (Debian `libjansson-dev`), not CMake or SDL."""

from __future__ import annotations

import atexit
import functools
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

SOURCE = Path(__file__).resolve().parent.parent / "third_party" / "kilombo"
UNITS = ("skilobot", "kbapi", "params", "stateio", "runsim", "neighbors", "distribution")
HEADERS = ("kilolib.h", "message.h", "message_crc.h", "params.h", "skilobot.h")


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
    (root / "include" / "kilombo").mkdir(parents=True)
    (root / "lib").mkdir()
    shutil.copy(SOURCE / "kilombo.h", root / "include")
    for name in HEADERS:
        shutil.copy(SOURCE / name, root / "include" / "kilombo")
    cc = shutil.which("cc") or shutil.which("gcc")
    objects = []
    for unit in UNITS:
        obj = root / f"{unit}.o"
        subprocess.run([cc, "-std=c99", "-fcommon", "-O2", "-DSKILO_HEADLESS", "-w", "-c",
                        str(SOURCE / f"{unit}.c"), "-o", str(obj)], check=True)
        objects.append(str(obj))
    subprocess.run(["ar", "rcs", str(root / "lib" / "libheadless.a"), *objects], check=True)
    return str(root)
