"""The pygls wiring: LSP requests in, `analysis`/`hover`/`complete`/`navigate`/`outline`
answers out, positions converted to the client's encoding (UTF-16 unless it asks for
UTF-8 or UTF-32; the compiler counts characters).

Each change of a document is analysed at once (a 500-line program takes tens of
milliseconds, docs/benchmarks.md) and its diagnostics published. The document's last
analysis that parsed is kept beside the current one: completion and hover on text
being typed, which rarely parses, read the names from it.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

from lsprotocol import types as lsp
from pygls.lsp.server import LanguageServer
from pygls.uris import to_fs_path

from swarmdsl.lsp import complete, hover, navigate, outline
from swarmdsl.lsp.analysis import Analysis, Range, analyse
from swarmdsl.lsp.chunks import ChunkParser
from swarmdsl.version import __version__

_LINE_BREAK = re.compile(r"\r\n|\r|\n")


class Positions:
    """Line/column conversions between the compiler's (characters) and the client's
    (UTF-16, UTF-8 or UTF-32 code units), lines split where the parser splits them."""

    def __init__(self, text: str, encoding: str):
        self.text = text
        self.starts = [0] + [m.end() for m in _LINE_BREAK.finditer(text)]
        self.lines = _LINE_BREAK.split(text)
        self.encoding = encoding

    def _units(self, s: str) -> int:
        if self.encoding == lsp.PositionEncodingKind.Utf8:
            return len(s.encode("utf-8", "surrogatepass"))
        if self.encoding == lsp.PositionEncodingKind.Utf32:
            return len(s)
        return len(s.encode("utf-16-le", "surrogatepass")) // 2

    def position(self, line: int, col: int) -> lsp.Position:
        """A position in the text: one past its end (a span to the end of the file,
        after its last line break) is the end of its last line."""
        if line >= len(self.lines):
            line, col = len(self.lines) - 1, len(self.lines[-1])
        line = max(line, 0)
        s = self.lines[line]
        return lsp.Position(line=line, character=self._units(s[:min(col, len(s))]))

    def range(self, r: Range) -> lsp.Range:
        return lsp.Range(start=self.position(r.line, r.col),
                         end=self.position(r.end_line, r.end_col))

    def from_client(self, pos: lsp.Position) -> tuple[int, int]:
        if pos.line >= len(self.lines):
            return len(self.lines) - 1, len(self.lines[-1])
        s, units, col = self.lines[pos.line], 0, 0
        for ch in s:
            if units >= pos.character:
                break
            units += self._units(ch)
            col += 1
        return pos.line, col

    def offset(self, line: int, col: int) -> int:
        return self.starts[min(line, len(self.starts) - 1)] + col


@dataclass
class _Doc:
    analysis: Analysis
    parsed: Analysis | None     # the last analysis whose text parsed
    parser: ChunkParser         # the document's declarations, parsed
    version: int | None = None  # the client's version of the text analysed


class SwarmLanguageServer(LanguageServer):
    def __init__(self):
        super().__init__("swarmdsl", __version__)
        self.docs: dict[str, _Doc] = {}

    def encoding(self) -> str:
        try:
            return self.workspace.position_encoding or lsp.PositionEncodingKind.Utf16
        except RuntimeError:     # before `initialize`
            return lsp.PositionEncodingKind.Utf16

    def positions(self, uri: str) -> Positions:
        return Positions(self.docs[uri].analysis.text, self.encoding())

    def refresh(self, uri: str, text: str, version: int | None = None) -> None:
        from swarmdsl.files import MAX_PROGRAM_BYTES
        from swarmdsl.lsp.ranges import Diagnostic

        path = to_fs_path(uri) or uri
        old = self.docs.get(uri)
        parser = old.parser if old else ChunkParser()
        if len(text.encode("utf-8", "surrogatepass")) > MAX_PROGRAM_BYTES:
            result = Analysis(text, path)   # as `swarmdsl check` refuses to read it
            result.diagnostics = [Diagnostic(Range(0, 0, 0, 1), "error",
                                             f"the program is larger than "
                                             f"{MAX_PROGRAM_BYTES} bytes, the most "
                                             "swarmdsl reads")]
        else:
            result = analyse(text, path, Path(path).resolve().parent, parser)
        parsed = result if result.parsed else (old.parsed if old else None)
        if version is None and old is not None:
            version = old.version
        self.docs[uri] = _Doc(result, parsed, parser, version)
        self.publish(uri)

    def publish(self, uri: str) -> None:
        doc = self.docs[uri]
        pos = Positions(doc.analysis.text, self.encoding())
        out = []
        for d in doc.analysis.diagnostics:
            related = [lsp.DiagnosticRelatedInformation(
                location=lsp.Location(uri=uri, range=pos.range(r.range)), message=r.message)
                for r in d.related] or None
            out.append(lsp.Diagnostic(range=pos.range(d.range), message=d.text,
                                      severity=_SEVERITY[d.severity], source="swarmdsl",
                                      related_information=related))
        self.text_document_publish_diagnostics(lsp.PublishDiagnosticsParams(
            uri=uri, diagnostics=out, version=doc.version))


_SEVERITY = {"error": lsp.DiagnosticSeverity.Error, "warning": lsp.DiagnosticSeverity.Warning,
             "information": lsp.DiagnosticSeverity.Information}
_COMPLETION_KIND = {
    "function": lsp.CompletionItemKind.Function, "variable": lsp.CompletionItemKind.Variable,
    "keyword": lsp.CompletionItemKind.Keyword, "enum": lsp.CompletionItemKind.EnumMember,
    "property": lsp.CompletionItemKind.Property, "field": lsp.CompletionItemKind.Field,
    "constant": lsp.CompletionItemKind.Constant, "struct": lsp.CompletionItemKind.Struct,
    "method": lsp.CompletionItemKind.Method,
}
LEGEND = lsp.SemanticTokensLegend(token_types=outline.TOKEN_TYPES,
                                  token_modifiers=outline.TOKEN_MODIFIERS)


def build_server() -> SwarmLanguageServer:
    server = SwarmLanguageServer()

    @server.feature(lsp.TEXT_DOCUMENT_DID_OPEN)
    def did_open(ls: SwarmLanguageServer, params: lsp.DidOpenTextDocumentParams):
        ls.refresh(params.text_document.uri, params.text_document.text,
                   params.text_document.version)

    @server.feature(lsp.TEXT_DOCUMENT_DID_CHANGE)
    def did_change(ls: SwarmLanguageServer, params: lsp.DidChangeTextDocumentParams):
        uri = params.text_document.uri
        doc = ls.workspace.get_text_document(uri)
        ls.refresh(uri, doc.source, params.text_document.version)

    @server.feature(lsp.TEXT_DOCUMENT_DID_SAVE)
    def did_save(ls: SwarmLanguageServer, params: lsp.DidSaveTextDocumentParams):
        uri = params.text_document.uri
        if uri in ls.docs:   # a model file beside it may have changed
            ls.refresh(uri, ls.docs[uri].analysis.text)

    @server.feature(lsp.TEXT_DOCUMENT_DID_CLOSE)
    def did_close(ls: SwarmLanguageServer, params: lsp.DidCloseTextDocumentParams):
        uri = params.text_document.uri
        ls.docs.pop(uri, None)
        ls.text_document_publish_diagnostics(lsp.PublishDiagnosticsParams(uri=uri,
                                                                          diagnostics=[]))

    @server.feature(lsp.TEXT_DOCUMENT_HOVER)
    def on_hover(ls: SwarmLanguageServer, params: lsp.HoverParams):
        doc = ls.docs.get(params.text_document.uri)
        if doc is None:
            return None
        pos = ls.positions(params.text_document.uri)
        line, col = pos.from_client(params.position)
        analysis = doc.analysis if doc.analysis.parsed else doc.parsed
        if analysis is None or analysis is not doc.analysis and \
                _word_at(doc.analysis.text, pos, line, col) != \
                _word_at(analysis.text, Positions(analysis.text, ls.encoding()), line, col):
            return None   # the old analysis has another word there
        found = hover.hover_text(analysis, line, col)
        if found is None:
            return None
        text, rng = found
        return lsp.Hover(contents=lsp.MarkupContent(kind=lsp.MarkupKind.Markdown, value=text),
                         range=pos.range(rng))

    @server.feature(lsp.TEXT_DOCUMENT_COMPLETION,
                    lsp.CompletionOptions(trigger_characters=[".", ">", " ", "("]))
    def on_completion(ls: SwarmLanguageServer, params: lsp.CompletionParams):
        doc = ls.docs.get(params.text_document.uri)
        if doc is None:
            return None
        pos = ls.positions(params.text_document.uri)
        line, col = pos.from_client(params.position)
        items = complete.completions(doc.parsed, doc.analysis.text, pos.offset(line, col))
        out = []
        for i in items:
            out.append(lsp.CompletionItem(
                label=i.label, kind=_COMPLETION_KIND.get(i.kind), detail=i.detail or None,
                documentation=i.doc, sort_text=f"{i.sort}{i.label}",
                insert_text=i.insert or i.label,
                insert_text_format=lsp.InsertTextFormat.Snippet if i.insert
                else lsp.InsertTextFormat.PlainText))
        return lsp.CompletionList(is_incomplete=False, items=out)

    @server.feature(lsp.TEXT_DOCUMENT_DEFINITION)
    def on_definition(ls: SwarmLanguageServer, params: lsp.DefinitionParams):
        doc, pos, line, col = _at(ls, params)
        if doc is None:
            return None
        return [lsp.Location(uri=params.text_document.uri, range=pos.range(s.range))
                for s in navigate.definition(doc.analysis, line, col)] or None

    @server.feature(lsp.TEXT_DOCUMENT_REFERENCES)
    def on_references(ls: SwarmLanguageServer, params: lsp.ReferenceParams):
        doc, pos, line, col = _at(ls, params)
        if doc is None:
            return None
        return [lsp.Location(uri=params.text_document.uri, range=pos.range(r))
                for r in navigate.references(doc.analysis, line, col,
                                             params.context.include_declaration)]

    @server.feature(lsp.TEXT_DOCUMENT_PREPARE_RENAME)
    def on_prepare_rename(ls: SwarmLanguageServer, params: lsp.PrepareRenameParams):
        doc, pos, line, col = _at(ls, params)
        if doc is None:
            return None
        try:
            occ = navigate.prepare_rename(doc.analysis, line, col)
        except navigate.RenameRefused as why:
            raise _refused(why) from None
        return pos.range(occ.range)

    @server.feature(lsp.TEXT_DOCUMENT_RENAME)
    def on_rename(ls: SwarmLanguageServer, params: lsp.RenameParams):
        doc, pos, line, col = _at(ls, params)
        if doc is None:
            return None
        try:
            edits = navigate.rename(doc.analysis, line, col, params.new_name)
        except navigate.RenameRefused as why:
            raise _refused(why) from None
        return lsp.WorkspaceEdit(changes={params.text_document.uri: [
            lsp.TextEdit(range=pos.range(r), new_text=new) for r, new in edits]})

    @server.feature(lsp.TEXT_DOCUMENT_DOCUMENT_SYMBOL)
    def on_symbols(ls: SwarmLanguageServer, params: lsp.DocumentSymbolParams):
        doc = ls.docs.get(params.text_document.uri)
        if doc is None:
            return None
        pos = ls.positions(params.text_document.uri)

        def convert(item):
            return lsp.DocumentSymbol(name=item.name, detail=item.detail,
                                      kind=getattr(lsp.SymbolKind, item.kind),
                                      range=pos.range(item.range),
                                      selection_range=pos.range(item.selection),
                                      children=[convert(c) for c in item.children])
        return [convert(i) for i in outline.outline(doc.analysis)]

    @server.feature(lsp.TEXT_DOCUMENT_FOLDING_RANGE)
    def on_folding(ls: SwarmLanguageServer, params: lsp.FoldingRangeParams):
        doc = ls.docs.get(params.text_document.uri)
        if doc is None:
            return None
        analysis = doc.analysis if doc.analysis.parsed else doc.parsed or doc.analysis
        return [lsp.FoldingRange(start_line=a, end_line=b,
                                 kind=lsp.FoldingRangeKind.Comment if k == "comment"
                                 else lsp.FoldingRangeKind.Region)
                for a, b, k in outline.folds(analysis)]

    @server.feature(lsp.TEXT_DOCUMENT_SEMANTIC_TOKENS_FULL, LEGEND)
    def on_tokens(ls: SwarmLanguageServer, params: lsp.SemanticTokensParams):
        doc = ls.docs.get(params.text_document.uri)
        if doc is None:
            return lsp.SemanticTokens(data=[])
        pos = ls.positions(params.text_document.uri)
        data, last_line, last_start = [], 0, 0
        for line, col, length, ttype, mods in outline.semantic_tokens(doc.analysis):
            start = pos.position(line, col).character
            end = pos.position(line, col + length).character
            delta_line = line - last_line
            delta_start = start - last_start if delta_line == 0 else start
            bits = sum(1 << outline.TOKEN_MODIFIERS.index(m) for m in mods)
            data += [delta_line, delta_start, end - start, outline.TOKEN_TYPES.index(ttype),
                     bits]
            last_line, last_start = line, start
        return lsp.SemanticTokens(data=data)

    _formatting(server)
    return server


def _formatting(server: SwarmLanguageServer) -> None:
    """`textDocument/formatting`: `swarmdsl fmt` on the document (nothing when it does
    not parse: a formatter that guessed at broken text could change its meaning)."""
    try:
        from swarmdsl.format import format_source
    except ImportError:
        return

    @server.feature(lsp.TEXT_DOCUMENT_FORMATTING)
    def on_format(ls: SwarmLanguageServer, params: lsp.DocumentFormattingParams):
        from swarmdsl.errors import SwarmError

        doc = ls.docs.get(params.text_document.uri)
        if doc is None:
            return None
        text = doc.analysis.text
        try:
            new = format_source(text, doc.analysis.filename)
        except SwarmError:
            return None
        if new == text:
            return []
        pos = ls.positions(params.text_document.uri)
        end = pos.position(len(pos.lines) - 1, len(pos.lines[-1]))
        return [lsp.TextEdit(range=lsp.Range(start=lsp.Position(line=0, character=0),
                                             end=end), new_text=new)]


def _at(ls: SwarmLanguageServer, params):
    doc = ls.docs.get(params.text_document.uri)
    if doc is None:
        return None, None, 0, 0
    pos = ls.positions(params.text_document.uri)
    line, col = pos.from_client(params.position)
    return doc, pos, line, col


def _word_at(text: str, pos: Positions, line: int, col: int) -> str:
    s = pos.lines[line] if line < len(pos.lines) else ""
    col = min(col, len(s))
    a = col
    while a > 0 and (s[a - 1].isalnum() or s[a - 1] == "_"):
        a -= 1
    b = col
    while b < len(s) and (s[b].isalnum() or s[b] == "_"):
        b += 1
    return s[a:b]


def _refused(why: Exception):
    from pygls.exceptions import JsonRpcException

    return JsonRpcException(str(why), code=lsp.LSPErrorCodes.RequestFailed)


def serve_stdio() -> None:
    logging.getLogger("pygls").setLevel(logging.WARNING)
    build_server().start_io()


def serve_ws(host: str, port: int) -> None:
    build_server().start_ws(host, port)
