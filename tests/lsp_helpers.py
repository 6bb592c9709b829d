"""Shared by the language-server tests: the server started as editors start it
(`swarmdsl lsp` in a subprocess, driven by pytest-lsp's real client), and helpers to
open a document and wait for its diagnostics."""

from __future__ import annotations

import asyncio
import os
import sys
from pathlib import Path

import pytest

pytest_lsp = pytest.importorskip("pytest_lsp", reason="the lsp tests need pytest-lsp")
lsp = pytest.importorskip("lsprotocol.types", reason="the lsp tests need lsprotocol")

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = sorted((ROOT / "programs").rglob("*.swarm"))
ERRORS = sorted((ROOT / "tests" / "data" / "errors").glob("*.swarm"))


def server_config():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    return pytest_lsp.ClientServerConfig(server_command=[sys.executable, "-m", "swarmdsl",
                                                         "lsp"], server_env=env)


async def start(client, encoding=None):
    caps = pytest_lsp.client_capabilities("visual-studio-code")
    if encoding is not None:
        caps.general = lsp.GeneralClientCapabilities(position_encodings=[encoding])
    return await client.initialize_session(lsp.InitializeParams(capabilities=caps))


_versions: dict[str, int] = {}


async def open_text(client, text: str, path: Path) -> list:
    """Open (or replace) `path`'s document with `text`; its published diagnostics."""
    uri = path.as_uri()
    version = _versions.get(uri, 0) + 1
    _versions[uri] = version
    client.diagnostics.pop(uri, None)
    if version == 1:
        client.text_document_did_open(lsp.DidOpenTextDocumentParams(
            text_document=lsp.TextDocumentItem(uri=uri, language_id="swarm", version=1,
                                               text=text)))
    else:
        client.text_document_did_change(lsp.DidChangeTextDocumentParams(
            text_document=lsp.VersionedTextDocumentIdentifier(uri=uri, version=version),
            content_changes=[lsp.TextDocumentContentChangeWholeDocument(text=text)]))
    for _ in range(400):
        if uri in client.diagnostics:
            return client.diagnostics[uri]
        await asyncio.sleep(0.025)
    raise AssertionError(f"no diagnostics for {path.name} within 10 s")


def position_of(text: str, needle: str, nth: int = 0, offset: int = 0):
    """The LSP position (UTF-16) of the `nth` occurrence of `needle`, plus `offset`."""
    at = -1
    for _ in range(nth + 1):
        at = text.index(needle, at + 1)
    at += offset
    line = text.count("\n", 0, at)
    col = at - (text.rfind("\n", 0, at) + 1)
    prefix = text.split("\n")[line][:col]
    return lsp.Position(line=line, character=len(prefix.encode("utf-16-le")) // 2)
