"""swarmdsl: a declarative language and vectorised runtime for swarm-robot behaviour."""

from swarmdsl.compiler.errors import SwarmError

__version__ = "0.1.0"

__all__ = ["SwarmError", "__version__", "load_program"]


def load_program(path, overrides=None):
    """Parse, check and compile the `.swarm` file at `path` into a Program."""
    from swarmdsl.compiler import compile_file

    return compile_file(path, overrides or {})
