"""The checker's and codegen's view of the built-ins: the function rows (`ops/functions.py`,
one row per function with all its evaluators), the aggregates and the named constants.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from swarmdsl.compiler import aggregate_forms as forms
from swarmdsl.ops.functions import FUNCTIONS, Builtin, vec_length
from swarmdsl.ops.targets import Refused
from swarmdsl.ops.types import (
    BOOL,
    FIELD,
    KIND,
    MEMORY,
    NUM,
    OTHER,
    REGION,
    SET,
    STATUS,
    STR,
    TYPE_TEXT,
    VALUE_TYPES,
    VEC,
)

__all__ = ["AGGREGATES", "Aggregate", "AggregateC", "BOOL", "CALLS", "CONSTANTS", "CallRow",
           "FIELD", "FUNCTIONS", "KIND", "MEMORY", "NUM", "OTHER", "REGION", "SET", "STATUS",
           "STR", "TYPE_TEXT", "VALUE_TYPES", "VEC", "Builtin", "Refused", "declare_calls",
           "vec_length"]

class AggregateC(NamedTuple):
    """An aggregate's exported C (`export/kilobot_c.py` loops over the table of heard
    neighbours and fills these in): `step` adds one neighbour's EACH to the accumulator
    `{acc}` (`{n}` neighbours so far, `{nb}` the table entry), `result` the value after
    the loop (`{default}` the `else`); `step_vec`, `result_vec` the same for a vector
    EACH (None: refused); `ctype` the accumulator's C type (None: no accumulator),
    `start` its first value, `setup` any further declaration."""

    step: str
    result: str
    step_vec: str | None = None
    result_vec: str | None = None
    ctype: str | None = "float"
    start: str = "0"
    setup: str = ""


class Aggregate(NamedTuple):
    """An aggregate over a neighbour set: whether it needs `: EACH`, the types EACH may
    have, its one-line meaning (the language server's hover shows it), its exported C
    (or a `Refused`), whether a batch of replicas runs it (each replica's pairs are
    its own: `runtime/batch.py`), and its array forms (`aggregate_forms.py`): from the
    pairs (`pairs`, the reference), the compiled kernel family that accumulates it
    (`kernel`) and what makes its value of the accumulators (`finish`)."""

    needs_each: bool
    each_types: tuple
    doc: str
    kilobot: AggregateC | Refused | None = None
    batch: bool | Refused = True
    pairs: Callable | None = None
    kernel: str = "sum"
    finish: Callable | None = None
    result: str | None = None     # its type: None, EACH's (a fixed type otherwise)
    takes_else: bool = False      # `else` gives the value of no neighbours


# name -> (from the pairs, kernel family, from the accumulators, type, takes `else`)
_FORMS = {
    "count": (forms.count_pairs, "sum", forms.count_finish, NUM, False),
    "sum": (forms.sum_pairs, "sum", forms.sum_finish, None, False),
    "mean": (forms.mean_pairs, "sum", forms.mean_finish, None, True),
    "min": (forms.min_pairs, "min", forms.extreme_finish, None, True),
    "max": (forms.max_pairs, "max", forms.extreme_finish, None, True),
    "nearest": (forms.nearest_pairs, "nearest", forms.nearest_finish, None, True),
    "any": (forms.any_pairs, "sum", forms.any_finish, BOOL, False),
    "all": (forms.all_pairs, "sum", forms.all_finish, BOOL, False),
}
_SUM_C = AggregateC("{acc} += {each};", "{acc}", "{acc} = kb_vadd({acc}, {each});", "{acc}")
_MIN_C = "{{ float e = {each}; if (!{n} || e {less} {acc}) {acc} = e; }}"

_AGGREGATES = {
    "count": Aggregate(False, (), "the number of neighbours in the set (0 when none)",
                       AggregateC("", "(float){n}", ctype=None)),
    "sum": Aggregate(True, (NUM, VEC), "the sum of EACH over the set (0, or (0, 0) for a "
                     "vector, when none)", _SUM_C),
    "mean": Aggregate(True, (NUM, VEC), "the mean of EACH over the set (the `else`, or 0, "
                      "when none)", _SUM_C._replace(
                          result="({n} ? {acc} / {n} : {default})",
                          result_vec="({n} ? kb_vdiv({acc}, {n}) : {default})")),
    "min": Aggregate(True, (NUM,), "the smallest EACH over the set (the `else`, or 0, "
                     "when none)", AggregateC(_MIN_C.replace("{less}", "<"),
                                              "({n} ? {acc} : {default})")),
    "max": Aggregate(True, (NUM,), "the largest EACH over the set (the `else`, or 0, "
                     "when none)", AggregateC(_MIN_C.replace("{less}", ">"),
                                              "({n} ? {acc} : {default})")),
    "nearest": Aggregate(True, (NUM, VEC, BOOL, STATUS),
                         "EACH for the nearest neighbour (the `else`, or 0, when none)",
                         AggregateC("if (!{n} || {nb}->dist < best{acc}) "
                                    "{{ best{acc} = {nb}->dist; {acc} = {each}; }}",
                                    "({n} ? {acc} : {default})",
                                    "if (!{n} || {nb}->dist < best{acc}) "
                                    "{{ best{acc} = {nb}->dist; {acc} = {each}; }}",
                                    "({n} ? {acc} : {default})",
                                    setup=" uint8_t best{acc} = 255;")),
    "any": Aggregate(True, (BOOL,), "whether some neighbour satisfies EACH (false when "
                     "none)", AggregateC("{acc} = {acc} || ({each});", "{acc}",
                                         ctype="uint8_t")),
    "all": Aggregate(True, (BOOL,), "whether every neighbour satisfies EACH (true when "
                     "none)", AggregateC("{acc} = {acc} && ({each});", "{acc}",
                                         ctype="uint8_t", start="1")),
}
# each row's array forms (aggregate_forms.py) and the kernel family accumulating it
AGGREGATES = {name: row._replace(pairs=pairs, kernel=kernel, finish=finish, result=result,
                                 takes_else=takes_else)
              for name, row in _AGGREGATES.items()
              for pairs, kernel, finish, result, takes_else in [_FORMS[name]]}

CONSTANTS = {"pi": float(np.pi), "tau": float(2 * np.pi), "inf": float("inf")}


@dataclass(frozen=True)
class CallRow:
    """A call a language extension adds beside the rows above (its type rule in
    `typing_rules.CALL_RULES`, its closure in `codegen.CALL_CODEGEN`, both registered
    by its module, which declares this row next to them with `declare_calls`): what the
    targets beyond the reference closure do with it.

    `batch`: whether R replicas in one store run it bit-identical to their solo runs
    (`compiler/batching.py`), or a `Refused`. `kilobot`: True when the exporter writes
    its C (`export/kilobot_c.py`, by the call's resolution: `heard`, `trilaterate`,
    `nn`), else a `Refused` saying why a Kilobot cannot run it (the located error's
    hint)."""

    name: str
    batch: bool | Refused
    kilobot: bool | Refused


CALLS: dict[str, CallRow] = {}


def declare_calls(names, *, batch: bool | Refused, kilobot: bool | Refused) -> None:
    """Declare the extension calls `names` with the same targets' forms."""
    for name in names:
        CALLS[name] = CallRow(name, batch, kilobot)


# The neighbour sets every aggregate reads: the pair table, replica by replica in a batch;
# a Kilobot hears its neighbours instead (`heard()`).
declare_calls(("neighbors", "neighbours"), batch=True, kilobot=Refused(
    "a Kilobot knows its neighbours through their messages: aggregate over `heard()`"))
