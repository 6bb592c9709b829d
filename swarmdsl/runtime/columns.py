"""The columns of `agents.parquet` the recorder writes whatever the program: its fixed
columns and how a vector is split. Apart from `record.py` so that checking a program
(`compiler/columns.py` refuses a variable that would take one of these names) imports
none of the recorder."""

from __future__ import annotations

# The columns every row of `agents.parquet` starts with, before the program's variables:
# name -> (Arrow type, what it holds). The checker refuses a variable of the same name
# (`compiler/columns.taken`): two columns of one name make the file unreadable.
FIXED_COLUMNS = {
    "tick": ("int64", "the tick"),
    "id": ("int64", "the agent's id"),
    "kind": ("string", "the agent's kind"),
    "status": ("string", "the agent's status"),
    "x": ("float64", "the agent's x position"),
    "y": ("float64", "the agent's y position"),
    "heading": ("float64", "the agent's heading"),
    "vx": ("float64", "the agent's x velocity"),
    "vy": ("float64", "the agent's y velocity"),
}


def vector_columns(name: str) -> tuple[str, str]:
    """The two columns a vector variable is recorded in (Parquet has no pair type)."""
    return f"{name}_x", f"{name}_y"


LEAF_RECORDED = "tree_leaf"  # the columns of agents.parquet `--tree-leaf` adds
RESULT_RECORDED = "tree_result"
