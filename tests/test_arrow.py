"""The recorder's Arrow columns, built from numpy buffers, equal `pyarrow.array`'s, and a
recorded run never imports pandas (which `pyarrow.array` and `to_numpy` would)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from swarmdsl.runtime import arrow

ROOT = Path(__file__).resolve().parents[1]

_NUMBER_TYPES = {"float64": np.float64, "int64": np.int64, "int32": np.int32,
                 "bool_": np.bool_}


@st.composite
def _numbers(draw):
    type_name = draw(st.sampled_from(sorted(_NUMBER_TYPES)))
    n = draw(st.integers(0, 70))      # across a byte's and a word's worth of bits
    values = draw(hnp.arrays(_NUMBER_TYPES[type_name], n))
    valid = draw(st.none() | hnp.arrays(np.bool_, n))
    return type_name, values, valid


@example(("float64", np.array([np.nan, 1.0]), None))
@example(("float64", np.array([np.nan, -0.0]), np.array([True, False])))
@given(_numbers())
def test_number_columns_equal_pyarrow_array(case):
    type_name, values, valid = case
    got = arrow.numbers(values, type_name, valid=valid)
    mask = None if valid is None else ~valid
    want = pa.array(values, type=getattr(pa, type_name)(), mask=mask)
    got.validate(full=True)
    assert got.type == want.type
    assert _same(got.to_pylist(), want.to_pylist())     # `equals` holds NaN unequal
    assert got.null_count == (0 if valid is None else int((~valid).sum()))


def _same(a: list, b: list) -> bool:
    """Equal lists, a NaN equal to a NaN (and None, a null, only to None)."""
    return len(a) == len(b) and all(
        x is y or x == y or (isinstance(x, float) and isinstance(y, float) and x != x and y != y)
        for x, y in zip(a, b, strict=True))


@given(st.lists(st.none() | st.text(max_size=12), min_size=1, max_size=6).flatmap(
    lambda names: st.tuples(st.just(names),
                            st.lists(st.integers(0, len(names) - 1), max_size=60))))
def test_label_columns_equal_pyarrow_array(case):
    names, codes = case
    got = arrow.labels(names, np.array(codes, dtype=np.int64))
    got.validate(full=True)
    assert got.equals(pa.array([names[c] for c in codes], type=pa.string()))


def test_a_label_code_outside_the_names_is_refused():
    with pytest.raises(ValueError, match="outside 0..1"):
        arrow.labels(["a", "b"], np.array([0, 2]))


@given(hnp.arrays(np.float64, st.integers(0, 40)), st.integers(0, 5), st.integers(0, 5))
def test_values_read_back_a_slice_of_chunks(data, cut, chunk):
    column = pa.chunked_array([pa.array(data[:chunk]), pa.array(data[chunk:])]) \
        .slice(min(cut, len(data)))
    got = arrow.values(column, "float64")
    np.testing.assert_array_equal(got, data[min(cut, len(data)):])


def test_values_refuse_a_column_with_nulls():
    with pytest.raises(ValueError, match="1 nulls"):
        arrow.values(pa.array([1.0, None]), "float64")


# A recorded run written in many parts (each part's metrics read back for run.json's
# summary) with a string column per agent (`--tree-leaf`): pandas must stay unimported.
# A program with a tree and a metric and nothing else to compile (its kernels are the
# motion's and the cell list's, which every numba run has).
PROGRAM = """world { size 20 x 20; edges wrap }
agent a {
  count 4
  velocity random_direction()
  var k = 0
  status s {
    tree sequence { wait(2); k = k + uniform(0, 1) }
  }
}
metric mean_k = mean(k)
"""
RUN_PROBE = """
import json, sys
from swarmdsl.cli import main
from swarmdsl.runtime.record import Recorder
Recorder.flush_bytes = 1                     # a part per recorded tick
code = main(["run", sys.argv[1], "--headless", "--steps", "5", "--out", sys.argv[2],
             "--seed", "3", "--tree-leaf"])
print(json.dumps({"code": code, "pandas": "pandas" in sys.modules}))
"""


def test_a_recorded_run_does_not_import_pandas(backend, tmp_path):
    program, out = tmp_path / "tree.swarm", tmp_path / "run"
    program.write_text(PROGRAM)
    done = subprocess.run([sys.executable, "-c", RUN_PROBE, str(program), str(out)],
                          capture_output=True, text=True, cwd=ROOT,
                          env=dict(os.environ, SWARMDSL_CACHE_DIR=str(tmp_path)))
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout.splitlines()[-1])
    assert got == {"code": 0, "pandas": False}
    import pyarrow.parquet as pq

    agents = pq.read_table(out / "agents.parquet")
    assert len(list((out / "agents.parquet").iterdir())) == 6      # ticks 0..5
    assert sorted(set(agents["tick"].to_pylist())) == list(range(6))
    leaves = agents["tree_leaf"].to_pylist()
    assert any(leaf and ":" in leaf for leaf in leaves)
    summary = json.loads((out / "run.json").read_text())["metrics"]
    metrics = pq.read_table(out / "metrics.parquet").to_pandas()
    last = metrics[metrics["tick"] == 5].set_index("name")["value"]
    assert summary["mean_k"]["last"] == pytest.approx(last["mean_k"])
    assert last["mean_k"] > 0
