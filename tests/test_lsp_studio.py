"""The studio's editor on the language server in a real browser (Debian's chromium, playwright): CodeMirror
with the language's highlighting, and the language server over the studio's websocket
underlining a typo with its message, completing after `other.`, and explaining a
built-in on hover. Skipped where chromium is missing (CI installs it: .ci/run)."""

from __future__ import annotations

import pytest

pytest.importorskip("pygls", reason="the editor's language server needs the lsp extra")

import tests.test_studio_browser as browser_tests  # noqa: E402

# the browser, the studio process and its page, as the studio's browser tests make them
WAIT, type_text = browser_tests.WAIT, browser_tests.type_text
browser, program = browser_tests.browser, browser_tests.program
studio, page = browser_tests.studio, browser_tests.page


def _source(page) -> str:
    return page.input_value("#source")


def test_the_editor_highlights_keywords_comments_numbers_and_builtins(page):
    page.wait_for_selector(".cm-content .tok-keyword", timeout=WAIT)
    keywords = set(page.locator(".cm-content .tok-keyword").all_inner_texts())
    assert {"param", "world", "field", "agent", "status", "metric"} <= keywords
    comments = page.locator(".cm-content .tok-comment").all_inner_texts()
    assert comments[0].startswith("# The studio tests' program")
    assert "300" in page.locator(".cm-content .tok-number").all_inner_texts()
    builtins = set(page.locator(".cm-content .tok-builtin").all_inner_texts())
    assert {"rotate", "normalize", "deposit"} <= builtins


def test_a_typo_is_underlined_with_the_checkers_message(page):
    text = _source(page)
    type_text(page, text.replace("deposit(warmth, 1)", "deposit(warmt, 1)"))
    underline = page.locator(".cm-lintRange-error").first
    underline.wait_for(timeout=WAIT)
    assert underline.inner_text() == "warmt"
    underline.hover()
    tooltip = page.locator(".cm-tooltip-lint")
    tooltip.wait_for(timeout=WAIT)
    assert "unknown name `warmt`" in tooltip.inner_text()
    assert "did you mean 'warmth'?" in tooltip.inner_text()


def test_completion_after_other_dot_offers_the_neighbours_state(page):
    text = _source(page)
    line = next(i for i, s in enumerate(text.split("\\n")) if "deposit(warmth" in s)
    page.click(".cm-content")
    page.keyboard.press("Control+Home")
    for _ in range(line):
        page.keyboard.press("ArrowDown")
    page.keyboard.press("End")
    page.keyboard.press("Enter")
    page.keyboard.type("let near = sum(neighbors(5) : other.")
    box = page.locator(".cm-tooltip-autocomplete")
    box.wait_for(timeout=WAIT)
    options = set(box.locator("li .cm-completionLabel").all_inner_texts())
    assert {"pos", "vel", "heading", "status"} <= options
    assert "deposit" not in options


def test_hover_over_a_builtin_shows_its_signature_and_meaning(page):
    from swarmdsl.compiler.builtins import FUNCTIONS

    page.wait_for_selector(".cm-content .tok-builtin", timeout=WAIT)
    word = page.locator(".cm-content .tok-builtin", has_text="normalize").first
    page.wait_for_function("window.editor && window.editor.client.serverCapabilities",
                           timeout=WAIT)
    word.hover()
    tooltip = page.locator(".cm-tooltip-hover")
    tooltip.wait_for(timeout=WAIT)
    assert "normalize(vector) -> a vector" in tooltip.inner_text()
    assert FUNCTIONS["normalize"].doc in tooltip.inner_text()


def test_the_language_server_socket_needs_the_token_and_its_exit_ends_only_itself(studio):
    import json
    import urllib.request

    from websockets.sync.client import connect

    base = studio.base.replace("http", "ws", 1)
    with pytest.raises(Exception):                  # noqa: B017  refused: no token
        with connect(f"{base}/lsp?token=wrong", open_timeout=10) as ws:
            ws.recv(timeout=5)
    with connect(f"{base}/lsp?token={studio.token}", open_timeout=10) as ws:
        ws.send(json.dumps({"jsonrpc": "2.0", "id": 1, "method": "initialize",
                            "params": {"processId": None, "rootUri": None,
                                       "capabilities": {}}}))
        reply = json.loads(ws.recv(timeout=20))
        assert reply["id"] == 1 and "hoverProvider" in reply["result"]["capabilities"]
        # another file than the studio's is refused: the page names no other file
        other = "file:///etc/other.swarm"
        ws.send(json.dumps({"jsonrpc": "2.0", "method": "textDocument/didOpen", "params": {
            "textDocument": {"uri": other, "languageId": "swarm", "version": 1,
                             "text": "agent a { }"}}}))
        ws.send(json.dumps({"jsonrpc": "2.0", "id": 2, "method": "textDocument/hover",
                            "params": {"textDocument": {"uri": other},
                                       "position": {"line": 0, "character": 7}}}))
        reply = json.loads(ws.recv(timeout=20))
        assert reply["id"] == 2 and "only its own file" in reply["error"]["message"]
        ws.send(json.dumps({"jsonrpc": "2.0", "method": "exit"}))
    with urllib.request.urlopen(f"{studio.base}/?token={studio.token}", timeout=20) as page:
        assert page.status == 200 and studio.proc.poll() is None
