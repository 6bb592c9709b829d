"""The language's type names, and how messages spell them."""

from __future__ import annotations

NUM, BOOL, VEC, STR = "num", "bool", "vec", "str"
SET, STATUS, KIND, FIELD, REGION, MEMORY, OTHER = (
    "set", "status", "kind", "field", "region", "memory", "other")
VALUE_TYPES = (NUM, BOOL, VEC)

TYPE_TEXT = {
    NUM: "a number", BOOL: "a boolean", VEC: "a vector", STR: "a string",
    SET: "a neighbour set", STATUS: "a status", KIND: "an agent kind", FIELD: "a field",
    REGION: "a region", MEMORY: "a path memory", OTHER: "`other`",
}
