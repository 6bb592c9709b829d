"""The VS Code extension (`editors/vscode/`): its TextMate grammar is generated from
the compiler's tables and up to date, and, run as VS Code runs it (vscode-textmate on
oniguruma, through node), it tokenises every shipped program with each keyword,
number, string and comment the parser reads scoped as one."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from swarmdsl.compiler.parse import tokens

ROOT = Path(__file__).resolve().parents[1]
VSCODE = ROOT / "editors" / "vscode"
GRAMMAR = VSCODE / "syntaxes" / "swarm.tmLanguage.json"
PROGRAMS = sorted((ROOT / "programs").rglob("*.swarm"))


def _generator():
    sys.path.insert(0, str(VSCODE))
    try:
        import grammar
    finally:
        sys.path.remove(str(VSCODE))
    return grammar


def test_the_grammar_file_is_generated_from_the_compilers_tables():
    assert json.loads(GRAMMAR.read_text()) == _generator().build(), \
        "run `python editors/vscode/grammar.py` and commit the grammar"


def test_the_extension_is_versioned_with_swarmdsl():
    from swarmdsl.version import __version__

    manifest = json.loads((VSCODE / "package.json").read_text())
    assert manifest["version"] == __version__
    assert manifest["contributes"]["languages"][0]["extensions"] == [".swarm"]
    assert manifest["contributes"]["configuration"]["properties"][
        "swarmdsl.server.command"]["default"] == ["swarmdsl", "lsp"]


@pytest.fixture(scope="module")
def scopes():
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed: the grammar test runs vscode-textmate in node")
    if not (VSCODE / "node_modules" / "vscode-textmate").is_dir():
        pytest.skip("the extension's npm packages are not installed: npm ci in "
                    "editors/vscode")
    done = subprocess.run([node, "test/tokenize.js", str(GRAMMAR), *map(str, PROGRAMS)],
                          cwd=VSCODE, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


_EXPECTED = {"NUMBER": "constant.numeric", "STRING": "string.quoted"}


def _scope_at(lines, line: int, col_utf16: int) -> list[str]:
    for start, end, scope in lines[line]:
        if start <= col_utf16 < end:
            return scope
    return []


def _utf16(text: str) -> int:
    return len(text.encode("utf-16-le")) // 2


@pytest.mark.parametrize("path", PROGRAMS, ids=lambda p: p.name)
def test_every_shipped_program_is_tokenised_as_the_parser_reads_it(scopes, path):
    text = path.read_text()
    lines = scopes[str(path)]
    starts = [0]
    for i, c in enumerate(text):
        if c == "\n":
            starts.append(i + 1)
    checked = 0
    for ttype, value, start, _stop in tokens(text):
        line = max(i for i, s in enumerate(starts) if s <= start)
        col = _utf16(text[starts[line]:start])
        scope = " ".join(_scope_at(lines, line, col))
        if ttype in _EXPECTED:
            assert _EXPECTED[ttype] in scope, (path.name, line + 1, value, scope)
        elif ttype != "NAME" and value[:1].isalpha():
            assert "keyword" in scope or "constant.language" in scope, \
                (path.name, line + 1, value, scope)
        else:
            continue
        checked += 1
    for number, line_text in enumerate(text.split("\n")):
        if "#" in line_text and '"' not in line_text:
            col = _utf16(line_text[:line_text.index("#")])
            assert "comment" in " ".join(_scope_at(lines, number, col)), (path.name, number)
    assert checked > 10


def test_the_studio_editor_bundle_carries_the_current_grammar():
    """The studio's editor.js embeds the grammar's patterns when it is built: rebuilt
    (`cd editors/studio && npm run build`) whenever the grammar changes."""
    bundle = (ROOT / "swarmdsl" / "studio" / "static" / "editor.js").read_text()
    grammar = _generator().build()
    for rule in ("keyword", "call", "state"):
        for pattern in grammar["repository"][rule]["patterns"]:
            assert json.dumps(pattern["match"])[1:-1] in bundle, \
                f"editor.js is older than the grammar ({rule}): rebuild it"
