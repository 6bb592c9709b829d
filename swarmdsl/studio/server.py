"""The studio's web server: one page, a websocket of frames and controls, and three small
endpoints (check, save, export). Starlette on uvicorn, imported only by `swarmdsl studio`.

Safe by default, as Jupyter is: it listens on 127.0.0.1, and every request and
websocket must carry the session's random token (`?token=`), or gets 403. The page
names no path: `save` writes the one file the studio was opened with, `export` writes a
folder it names itself under the outputs folder, the static files are a fixed table.
A program with errors, a run that faults or a bug in a handler answers with a message;
the server goes on.
"""

from __future__ import annotations

import asyncio
import json
import secrets
import socket
from pathlib import Path
from urllib.parse import parse_qs

from swarmdsl.errors import SwarmError
from swarmdsl.files import MAX_PROGRAM_BYTES
from swarmdsl.studio.session import LAYERS, Session

STATIC = Path(__file__).parent / "static"
# name -> media type; only these files are ever read from STATIC
FILES = {"studio.html": "text/html; charset=utf-8",
         "renderer.js": "text/javascript; charset=utf-8",
         "studio.js": "text/javascript; charset=utf-8",
         "studio.css": "text/css; charset=utf-8",
         "page.css": "text/css; charset=utf-8",
         # the editor: CodeMirror on the language server, bundled from editors/studio
         "editor.js": "text/javascript; charset=utf-8",
         "editor.css": "text/css; charset=utf-8"}
IDLE_POLL = 0.05            # seconds between looks at a paused session
IN_FLIGHT = 2               # frames on their way to a page: one drawn, one coming


def new_token() -> str:
    return secrets.token_urlsafe(24)


class TokenGate:
    """ASGI middleware: an HTTP request or websocket without `?token=TOKEN` gets 403."""

    def __init__(self, app, token: str):
        self.app, self.token = app, token

    async def __call__(self, scope, receive, send):
        if scope["type"] in ("http", "websocket"):
            query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
            given = query.get("token", [""])[0]
            if not secrets.compare_digest(given.encode(), self.token.encode()):
                if scope["type"] == "websocket":
                    await send({"type": "websocket.close", "code": 1008})  # handshake: 403
                    return
                await send({"type": "http.response.start", "status": 403,
                            "headers": [(b"content-type", b"text/plain; charset=utf-8")]})
                await send({"type": "http.response.body",
                            "body": b"403: this studio needs the token from its URL\n"})
                return
        await self.app(scope, receive, send)


class Studio:
    """The web app around one `Session`."""

    def __init__(self, session: Session, token: str):
        self.session = session
        self.token = token
        self.driver = 0             # the newest websocket steps the run; others watch
        self._connections = 0
        self._connections_live: dict[int, _Connection] = {}

    # ---- HTTP ----
    def app(self):
        from starlette.applications import Starlette
        from starlette.routing import Route, WebSocketRoute

        routes = [Route("/", self.page), Route("/static/{name}", self.static),
                  Route("/api/check", self.check, methods=["POST"]),
                  Route("/api/save", self.save, methods=["POST"]),
                  Route("/api/export", self.export, methods=["POST"]),
                  WebSocketRoute("/ws", self.websocket),
                  WebSocketRoute("/lsp", self.language_server)]
        return TokenGate(Starlette(routes=routes), self.token)

    async def page(self, request):
        """The page, its scripts' addresses carrying the token (they are requests too)."""
        from urllib.parse import quote

        from starlette.responses import HTMLResponse

        html = (STATIC / "studio.html").read_text(encoding="utf-8")
        html = html.replace("__FILE_URI__", self.session.file.as_uri())
        return HTMLResponse(html.replace("__TOKEN__", quote(self.token, safe="")),
                            headers={"cache-control": "no-store"})

    async def static(self, request):
        return self._file(request.path_params["name"])

    def _file(self, name: str):
        from starlette.responses import Response

        if name not in FILES:
            return Response("not found\n", status_code=404, media_type="text/plain")
        return Response((STATIC / name).read_bytes(), media_type=FILES[name],
                        headers={"cache-control": "no-store"})

    async def _body(self, request) -> dict:
        data = await request.body()
        if len(data) > MAX_PROGRAM_BYTES + 4096:
            raise ValueError("the request is too large")
        body = json.loads(data or b"{}")
        if not isinstance(body, dict):
            raise ValueError("expected a JSON object")
        return body

    async def check(self, request):
        """The checker's diagnostics for the editor's text (it is not run); the session
        keeps them as the diagnostics every later scene shows."""
        from starlette.responses import JSONResponse

        try:
            text = _text(await self._body(request))
        except ValueError as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)
        found = await asyncio.to_thread(self.session.check, text)
        return JSONResponse({"diagnostics": found})

    async def save(self, request):
        """Write the editor's text to the file the studio was opened with, and only it."""
        from starlette.responses import JSONResponse

        try:
            text = _text(await self._body(request))
        except ValueError as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)
        try:
            await asyncio.to_thread(_write, self.session.file, text)
        except OSError as exc:
            return JSONResponse({"error": f"could not save {self.session.path.name}: "
                                          f"{exc.strerror or exc}"}, status_code=500)
        self.session.saved()        # the unsaved mark and the Reproduce line change
        self._notify()
        return JSONResponse({"saved": self.session.path.name, "bytes": len(text.encode())})

    async def export(self, request):
        """Replay the run into a new folder of the outputs folder (`export.py`)."""
        from starlette.responses import JSONResponse

        from swarmdsl.studio.export import export

        try:
            body = await self._body(request)
            video = body.get("video")
            result = await asyncio.to_thread(export, self.session, video)
        except (ValueError, SwarmError) as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)
        except OSError as exc:          # a full disk, a folder taken away meanwhile
            return JSONResponse({"error": f"export failed: {exc.strerror or exc}"},
                                status_code=500)
        return JSONResponse(result)

    # ---- the language server ----
    async def language_server(self, ws):
        """`swarmdsl lsp` for the page's editor over this websocket, one server per
        connection (JSON-RPC messages without headers, as @codemirror/lsp-client sends
        them). Its analyses run on a thread of their own, one message after another,
        so the frames keep flowing while a long program is checked; `exit` closes the
        socket (pygls would end the process: the studio's). The page may name only the
        studio's own file: a message about another document is refused (an analysis
        reads the model files beside its program). Without the `lsp` extra the socket
        closes and the editor keeps its highlighting and the page's checks."""
        from concurrent.futures import ThreadPoolExecutor

        from starlette.websockets import WebSocketDisconnect

        try:
            from swarmdsl.lsp.server import build_server
        except ImportError:
            await ws.close(code=1011)
            return
        await ws.accept()
        loop = asyncio.get_running_loop()
        protocol = build_server().protocol
        protocol.set_writer(_SocketWriter(ws, loop), include_headers=False)
        worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="studio-lsp")
        own = self.session.file.as_uri()
        try:
            while True:
                text = await ws.receive_text()
                try:
                    raw = json.loads(text)
                    params = raw.get("params") if isinstance(raw, dict) else None
                    doc = params.get("textDocument") if isinstance(params, dict) else None
                    uri = doc.get("uri") if isinstance(doc, dict) else None
                    if uri is not None and uri != own:
                        if "id" in raw:
                            await ws.send_text(json.dumps({
                                "jsonrpc": "2.0", "id": raw["id"], "error": {
                                    "code": -32602, "message": "the studio edits only its "
                                    "own file"}}))
                        continue
                    message = json.loads(text, object_hook=protocol.structure_message)
                except (ValueError, AttributeError, TypeError):
                    continue       # not JSON-RPC: nothing to answer
                if getattr(message, "method", None) == "exit":
                    await ws.close()
                    break
                await loop.run_in_executor(worker, protocol.handle_message, message)
        except WebSocketDisconnect:
            pass
        finally:
            worker.shutdown(wait=False)

    # ---- the websocket ----
    async def websocket(self, ws):
        """Frames out (binary), controls in (JSON text). The page sends `ready` when it
        draws, so at most IN_FLIGHT frames wait for it and a slow page slows the stream
        instead of filling memory; the next frame is made while the page draws."""
        from starlette.websockets import WebSocketDisconnect

        await ws.accept()
        self._connections += 1
        me = self.driver = self._connections
        conn = self._connections_live[me] = _Connection()
        sender = asyncio.create_task(self._send_frames(ws, conn, me))
        try:
            while True:
                message = await ws.receive()
                if message["type"] == "websocket.disconnect":
                    break
                if message.get("text") is None:
                    continue
                try:
                    op = json.loads(message["text"])
                    if not isinstance(op, dict):
                        raise ValueError("a control is a JSON object")
                    reply = await self._control(op, conn)
                except (ValueError, TypeError, KeyError, SwarmError) as exc:
                    reply = {"type": "result", "op": "?", "errors": [
                        {"severity": "error", "message": str(exc), "text": str(exc)}]}
                except Exception as exc:     # a bug: reported, the server goes on
                    reply = _internal_reply(exc)
                if reply is not None:
                    await ws.send_text(json.dumps(reply, allow_nan=False))
        except WebSocketDisconnect:
            pass                    # the page closed while its reply was on the way
        finally:
            del self._connections_live[me]
            if self.driver == me:
                self.driver = max(self._connections_live, default=0)
            sender.cancel()
            try:
                await sender
            except (asyncio.CancelledError, Exception):
                pass

    async def _send_frames(self, ws, conn, me: int) -> None:
        """Send each page what it lacks, for as long as it is connected; a bug in
        making a frame is reported to the page, which keeps its last frame."""
        while True:
            try:
                await self._send_next(ws, conn, me)
            except Exception as exc:
                from starlette.websockets import WebSocketState

                if WebSocketState.CONNECTED not in (ws.client_state, ws.application_state):
                    return          # the page went away
                session = self.session
                session.set_playing(False)
                # no retry until the next change; the credit the frame took comes back
                conn.seen, conn.scene_version = session.version, session.scene_version
                conn.forced = False
                conn.credits = min(IN_FLIGHT, conn.credits + 1)
                await ws.send_text(json.dumps(_internal_reply(exc), allow_nan=False))

    async def _send_next(self, ws, conn, me: int) -> None:
        """Wait for a credit and for something new; send the scene when it changed,
        then a frame."""
        session = self.session
        while conn.credits <= 0:
            await conn.wake.wait()
            conn.wake.clear()
        conn.credits -= 1
        while True:
            if session.scene_version != conn.scene_version:
                scene = await asyncio.to_thread(session.scene)
                conn.scene_version = scene["version"]
                history = scene.get("history") or []
                conn.since = history[-1][0] if history else -1
                await ws.send_text(json.dumps(scene, allow_nan=False))
            if session.playing and me == self.driver:
                await asyncio.to_thread(session.advance)
                self._notify()
                break
            if session.version != conn.seen or conn.forced:
                break
            try:        # woken by any control; the timeout catches other changes
                await asyncio.wait_for(conn.changed.wait(), IDLE_POLL)
            except TimeoutError:
                pass
            conn.changed.clear()
        conn.forced = False
        conn.seen = session.version
        data, conn.since = await asyncio.to_thread(session.frame, conn.layers, conn.since)
        await ws.send_bytes(data)

    async def _control(self, op: dict, conn) -> dict | None:
        session = self.session
        name = op.get("op")
        if name == "ready":             # the page drew a frame (and dropped n - 1)
            conn.credits = min(IN_FLIGHT, conn.credits + max(1, int(op.get("n", 1))))
            conn.wake.set()
            return None
        if name == "layers":
            conn.layers = {k: op.get(k) for k in LAYERS}
            conn.forced = True
            conn.changed.set()
            return None
        if name == "hello":                 # a (re)connected page: send everything
            conn.scene_version = -1
            conn.forced = True
            conn.changed.set()
            return None
        reply = await asyncio.to_thread(session.control, op)
        self._notify()
        return reply

    def _notify(self) -> None:
        """Wake every page's sender: the session changed."""
        for conn in self._connections_live.values():
            conn.changed.set()


class _Connection:
    """One page's view: its layers and what it has been sent."""

    def __init__(self):
        self.credits = IN_FLIGHT        # frames it may be sent before it draws one
        self.wake = asyncio.Event()     # a credit came
        self.changed = asyncio.Event()  # the session changed
        self.layers: dict = {"field": None}
        self.scene_version = -1
        self.since = -1
        self.forced = True
        self.seen = -1                  # the session's version of the last frame sent


class _SocketWriter:
    """pygls' writer interface on a starlette websocket, called from the language
    server's thread: each message one text frame, sent on the event loop."""

    def __init__(self, ws, loop):
        self.ws, self.loop = ws, loop

    def write(self, data) -> None:
        text = data.decode("utf-8") if isinstance(data, bytes) else data
        asyncio.run_coroutine_threadsafe(self._send(text), self.loop)

    async def _send(self, text: str) -> None:
        from starlette.websockets import WebSocketState

        if WebSocketState.CONNECTED in (self.ws.client_state, self.ws.application_state):
            try:
                await self.ws.send_text(text)
            except (RuntimeError, OSError):
                pass      # the page went away while the answer was on its way

    def close(self) -> None:
        asyncio.run_coroutine_threadsafe(self.ws.close(), self.loop)


def _internal_reply(exc: Exception) -> dict:
    """A bug in swarmdsl as the page shows an error: one line, the server goes on."""
    from swarmdsl.internal import internal_error

    text = str(internal_error(exc))
    return {"type": "result", "op": "?",
            "errors": [{"severity": "error", "message": text, "text": text}]}


def _text(body: dict) -> str:
    text = body.get("text")
    if not isinstance(text, str):
        raise ValueError("expected the program text as `text`")
    if len(text.encode()) > MAX_PROGRAM_BYTES:
        raise ValueError(f"the program is larger than {MAX_PROGRAM_BYTES} bytes")
    return text


def _write(path: Path, text: str) -> None:
    """Write `text` to `path` through a temporary file in its folder, then rename."""
    tmp = path.with_name(f".{path.name}.studio-tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def bind(host: str, port: int) -> socket.socket:
    """A listening socket on (host, port); port 0 picks a free one."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(64)
    sock.set_inheritable(True)
    return sock


def serve(studio: Studio, sock: socket.socket) -> None:
    """Serve until Ctrl-C (uvicorn's own signal handling stops it cleanly)."""
    import uvicorn

    # no per-message deflate: compressing 1.4 MB of coordinates a frame at 10^5 agents
    # costs more than sending them over the loopback
    config = uvicorn.Config(studio.app(), log_level="warning", lifespan="off",
                            ws_max_size=MAX_PROGRAM_BYTES + 4096,
                            ws_per_message_deflate=False)
    uvicorn.Server(config).run(sockets=[sock])
