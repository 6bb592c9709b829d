"""`swarmdsl lsp`: the language server on standard input and output, for editors.

Registering the command imports nothing of the server: pygls and lsprotocol (the `lsp`
extra) load only when it runs.
"""

from __future__ import annotations

_INSTALL = "pip install 'swarmdsl[lsp]'"


def register(sub) -> None:
    p = sub.add_parser("lsp", help="run the language server (for editors)",
                       description="Serve the Language Server Protocol on standard input "
                       "and output: diagnostics, hover, completion, go to definition, "
                       "references, rename, outline, folding, highlighting and "
                       "formatting for .swarm files. Editors start it themselves "
                       "(docs/editors.md).")
    p.add_argument("--stdio", action="store_true",
                   help="talk over standard input and output (the default and only "
                   "transport; accepted because many editors pass it)")
    p.set_defaults(func=cmd_lsp)


def cmd_lsp(args) -> int:
    from swarmdsl.errors import SwarmOptionError

    try:
        import lsprotocol  # noqa: F401
        import pygls  # noqa: F401
    except ImportError as exc:
        raise SwarmOptionError(f"swarmdsl lsp needs {exc.name}: {_INSTALL}") from None
    from swarmdsl.lsp.server import serve_stdio

    serve_stdio()
    return 0
