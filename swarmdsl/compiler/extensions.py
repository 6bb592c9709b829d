"""Imports the modules that extend the core language (each registers its names, calls,
actions and options in the tables of checker, codegen and runtime)."""

from swarmdsl.compiler import lang_nn  # noqa: F401  nn("models/x.pt", ...)
from swarmdsl.compiler import lang_properties  # noqa: F401  invariant, eventually
from swarmdsl.compiler import lang_fields, lang_memory  # noqa: F401  fields, regions, memory
from swarmdsl.compiler import lang_beliefs, lang_messaging, lang_robots  # noqa: F401,I001  robots
