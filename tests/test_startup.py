"""Start-up: the grammar cache (reused, safe when unwritable or corrupt) and lazy imports.

Each test runs a fresh interpreter: the parser is built once per process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BOIDS = ROOT / "programs" / "boids.swarm"

# Parse and check a program; report whether lark loaded its tables from the cache, the
# AST's statement count, and which heavy modules got imported.
PROBE = f"""
import json, logging, sys
from lark import logger
seen = []
class Catch(logging.Handler):
    def emit(self, record):
        seen.append(record.getMessage())
for handler in logger.handlers:  # lark's own: prints only what a user would see
    handler.setLevel(logging.CRITICAL)
logger.addHandler(Catch())
logger.setLevel(logging.DEBUG)
from swarmdsl.compiler import compile_file
program = compile_file({str(BOIDS)!r})
heavy = sorted(m for m in ("scipy", "torch", "pygame", "numba", "pandas", "matplotlib")
               if m in sys.modules)
failed = any("Failed to load" in m for m in seen)
print(json.dumps({{"loaded": not failed and any("Loading grammar from" in m for m in seen),
                  "saved": any("Saving grammar to cache" in m for m in seen),
                  "kinds": [k.name for k in program.kinds], "heavy": heavy}}))
"""


def _probe(cache_dir) -> dict:
    env = dict(os.environ, SWARMDSL_CACHE_DIR=str(cache_dir))
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                          env=env, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # nothing printed, whatever the cache's state
    return json.loads(done.stdout)


def test_grammar_tables_are_cached_and_reused(tmp_path):
    first = _probe(tmp_path)
    assert (first["loaded"], first["saved"]) == (False, True)
    files = [p.name for p in tmp_path.iterdir()]
    assert len(files) == 1 and files[0].startswith("grammar-")
    second = _probe(tmp_path)
    assert (second["loaded"], second["saved"]) == (True, False)
    assert second["kinds"] == first["kinds"] == ["boid"]


@pytest.mark.parametrize("damage", [b"", b"garbage\n\x00\x01", "truncate"])
def test_a_corrupt_cache_is_rebuilt_silently(tmp_path, damage):
    _probe(tmp_path)
    (cache,) = tmp_path.iterdir()
    good = cache.read_bytes()
    cache.write_bytes(good[: len(good) // 2] if damage == "truncate" else damage)
    got = _probe(tmp_path)
    assert not got["loaded"] and got["kinds"] == ["boid"]
    assert _probe(tmp_path)["loaded"]  # rewritten whole


def test_an_unusable_cache_folder_means_no_cache(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    got = _probe(blocker / "cache")  # cannot be created under a file
    assert got["kinds"] == ["boid"] and not got["loaded"]
    assert blocker.read_text() == "not a folder"


def test_cache_off_with_an_empty_setting(tmp_path):
    got = _probe("")
    assert not got["loaded"] and not got["saved"]


def test_compiling_imports_no_heavy_library(tmp_path):
    """`swarmdsl check` compiles: it must not pay for scipy, torch, pygame or numba."""
    assert _probe(tmp_path)["heavy"] == []


# Runtime modules `swarmdsl check` of a program that uses none of their features must not
# import: the language extensions load them where a program is compiled to use them or
# run. A module-level import of one of these brings back its start-up cost for every
# command (`benchmarks/startup.py`).
DEFERRED = (
    "swarmdsl.analysis.render", "swarmdsl.compiler.tree_outcomes",
    "swarmdsl.analysis.tree_render", "swarmdsl.runtime.choice",
    "swarmdsl.runtime.environment", "swarmdsl.runtime.fields",
    "swarmdsl.runtime.internal_map", "swarmdsl.runtime.jsonsafe", "swarmdsl.runtime.memory",
    "swarmdsl.runtime.messaging", "swarmdsl.runtime.nn", "swarmdsl.runtime.randomness",
    "swarmdsl.runtime.refined_grid", "swarmdsl.runtime.regions", "swarmdsl.runtime.robots",
    "swarmdsl.runtime.sensing", "swarmdsl.runtime.tree_leaves",
    "swarmdsl.runtime.trilateration", "swarmdsl.runtime.twins", "swarmdsl.train.fit",
    "zipfile",
    # The recorder, the numba backend's fused paths and the other commands' modules:
    # `check` never runs the program nor reads those commands' options.
    "swarmdsl.runtime.record", "swarmdsl.runtime.metrics", "swarmdsl.runtime.spool",
    "swarmdsl.runtime.compiled.fused", "swarmdsl.runtime.compiled.siblings",
    "swarmdsl.runtime.compiled.statements", "swarmdsl.train.cli", "swarmdsl.train.data",
    "swarmdsl.sweep.cli", "swarmdsl.testing.cli", "swarmdsl.plot.cli", "swarmdsl.runtime.trees",
    "swarmdsl.studio.cli", "swarmdsl.studio.server", "starlette", "uvicorn",
)

CHECK_PROBE = f"""
import contextlib, io, json, sys
from swarmdsl.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    code = main(["check", {str(BOIDS)!r}])
print(json.dumps({{"code": code, "modules": sorted(sys.modules)}}))
"""


def test_check_imports_no_runtime_it_does_not_use(tmp_path):
    env = dict(os.environ, SWARMDSL_CACHE_DIR=str(tmp_path))
    done = subprocess.run([sys.executable, "-c", CHECK_PROBE], capture_output=True,
                          text=True, env=env, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    assert got["code"] == 0
    assert sorted(set(DEFERRED) & set(got["modules"])) == []
    # The probe sees what the command imported: the language extensions were loaded.
    assert "swarmdsl.compiler.extensions" in got["modules"]
