"""The exported C's operators and functions against the language's rows
(`swarmdsl/ops/`) on the edge values the backends are checked with
(`tests/test_ops_rows.py`: negatives, zeros of both signs, NaN, infinities, huge, tiny).

A Kilobot computes in 32-bit floats, so the reference is the row's numpy evaluator on
the edge values as a float holds them (1e308 becomes inf, 5e-324 becomes 0), rounded
to a float: the C must give it to a float's precision, the same infinity, or NaN
where the language gives NaN (`7 % inf` is 7, `min(NaN, 1)` NaN, as every evaluator
of the language gives). Run on the host's compiler, against the same C the robot
builds (`-DKILOLIB_API`); zeros' signs are not compared (a Kilobot program cannot
tell them apart but by dividing by them).

The C of each case is the row's own `kilobot` form, the one the exporter writes: every
row of `ops/` is here unless it declares a refusal, so a new row's C is checked the
moment it is written (and a row with neither fails `tests/test_rows_complete.py`)."""

from __future__ import annotations

import shutil
import subprocess
from types import SimpleNamespace

import numpy as np
import pytest

from swarmdsl.export.kilobot_csrc import preamble
from swarmdsl.export.kilolib_api import HEADER
from swarmdsl.ops.functions import FUNCTIONS
from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS, NEGATE
from swarmdsl.ops.targets import Refused
from swarmdsl.ops.types import NUM, VEC
from tests.test_ops_rows import _arrays, _grid

_CC = shutil.which("gcc") or shutil.which("cc")
pytestmark = pytest.mark.skipif(not _CC, reason="no C compiler for the host")

def _call_c(template: str, params: tuple, result: str) -> str:
    """A statement setting out[0] (and out[1] for a vector) from in[...], through a
    row's C `template` of its operands' C."""
    args, k = [], 0
    for t in params:
        if t == VEC:
            args.append(f"kb_v(in[{k}], in[{k + 1}])")
            k += 2
        else:
            args.append(f"in[{k}]")
            k += 1
    expr = template.format(*args)
    if result == VEC:
        return f"{{ kb_vec_t r = {expr}; out[0] = r.x; out[1] = r.y; }}"
    return f"out[0] = (float)({expr}); out[1] = 0.0f;"


def _vec_numpy(op):
    """numpy of an operator on (M,) and (M, 2) operands, as the closures broadcast."""
    def run(n, *args, types):
        shaped = [a if t == VEC else np.asarray(a)[:, None] for a, t in zip(args, types,
                                                                              strict=True)]
        return op.numpy(*shaped)
    return run


def _rows():
    """(case, C template, params, result, numpy of the argument arrays) of every row the
    export translates: operators (numbers and vectors), comparisons, negation, and every
    function with a C form but the draws (their values are the robot's own stream)."""
    out = []
    for op in (*ARITHMETIC.values(), *COMPARISONS.values()):
        out.append((op.node, op.kilobot, (NUM, NUM), NUM,
                    lambda n, a, b, op=op: op.numpy(a, b)))
        for types, form in op.kilobot_vec.items():
            out.append((f"{op.node}_{'_'.join(types)}", form, types, op.types[types],
                        lambda n, *a, op=op, t=types: _vec_numpy(op)(n, *a, types=t)))
    out.append(("neg", NEGATE.kilobot, (NUM,), NUM, lambda n, a: NEGATE.numpy(a)))
    out.append(("neg_vec", NEGATE.kilobot_vec[(VEC,)], (VEC,), VEC,
                lambda n, a: NEGATE.numpy(a)))
    for name, row in FUNCTIONS.items():
        if row.random or isinstance(row.kilobot, Refused):
            continue
        template = row.kilobot if "{" in row.kilobot else \
            f"{row.kilobot}({', '.join(f'{{{i}}}' for i in range(len(row.params)))})"
        out.append((name, template, row.params, row.result,
                    lambda n, *a, row=row: row.numpy(SimpleNamespace(n=n), *a)))
    return out


ROWS = _rows()


@pytest.fixture(scope="module")
def evaluator(tmp_path_factory):
    """A host program of the exported preamble reading rows of floats on stdin and
    writing each row's two output floats, the row named by its first argument."""
    folder = tmp_path_factory.mktemp("ops")
    (folder / "kilolib_api.h").write_text(HEADER)
    cases = "".join(f'    if (!strcmp(f, "{name}")) {{ {_call_c(form, params, result)} }}\n'
                    for name, form, params, result, _ in ROWS)
    (folder / "ops.c").write_text(
        preamble() + "#include <stdio.h>\n#include <stdlib.h>\n#include <string.h>\n"
        "uint8_t rand_soft(void) { return 0; }\nuint8_t rand_hard(void) { return 0; }\n"
        "int main(int argc, char **argv)\n{\n    const char *f = argv[1];\n"
        "    int n = atoi(argv[2]);\n    float in[8], out[2];\n"
        "    while (fread(in, sizeof(float), n, stdin) == (size_t)n) {\n" + cases +
        "        fwrite(out, sizeof(float), 2, stdout);\n    }\n    return 0;\n}\n")
    subprocess.run([_CC, "-std=gnu99", "-O2", "-DKILOLIB_API", "-Wall", "-Werror",
                    "-Wno-unused-function", "-o", str(folder / "ops"), str(folder / "ops.c"),
                    "-lm"], check=True, capture_output=True, cwd=folder)
    return folder / "ops"


# Rows whose result's components are differences of products: a float's precision of
# the arguments' size, not of the (possibly cancelled) result's.
_CANCELLING = {"rotate"}


def _agree(got: np.ndarray, want: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Float results agreeing with the float-rounded reference: both NaN, the same
    infinity, or equal to a float's precision (of `scale`, the row's own size)."""
    nan = np.isnan(want) & np.isnan(got)
    with np.errstate(all="ignore"):
        close = np.abs(got.astype(float) - want) <= 4e-7 * np.maximum(np.abs(want), scale) \
            + 1e-30
    return nan | (got == want) | (np.isfinite(want) & close)


def test_every_row_with_a_c_form_is_cross_checked():
    """No row's C escapes the edge values: every operator, comparison and function row
    with a C form (draws aside) has its case here."""
    names = {r[0] for r in ROWS}
    assert {op.node for op in (*ARITHMETIC.values(), *COMPARISONS.values())} <= names
    assert {n for n, b in FUNCTIONS.items()
            if not b.random and not isinstance(b.kilobot, Refused)} <= names
    assert {"add_vec_vec", "mul_num_vec", "neg_vec"} <= names


@pytest.mark.parametrize(("name", "form", "params", "result", "numpy"), ROWS,
                         ids=[r[0] for r in ROWS])
def test_every_c_function_gives_the_languages_value_on_the_edge_values(
        evaluator, name, form, params, result, numpy):
    width = 2 if result == VEC else 1
    with np.errstate(all="ignore"):
        grid = np.array(_grid(params), dtype=np.float32)      # as a float holds them
        ref = np.asarray(numpy(len(grid), *_arrays(params, grid.astype(float).tolist())),
                         dtype=float).reshape(len(grid), width)
        want = ref.astype(np.float32).astype(float)
    run = subprocess.run([str(evaluator), name, str(grid.shape[1])],
                         input=grid.tobytes(), capture_output=True, check=True)
    got = np.frombuffer(run.stdout, dtype=np.float32).reshape(len(grid), 2)[:, :width]
    assert len(grid) > 20
    with np.errstate(all="ignore"):
        size = np.where(np.isfinite(grid), np.abs(grid), 0).max(axis=1).astype(float)
    scale = size[:, None] if name in _CANCELLING else np.zeros((len(grid), 1))
    bad = ~_agree(got, want, scale)
    rows = np.flatnonzero(bad.any(axis=1))[:5]
    assert rows.size == 0, [(grid[i].tolist(), got[i].tolist(), want[i].tolist())
                            for i in rows]


def test_seven_modulo_infinity_is_seven_on_the_robot(evaluator):
    """The issue's case: C's `a - b * floor(a / b)` gave NaN for `7 % inf`."""
    rows = np.array([[7, np.inf], [-7, np.inf], [7, -np.inf]], dtype=np.float32)
    run = subprocess.run([str(evaluator), "mod", "2"], input=rows.tobytes(),
                         capture_output=True, check=True)
    got = np.frombuffer(run.stdout, dtype=np.float32).reshape(3, 2)[:, 0]
    assert got.tolist() == [7.0, np.inf, -np.inf]
