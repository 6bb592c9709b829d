"""The value types an agent's column holds, by the names the language gives them: a
number (float64), a boolean, a vector (two float64). The runtime stores, places and
records agents by these; the compiler's type table (`compiler/builtins.py`) takes its
value types from here."""

NUM, BOOL, VEC = "num", "bool", "vec"
