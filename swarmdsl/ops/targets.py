"""The targets a construct's row answers for, and a row's declared refusal of one.

Every row of the language's tables (`ops/functions.py`, `ops/operators.py`, the
aggregates, actions and extension calls in `compiler/`, the tree nodes in
`runtime/trees.py`) carries a form for each target, or a `Refused` saying why it
has none. A refusal is data, not an absence: the target turns it into a located error
where the construct is used (`file:line:col: error: ... cannot run on a Kilobot`), and
the completeness tests (`tests/test_rows_complete.py`) fail on a row that has neither,
so a new construct cannot silently miss a target.

- numpy: the reference closures; every row has one (it is the language's meaning).
- numba: the kernels' scalar trees; a row without one keeps the reference closure
  (a fallback `-v` names, never a different answer).
- batch: R replicas in one store (`runtime/batch.py`), each bit-identical to its solo
  run; a row that cannot be laid out per replica is refused before the batch starts and
  the run goes solo.
- kilobot: the exported C (`export/kilobot_c.py`).
"""

from __future__ import annotations

from dataclasses import dataclass

TARGETS = ("numpy", "numba", "batch", "kilobot")


@dataclass(frozen=True)
class Refused:
    """A target the row has no form on, and why, in the user's words (shown as the
    located error's hint)."""

    why: str


def refusal(form) -> Refused | None:
    """The row's refusal when `form` is one, else None (a form, or True for "runs")."""
    return form if isinstance(form, Refused) else None
