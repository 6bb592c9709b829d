"""The errors every layer shares live in `swarmdsl/errors.py` (below the runtime and the
compiler alike); this name stays for code written against the compiler's."""

from swarmdsl.errors import (  # noqa: F401
    Span,
    SwarmCheckError,
    SwarmError,
    SwarmOptionError,
    SwarmRuntimeError,
    SwarmSyntaxError,
    article,
    cell_count,
    cell_width,
    close_match,
    did_you_mean,
    lone_cr_as_newline,
    source_lines,
)
