"""The language server parses only the declarations an edit changed
(`swarmdsl/lsp/chunks.py`): its tree must be the whole parse's, spans and all."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmdsl.compiler.parse import parse
from swarmdsl.errors import SwarmError
from swarmdsl.lsp.chunks import ChunkParser, pieces
from tests.test_fuzz import _grammar_programs

ROOT = Path(__file__).resolve().parents[1]
TEXTS = [p.read_text() for p in sorted((ROOT / "programs").rglob("*.swarm"))]
TEXTS += [block for path in sorted((ROOT / "docs").glob("*.md"))
          for block in re.findall(r"```swarm\n(.*?)```", path.read_text(), re.S)]


def _whole(text: str):
    try:
        return parse(text, "t.swarm")
    except SwarmError as err:
        return str(err)


def _chunked(parser: ChunkParser, text: str):
    try:
        return parser.parse(text, "t.swarm")
    except SwarmError as err:
        return str(err)


@pytest.mark.parametrize("text", TEXTS, ids=range(len(TEXTS)))
def test_the_tree_is_the_whole_parses_spans_and_all(text):
    parser = ChunkParser()
    assert _chunked(parser, text) == _whole(text)
    assert _chunked(parser, text) == _whole(text)      # from the pieces kept


def test_an_edit_reparses_only_its_declaration_and_keeps_the_others():
    text = (ROOT / "programs" / "aco.swarm").read_text()
    parser = ChunkParser()
    first = parser.parse(text, "t.swarm")
    edited = text.replace("param drop = 1", "param drop = 2")
    second = parser.parse(edited, "t.swarm")
    assert second == parse(edited, "t.swarm")
    same = [a is b for a, b in zip(first.decls, second.decls, strict=True)]
    assert same.count(False) == 1
    # inside a kind: only the edited status is parsed again
    edited2 = edited.replace("step 5", "step 6") if "step 5" in edited else \
        edited.replace("len(trail) == 0", "len(trail) < 1", 1)
    third = parser.parse(edited2, "t.swarm")
    assert third == parse(edited2, "t.swarm")
    (old_kind,) = [d for d in second.decls if d.__class__.__name__ == "AgentDecl"]
    (new_kind,) = [d for d in third.decls if d.__class__.__name__ == "AgentDecl"]
    same = [a is b for a, b in zip(old_kind.items, new_kind.items, strict=True)]
    assert same.count(False) == 1 and len(same) > 5


def test_pieces_start_at_top_level_lines_only():
    text = "param a = (1 +\n2)\nagent x {\n  count 1\n}\n# c\nparam b = 3\n"
    assert [first for first, _ in pieces(text)] == [0, 2, 6]
    assert pieces("agent x {\n") is None


@settings(deadline=None, suppress_health_check=list(HealthCheck))
@given(st.sampled_from(TEXTS), st.integers(0, 10 ** 6), st.sampled_from(["", "x", "}",
                                                                           "{", "(", "\n"]))
def test_edited_text_parses_to_the_whole_parse_or_its_error(text, at, insert):
    parser = ChunkParser()
    _chunked(parser, text)
    at = at % (len(text) + 1)
    edited = text[:at] + insert + text[at:]
    assert _chunked(parser, edited) == _whole(edited)


@settings(deadline=None, suppress_health_check=list(HealthCheck))
@given(_grammar_programs())
def test_grammar_fuzzed_text_parses_alike(text):
    assert _chunked(ChunkParser(), text) == _whole(text)
