"""The language server end to end, through a real LSP client (pytest-lsp) talking to
`swarmdsl lsp` in a subprocess: diagnostics as `swarmdsl check` gives them, hover,
completion, definition, references, rename, outline, folding, semantic tokens."""

from __future__ import annotations

import contextlib
import io
import re

import pytest

from tests.lsp_helpers import (
    ERRORS,
    PROGRAMS,
    ROOT,
    lsp,
    open_text,
    position_of,
    pytest_lsp,
    server_config,
    start,
)

pytestmark = pytest.mark.asyncio(loop_scope="module")
LanguageClient = pytest_lsp.LanguageClient


@pytest_lsp.fixture(scope="module", config=server_config())
async def client(lsp_client: LanguageClient):
    await start(lsp_client)
    yield
    await lsp_client.shutdown_session()


def check_output(path) -> list[tuple[int, int, str, str]]:
    """(line, col, severity, message) of every diagnostic `swarmdsl check` prints."""
    from swarmdsl.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        main(["check", str(path)])
    out = []
    for m in re.finditer(rf"^{re.escape(str(path))}:(\d+):(\d+): (error|warning|note): "
                         r"(.*)$", err.getvalue(), re.M):
        out.append((int(m.group(1)), int(m.group(2)), m.group(3), m.group(4)))
    return out


_SEVERITY = {1: "error", 2: "warning", 3: "note"}


def as_check(diagnostics) -> list[tuple[int, int, str, str]]:
    return [(d.range.start.line + 1, d.range.start.character + 1, _SEVERITY[d.severity],
             d.message.split("\nhint: ")[0]) for d in diagnostics]


async def test_every_bad_input_is_a_diagnostic_where_check_puts_it(client):
    assert len(ERRORS) > 50
    for path in ERRORS:
        text = path.read_text()
        got = as_check(await open_text(client, text, path))
        want = check_output(path)
        assert want, path.name
        errors = [d for d in got if d[2] == "error"]
        assert errors == [d for d in want if d[2] == "error"], path.name


async def test_shipped_programs_have_the_warnings_check_prints_and_no_error(client):
    for path in PROGRAMS:
        got = as_check(await open_text(client, path.read_text(), path))
        assert not [d for d in got if d[2] == "error"], path.name
        want = check_output(path)
        assert sorted(got) == sorted(want), path.name


async def test_a_hint_and_the_related_declaration_come_with_the_error(client):
    text = ("param n = 10\nagent a {\n  count n\n  var e = 1\n  var e = 2\n"
            "  status idle { when e > 0 -> idel }\n}\n")
    path = ROOT / "tests" / "scratch_hint.swarm"
    diags = await open_text(client, text, path)
    dup = next(d for d in diags if "already declared" in d.message)
    assert dup.range.start == lsp.Position(line=4, character=6)
    related = dup.related_information
    assert related and related[0].location.range.start == lsp.Position(line=3, character=6)
    typo = next(d for d in diags if "unknown status" in d.message)
    assert "hint: did you mean 'idle'?" in typo.message
    assert typo.severity == lsp.DiagnosticSeverity.Error


async def test_broken_text_still_gets_its_error_and_later_a_fix_clears_it(client):
    path = ROOT / "tests" / "scratch_broken.swarm"
    text = (ROOT / "programs" / "boids.swarm").read_text()
    cut = text[:text.index("velocity = rotate")] + "velocity = (1, \n"
    diags = await open_text(client, cut, path)
    assert [d for d in diags if d.severity == lsp.DiagnosticSeverity.Error]
    assert list(await open_text(client, text, path)) == []


async def test_columns_are_utf16_after_wide_characters(client):
    # `😀` is one character to the compiler and two UTF-16 units to the editor
    text = 'agent a {\n  count 2\n  status s { let t = "😀"; velocity = bogus }\n}\n'
    path = ROOT / "tests" / "scratch_utf16.swarm"
    diags = await open_text(client, text, path)
    err = next(d for d in diags if "unknown name" in d.message)
    assert err.range.start == position_of(text, "bogus")
    assert err.range.start.character == text.splitlines()[2].index("bogus") + 1


def _hover_text(h) -> str:
    return h.contents.value if h is not None else ""


async def test_hover_shows_a_builtins_signature_and_its_rows_doc(client):
    from swarmdsl.compiler.builtins import AGGREGATES, FUNCTIONS

    path = ROOT / "programs" / "boids.swarm"
    text = path.read_text()
    await open_text(client, text, path)
    uri = path.as_uri()
    h = await client.text_document_hover_async(lsp.HoverParams(
        text_document=lsp.TextDocumentIdentifier(uri=uri),
        position=position_of(text, "normalize(", offset=2)))
    assert "normalize(vector) -> a vector" in _hover_text(h)
    assert FUNCTIONS["normalize"].doc in _hover_text(h)
    h = await client.text_document_hover_async(lsp.HoverParams(
        text_document=lsp.TextDocumentIdentifier(uri=uri),
        position=position_of(text, "sum(", offset=1)))
    assert AGGREGATES["sum"].doc in _hover_text(h)


async def test_hover_shows_a_params_value_and_range_and_a_lets_type(client):
    text = ("param radius = 2 * 40 in 10..200\nworld { size 100 x 100 }\nagent a {\n"
            "  count 3\n  status s {\n    let near = neighbors(radius)\n"
            "    velocity += (count(near), 0)\n  }\n}\n")
    path = ROOT / "tests" / "scratch_hover.swarm"
    await open_text(client, text, path)
    uri = path.as_uri()
    h = await client.text_document_hover_async(lsp.HoverParams(
        text_document=lsp.TextDocumentIdentifier(uri=uri),
        position=position_of(text, "radius)", offset=1)))
    assert "value 80, range 10..200" in _hover_text(h)
    h = await client.text_document_hover_async(lsp.HoverParams(
        text_document=lsp.TextDocumentIdentifier(uri=uri),
        position=position_of(text, "near)", offset=1)))
    assert "a neighbour set" in _hover_text(h) and "let near" in _hover_text(h)


async def _complete(client, path, text, needle, offset=None):
    await open_text(client, text, path)
    at = position_of(text, needle, offset=len(needle) if offset is None else offset)
    result = await client.text_document_completion_async(lsp.CompletionParams(
        text_document=lsp.TextDocumentIdentifier(uri=path.as_uri()), position=at))
    return {i.label: i for i in result.items}


async def test_completion_after_other_dot_offers_every_kinds_variables(client):
    path = ROOT / "tests" / "scratch_complete.swarm"
    good = ("agent a {\n  count 3\n  var energy = 1\n  status s {\n"
            "    let near = neighbors(5)\n    energy += 0\n  }\n}\n"
            "agent b {\n  count 1\n  attr weight = 2\n  status t { }\n}\n")
    await open_text(client, good, path)
    typing = good.replace("energy += 0", "energy += sum(near : other.")
    items = await _complete(client, path, typing, "other.")
    assert {"energy", "weight", "pos", "vel", "status"} <= set(items)
    assert "neighbors" not in items


async def test_completion_after_arrow_offers_the_kinds_statuses(client):
    path = ROOT / "tests" / "scratch_arrow.swarm"
    good = ("agent a {\n  count 3\n  status idle { }\n  status busy { }\n}\n"
            "agent b {\n  count 1\n  status other_kind_status { }\n}\n")
    await open_text(client, good, path)
    typing = good.replace("status idle { }", "status idle {\n    when tick > 3 -> \n  }")
    items = await _complete(client, path, typing, "-> ")
    assert set(items) == {"idle", "busy"}


async def test_completion_in_a_status_offers_lets_builtins_with_snippets_and_keywords(client):
    path = ROOT / "programs" / "boids.swarm"
    text = path.read_text()
    typing = text.replace("    velocity = rotate", "    velocity = \n    velocity = rotate", 1)
    items = await _complete(client, path, typing, "velocity = \n", offset=len("velocity = "))
    for name in ("near", "sep", "radius", "pos", "sum", "normalize", "flying", "if"):
        assert name in items, name
    assert "when" not in items     # a value is being written, not a statement
    assert items["normalize"].insert_text == "normalize(${1:vector})"
    assert items["normalize"].insert_text_format == lsp.InsertTextFormat.Snippet
    typing = text.replace("    velocity = rotate", "    \n    velocity = rotate", 1)
    items = await _complete(client, path, typing, "    \n    velocity = rotate", offset=4)
    assert {"when", "let", "tree", "near", "deposit"} <= set(items)
    await open_text(client, text, path)


async def test_completion_at_top_level_offers_declaration_keywords(client):
    path = ROOT / "tests" / "scratch_top.swarm"
    items = await _complete(client, path, "param n = 1\n\n", "\n\n")
    assert {"agent", "param", "world", "field", "tree", "metric"} <= set(items)


async def test_definition_and_references_of_a_let_and_a_status(client):
    path = ROOT / "programs" / "patrol.swarm"
    text = path.read_text()
    await open_text(client, text, path)
    doc = lsp.TextDocumentIdentifier(uri=path.as_uri())
    got = await client.text_document_definition_async(lsp.DefinitionParams(
        text_document=doc, position=position_of(text, "count(ahead)", offset=7)))
    assert got[0].range.start == position_of(text, "let ahead", offset=4)
    got = await client.text_document_definition_async(lsp.DefinitionParams(
        text_document=doc, position=position_of(text, "-> charging", offset=4)))
    assert got[0].range.start == position_of(text, "status charging", offset=7)
    refs = await client.text_document_references_async(lsp.ReferenceParams(
        text_document=doc, position=position_of(text, "status charging", offset=8),
        context=lsp.ReferenceContext(include_declaration=True)))
    starts = {(r.range.start.line, r.range.start.character) for r in refs}
    want = {(p.line, p.character) for p in (
        position_of(text, "charging {", 0), position_of(text, "status charging", offset=7),
        position_of(text, "!= charging", offset=3), position_of(text, "== charging", offset=3))}
    assert want <= starts
    code = "\n".join(s for s in text.splitlines() if not s.startswith("#"))
    assert len(starts) == code.count("charging") - code.count("charging_")


async def _rename(client, path, text, needle, new, offset=0):
    await open_text(client, text, path)
    return await client.text_document_rename_async(lsp.RenameParams(
        text_document=lsp.TextDocumentIdentifier(uri=path.as_uri()),
        position=position_of(text, needle, offset=offset), new_name=new))


def _apply(text: str, edit) -> str:
    lines = text.splitlines(keepends=True)
    (edits,) = edit.changes.values()
    for e in sorted(edits, key=lambda e: (e.range.start.line, e.range.start.character),
                    reverse=True):
        s = lines[e.range.start.line]
        lines[e.range.start.line] = (s[:e.range.start.character] + e.new_text
                                     + s[e.range.end.character:])
    return "".join(lines)


async def test_rename_a_param_renames_every_use_and_the_program_still_checks(client):
    from swarmdsl.compiler import compile_source

    path = ROOT / "programs" / "patrol.swarm"
    text = path.read_text()
    edit = await _rename(client, path, text, "param cruise", "speed_limit", offset=6)
    new = _apply(text, edit)
    assert "cruise" not in new and new.count("speed_limit") == text.count("cruise")
    compile_source(new, "renamed.swarm")


async def test_rename_a_variable_read_as_other_renames_it_in_every_kind(client):
    path = ROOT / "tests" / "scratch_rename.swarm"
    text = ("agent a {\n  count 2\n  var energy = 1\n  status s {\n"
            "    energy += sum(neighbors(5) : other.energy)\n  }\n}\n"
            "agent b {\n  count 2\n  var energy = 3\n  status t { energy -= 1 }\n}\n")
    edit = await _rename(client, path, text, "var energy", "charge", offset=4)
    new = _apply(text, edit)
    assert "energy" not in new and new.count("charge") == 5


async def test_rename_that_would_clash_is_refused_with_the_reason(client):
    path = ROOT / "programs" / "patrol.swarm"
    text = path.read_text()
    with pytest.raises(Exception, match="already the param `gap`"):
        await _rename(client, path, text, "param cruise", "gap", offset=6)
    with pytest.raises(Exception, match="keyword or a built-in"):
        await _rename(client, path, text, "param cruise", "pos", offset=6)
    with pytest.raises(Exception, match="built into the language"):
        await _rename(client, path, text, "min(battery", "smallest")
    with pytest.raises(Exception, match="already the status `patrol`"):
        await _rename(client, path, text, "status charging", "patrol", offset=8)


async def test_outline_lists_declarations_with_kinds_statuses_and_lets(client):
    path = ROOT / "programs" / "patrol.swarm"
    text = path.read_text()
    await open_text(client, text, path)
    syms = await client.text_document_document_symbol_async(lsp.DocumentSymbolParams(
        text_document=lsp.TextDocumentIdentifier(uri=path.as_uri())))
    names = [s.name for s in syms]
    assert names[:6] == ["robots", "cruise", "gap", "low", "drain", "charge_rate"]
    assert {"world", "dock", "visit", "robot", "charging_now"} <= set(names)
    robot = next(s for s in syms if s.name == "robot")
    assert robot.kind == lsp.SymbolKind.Class
    children = {c.name: c for c in robot.children}
    assert {"battery", "wp", "patrol", "charging", "powered"} <= set(children)
    assert [c.name for c in children["patrol"].children] == ["ahead"]


async def test_folding_covers_blocks_and_comment_runs(client):
    path = ROOT / "programs" / "patrol.swarm"
    text = path.read_text()
    await open_text(client, text, path)
    folds = await client.text_document_folding_range_async(lsp.FoldingRangeParams(
        text_document=lsp.TextDocumentIdentifier(uri=path.as_uri())))
    got = {(f.start_line, f.end_line, f.kind) for f in folds}
    lines = text.splitlines()
    agent = next(i for i, s in enumerate(lines) if s.startswith("agent robot"))
    end = next(i for i in range(agent, len(lines)) if lines[i] == "}")
    assert (agent, end, lsp.FoldingRangeKind.Region) in got
    assert (0, 9, lsp.FoldingRangeKind.Comment) in got


async def test_semantic_tokens_tell_keywords_params_statuses_and_functions(client):
    from swarmdsl.lsp.outline import TOKEN_TYPES

    path = ROOT / "programs" / "patrol.swarm"
    text = path.read_text()
    await open_text(client, text, path)
    toks = await client.text_document_semantic_tokens_full_async(lsp.SemanticTokensParams(
        text_document=lsp.TextDocumentIdentifier(uri=path.as_uri())))
    data, line, col, found = toks.data, 0, 0, {}
    lines = text.splitlines()
    for i in range(0, len(data), 5):
        dl, dc, length, ttype, _mods = data[i:i + 5]
        line += dl
        col = col + dc if dl == 0 else dc
        found.setdefault(TOKEN_TYPES[ttype], set()).add(lines[line][col:col + length])
    assert {"param", "agent", "status", "when", "let", "tree"} <= found["keyword"]
    assert {"charging", "patrol"} <= found["enumMember"]
    assert {"rotate", "normalize", "count", "min"} <= found["function"]
    assert "# Patrolling robots with a charging dock, written as a behaviour tree." \
        in found["comment"]
    assert {"robot"} <= found["class"]


async def test_formatting_lays_out_the_document_and_refuses_broken_text(client):
    path = ROOT / "tests" / "scratch_format.swarm"
    messy = "agent a{\ncount 2\nstatus s{ velocity=(1,0) }\n}\n"
    await open_text(client, messy, path)
    doc = lsp.TextDocumentIdentifier(uri=path.as_uri())
    options = lsp.FormattingOptions(tab_size=2, insert_spaces=True)
    edits = await client.text_document_formatting_async(lsp.DocumentFormattingParams(
        text_document=doc, options=options))
    assert [e.new_text for e in edits] == [
        "agent a {\n  count 2\n  status s { velocity = (1, 0) }\n}\n"]
    await open_text(client, messy.replace("(1,0)", "(1,"), path)
    assert not await client.text_document_formatting_async(lsp.DocumentFormattingParams(
        text_document=doc, options=options))


async def test_hover_on_actions_options_and_tree_nodes_reads_their_rows(client):
    from swarmdsl.compiler.actions import ACTIONS
    from swarmdsl.compiler.options import AGENT_OPTIONS

    path = ROOT / "programs" / "aco_bt.swarm"
    text = path.read_text()
    await open_text(client, text, path)
    doc = lsp.TextDocumentIdentifier(uri=path.as_uri())

    async def hover_at(needle, offset=1):
        h = await client.text_document_hover_async(lsp.HoverParams(
            text_document=doc, position=position_of(text, needle, offset=offset)))
        return _hover_text(h)

    assert ACTIONS["remember"].doc in await hover_at("remember(")
    assert AGENT_OPTIONS["count"].doc in await hover_at("  count ", offset=3)
    assert "tree node `sequence`" in await hover_at("sequence")


async def test_a_diagnostic_past_the_last_line_stays_inside_the_document(client):
    path = ROOT / "tests" / "scratch_empty.swarm"
    diags = await open_text(client, "", path)
    (only,) = diags
    assert "declares no agent kind" in only.message
    assert only.range.end.line == 0
