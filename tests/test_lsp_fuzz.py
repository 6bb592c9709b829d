"""Fuzzed text never crashes the language server nor leaves it unresponsive: shipped
programs and the grammar fuzzer's programs, cut at random points (what an editor sends
while a file is typed), each answered with diagnostics and every request answered.

The server runs as editors run it (`swarmdsl lsp`, a subprocess); this test talks
JSON-RPC to it synchronously, with a deadline on every answer, so hypothesis can drive
it. The long run: `HYPOTHESIS_PROFILE=long python -m pytest -m slow tests/test_lsp_fuzz.py`.
"""

from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("pygls", reason="the language server needs pygls (the lsp extra)")

from tests.test_fuzz import _grammar_programs  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = sorted((ROOT / "programs").rglob("*.swarm"))
DEADLINE = 20.0     # seconds for any answer: far above the ~50 ms one takes


class Server:
    """`swarmdsl lsp` in a subprocess, spoken to one request at a time."""

    def __init__(self):
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
        self.proc = subprocess.Popen([sys.executable, "-m", "swarmdsl", "lsp"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, env=env)
        self.inbox: queue.Queue = queue.Queue()
        self.next_id = 0
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        out = self.proc.stdout
        while True:
            headers = {}
            while True:
                line = out.readline()
                if not line:
                    self.inbox.put(None)
                    return
                if line in (b"\r\n", b"\n"):
                    break
                key, _, value = line.decode().partition(":")
                headers[key.strip().lower()] = value.strip()
            self.inbox.put(json.loads(out.read(int(headers["content-length"]))))

    def send(self, message: dict) -> None:
        body = json.dumps({"jsonrpc": "2.0", **message}).encode()
        self.proc.stdin.write(b"Content-Length: %d\r\n\r\n" % len(body) + body)
        self.proc.stdin.flush()

    def wait_for(self, match) -> dict:
        while True:
            try:
                msg = self.inbox.get(timeout=DEADLINE)
            except queue.Empty:
                raise AssertionError(f"the server gave no answer in {DEADLINE} s") from None
            assert msg is not None, "the server exited"
            if match(msg):
                return msg

    def request(self, method: str, params: dict) -> dict:
        self.next_id += 1
        rid = self.next_id
        self.send({"id": rid, "method": method, "params": params})
        reply = self.wait_for(lambda m: m.get("id") == rid)
        assert "error" not in reply, (method, reply["error"])
        return reply

    def close(self) -> None:
        try:
            self.request("shutdown", {})
            self.send({"method": "exit"})
            self.proc.wait(timeout=10)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
            self.reader.join(timeout=10)
            self.proc.stdin.close()
            self.proc.stdout.close()


@pytest.fixture(scope="module")
def server():
    s = Server()
    s.request("initialize", {"processId": None, "rootUri": None, "capabilities": {}})
    s.send({"method": "initialized", "params": {}})
    uri = (ROOT / "tests" / "fuzzed.swarm").as_uri()
    s.send({"method": "textDocument/didOpen", "params": {"textDocument": {
        "uri": uri, "languageId": "swarm", "version": 1, "text": ""}}})
    s.wait_for(lambda m: m.get("method") == "textDocument/publishDiagnostics")
    s.uri, s.version = uri, 1
    yield s
    s.close()


def _assert_served(server: Server, text: str, where: float) -> None:
    """Every request about `text` answered without an error (`Server.request`)."""
    server.version += 1
    server.send({"method": "textDocument/didChange", "params": {
        "textDocument": {"uri": server.uri, "version": server.version},
        "contentChanges": [{"text": text}]}})
    server.wait_for(lambda m: m.get("method") == "textDocument/publishDiagnostics")
    lines = text.split("\n")
    line = min(int(where * len(lines)), len(lines) - 1)
    pos = {"line": line, "character": len(lines[line]) // 2}
    doc = {"uri": server.uri}
    for method in ("textDocument/hover", "textDocument/completion",
                   "textDocument/definition", "textDocument/documentSymbol",
                   "textDocument/foldingRange", "textDocument/semanticTokens/full",
                   "textDocument/formatting"):
        params = {"textDocument": doc}
        if method in ("textDocument/hover", "textDocument/completion",
                      "textDocument/definition"):
            params["position"] = pos
        if method == "textDocument/formatting":
            params["options"] = {"tabSize": 2, "insertSpaces": True}
        server.request(method, params)
    server.request("textDocument/references", {"textDocument": doc, "position": pos,
                                                "context": {"includeDeclaration": True}})


# half the profile's examples per test: each is a round trip to another process
FUZZ = settings(max_examples=max(1, settings.default.max_examples // 2), deadline=None,
                suppress_health_check=list(HealthCheck))


@FUZZ
@given(st.sampled_from(PROGRAMS), st.floats(0, 1), st.floats(0, 1))
def test_shipped_programs_cut_anywhere_are_served(server, path, cut, where):
    text = path.read_text()
    _assert_served(server, text[:int(cut * len(text))], where)
    assert server.proc.poll() is None      # and it is still up for the next edit


@FUZZ
@given(_grammar_programs(), st.floats(0, 1), st.floats(0, 1))
def test_grammar_fuzzer_programs_cut_anywhere_are_served(server, text, cut, where):
    _assert_served(server, text[:int(cut * len(text))], where)
    assert server.proc.poll() is None


def test_the_server_is_still_alive_and_answers(server):
    _assert_served(server, (ROOT / "programs" / "boids.swarm").read_text(), 0.5)
    assert server.proc.poll() is None
