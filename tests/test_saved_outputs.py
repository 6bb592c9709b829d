"""Every shipped program and every example in the language reference records, on each
backend, exactly the outputs saved in `tests/data/saved_outputs.json`: the rows of
`agents.parquet`, `metrics.parquet` and the arrays of `fields.npz`, bit for bit.

A change to how the code is laid out (a new home for a construct, another walker, a
driver) must not change a run. A change that means to change runs (a new random stream,
a fixed bug) rewrites the file on purpose and says so in the CHANGELOG:

    SWARMDSL_SAVE_OUTPUTS=1 python -m pytest tests/test_saved_outputs.py -k numpy

Digests are of the values, not the files: Parquet's footer names the writer's version.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import swarmdsl
from swarmdsl.compiler import compile_source
from swarmdsl.runtime.runner import Run

ROOT = Path(__file__).resolve().parent.parent
SAVED = Path(__file__).parent / "data" / "saved_outputs.json"
TICKS = 20
SAVING = os.environ.get("SWARMDSL_SAVE_OUTPUTS") == "1"


def _programs():
    for path in sorted((ROOT / "programs").rglob("*.swarm")):
        yield pytest.param("program", path, id=str(path.relative_to(ROOT / "programs")))
    for path in sorted((ROOT / "docs").glob("language*.md")):
        blocks = re.findall(r"```swarm\n(.*?)```", path.read_text(), re.S)
        for i in range(len(blocks)):
            yield pytest.param("example", (path, i), id=f"{path.stem}-{i}")


def _hash_column(h, column: pa.ChunkedArray) -> None:
    array = column.combine_chunks()
    while pa.types.is_list(array.type) or pa.types.is_fixed_size_list(array.type):
        h.update(np.asarray(array.value_lengths()).tobytes())
        array = array.flatten()
    if pa.types.is_string(array.type) or pa.types.is_dictionary(array.type):
        h.update("\0".join(map(str, array.to_pylist())).encode())
    else:
        h.update(np.asarray(array.to_numpy(zero_copy_only=False)).tobytes())


def _digest(out: Path) -> dict[str, str]:
    found = {}
    for name in ("agents.parquet", "metrics.parquet"):
        if (out / name).exists():
            table = pq.read_table(out / name)
            h = hashlib.sha256(",".join(table.column_names).encode())
            for column in table.columns:
                _hash_column(h, column)
            found[name] = f"{table.num_rows} rows {h.hexdigest()[:32]}"
    if (out / "fields.npz").exists():
        h = hashlib.sha256()
        with np.load(out / "fields.npz") as fields:
            for key in sorted(fields.files):
                h.update(key.encode() + fields[key].dtype.str.encode())
                h.update(np.ascontiguousarray(fields[key]).tobytes())
        found["fields.npz"] = h.hexdigest()[:32]
    return found


def _load(kind, where):
    if kind == "program":
        return swarmdsl.load_program(where)
    path, i = where
    source = re.findall(r"```swarm\n(.*?)```", path.read_text(), re.S)[i]
    return compile_source(source, f"{path.name}-example.swarm", program_dir=ROOT / "programs")


@pytest.mark.parametrize("kind, where", list(_programs()))
def test_a_run_records_the_saved_outputs(backend, kind, where, tmp_path, request):
    name = request.node.callspec.id.split("-", 1)[1]
    run = Run(_load(kind, where), seed=5, steps=TICKS, out=tmp_path, backend=backend)
    run.show_progress = False
    assert run.execute() == "completed"
    got = _digest(tmp_path)
    saved = json.loads(SAVED.read_text()) if SAVED.exists() else {}
    if SAVING:
        saved[name] = got
        SAVED.write_text(json.dumps(saved, indent=1, sort_keys=True) + "\n")
        return
    assert name in saved, f"no saved outputs for {name}: save them (module docstring)"
    assert got == saved[name]
