"""`swarmdsl studio FILE`: the program and its swarm side by side in the browser.

Registering the command imports nothing of the server: starlette and uvicorn (the
`studio` extra) load only when the command runs.
"""

from __future__ import annotations

import sys

from swarmdsl.command_args import parse_sets, path_arg
from swarmdsl.runtime import backends

TOKEN_VARIABLE = "SWARMDSL_STUDIO_TOKEN"     # a fixed token, for scripts and tests
DEFAULT_PORT = 8765
_INSTALL = "pip install 'swarmdsl[studio]'"


def register(sub) -> None:
    p = sub.add_parser("studio", help="edit and watch a program in the browser",
                       description="Serve FILE's editor, swarm view, sliders and plots on "
                       "a local web page, and open it in the browser.")
    p.add_argument("file", type=path_arg("file", "a .swarm program file", text=True),
                   help="the .swarm program (the only file the page can save)")
    p.add_argument("--port", type=int, default=None,
                   help=f"port to listen on (default {DEFAULT_PORT}, or a free one when "
                   "that is taken; 0: a free one)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--no-browser", action="store_true",
                   help="print the page's address instead of opening a browser")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a param; repeatable")
    p.add_argument("--out", type=path_arg("--out", "a folder name, e.g. runs"),
                   metavar="DIR", help="where exports go (default: FILE's folder/"
                   "NAME-studio)")
    p.add_argument("--backend", choices=backends.names(), default=None,
                   help="the simulation's backend (as `run --backend`)")
    p.set_defaults(func=cmd_studio)


def cmd_studio(args) -> int:
    import os
    from pathlib import Path

    from swarmdsl.cli import check_run_ranges
    from swarmdsl.errors import SwarmOptionError

    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError as exc:
        raise SwarmOptionError(f"swarmdsl studio needs {exc.name}: {_INSTALL}") from None
    from swarmdsl.studio.server import Studio, new_token, serve
    from swarmdsl.studio.session import Session

    path = Path(args.file)
    if not path.is_file():
        raise SwarmOptionError(f"no such program file: {args.file}")
    check_run_ranges(args.seed, None, None)
    if args.port is not None and not 0 <= args.port <= 65535:
        raise SwarmOptionError(f"--port {args.port}: must be from 0 to 65535")
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(f"warning: --host {args.host}: the studio is reachable from other machines; "
              "anyone with its URL (and token) can edit and save "
              f"{path.name}", file=sys.stderr)
    session = Session(path, parse_sets(args.set), seed=args.seed, out=args.out,
                      backend=args.backend)
    for d in session.errors:      # it still serves: the page shows them at their lines
        print(d["text"], file=sys.stderr)
    token = os.environ.get(TOKEN_VARIABLE) or new_token()
    sock = _listen(args.host, args.port)
    port = sock.getsockname()[1]
    shown = f"[{args.host}]" if ":" in args.host else args.host
    url = f"http://{shown}:{port}/?token={token}"
    print(f"swarmdsl studio: {path.name} at {url}", flush=True)
    print("press Ctrl-C to stop", file=sys.stderr, flush=True)
    if not args.no_browser:
        import webbrowser

        webbrowser.open(url)
    serve(Studio(session, token), sock)
    return 0


def _listen(host: str, port: int | None):
    from swarmdsl.errors import SwarmOptionError
    from swarmdsl.studio.server import bind

    try:
        return bind(host, DEFAULT_PORT if port is None else port)
    except OSError as exc:
        if port is None:
            try:
                return bind(host, 0)
            except OSError:
                pass
        where = f"--port {port}" if port is not None else f"--host {host}"
        raise SwarmOptionError(f"{where}: cannot listen on {host}:"
                               f"{DEFAULT_PORT if port is None else port} "
                               f"({exc.strerror or exc})") from None
