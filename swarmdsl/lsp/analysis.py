"""One analysis of a document's text: what `swarmdsl check` would say about it, plus
the checker's own resolutions kept for the editor features.

`swarmdsl check` compiles (parse -> check -> build) and stops at the first phase that
fails. The server does the same phases in the same order, so every diagnostic has the
line, column and words the command prints, but it keeps the `Checker` even when it
raised: its resolved names and types are what hover, go-to-definition and rename read,
and they are there for every part of the program the checker reached.

Positions here are 0-based lines and 0-based columns counted in characters (Unicode
code points), as the parser counts them; `server.py` converts them to the client's
position encoding (UTF-16 by default).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from swarmdsl.errors import Span, SwarmCheckError, SwarmError
from swarmdsl.lsp.ranges import Diagnostic, Range, Related

__all__ = ["Analysis", "Diagnostic", "Range", "Related", "analyse"]


@dataclass
class Analysis:
    """The text, and what the compiler learned of it (None past the phase that failed)."""

    text: str
    filename: str
    tree: object = None          # ast.Program, when the text parses
    checker: object = None       # the Checker that ran over it (even when it raised)
    info: object = None          # ProgramInfo, when the check passed
    diagnostics: list[Diagnostic] = field(default_factory=list)
    index: object = None         # index.Index of every name's occurrences

    @property
    def parsed(self) -> bool:
        return self.tree is not None


def analyse(text: str, filename: str, program_dir: Path | None = None,
            parser=None) -> Analysis:
    """Parse, check and build `text` as `swarmdsl check FILENAME` would; never raises.

    `parser`: a `chunks.ChunkParser` kept for the document, which parses again only
    the declarations an edit changed (the same tree as the whole parse).

    A bug in swarmdsl met on this text (any exception that is not a SwarmError)
    becomes one diagnostic at the top of the file saying so, rather than a dead server.
    """
    from swarmdsl.compiler import extensions  # noqa: F401  (registers the extensions)
    from swarmdsl.compiler.checker import Checker
    from swarmdsl.compiler.lowering import REFERENCE
    from swarmdsl.compiler.parse import parse
    from swarmdsl.compiler.program import build_program
    from swarmdsl.lsp.index import build_index

    program_dir = program_dir or Path(filename).resolve().parent
    result = Analysis(text, filename)
    errors: list[SwarmError] = []
    try:
        result.tree = parser.parse(text, filename) if parser else parse(text, filename)
        result.checker = Checker(result.tree, filename, {}, program_dir)
        try:
            result.info = result.checker.run()
        except SwarmCheckError as err:
            errors = list(err.diagnostics)
        except SwarmError as err:
            errors = [err]
        if result.info is not None:
            try:
                build_program(result.info, text, program_dir, REFERENCE)
            except SwarmCheckError as err:
                errors = list(err.diagnostics)
            except SwarmError as err:
                errors = [err]
    except SwarmError as err:    # a syntax error: the parser stops at the first
        errors = list(getattr(err, "diagnostics", [err]))
    except RecursionError:
        errors = [SwarmError("the program is nested too deeply to analyse", Span.point(
            filename, 1, 1))]
    except Exception as exc:   # noqa: BLE001  a bug in swarmdsl: say so, keep serving
        errors = [SwarmError(f"internal error: {type(exc).__name__}: {exc} (please report "
                             "this)", Span.point(filename, 1, 1))]
    found = [*errors]
    if result.checker is not None:
        found += result.checker.warnings
    if result.info is not None:
        found += result.info.extra.get("notes", [])
    result.diagnostics = [_diagnostic(e, result) for e in found]
    if result.tree is not None:
        try:
            result.index = build_index(result)
        except Exception as exc:   # noqa: BLE001  features degrade; diagnostics stay
            result.index = None
            result.diagnostics.append(Diagnostic(Range(0, 0, 0, 1), "error",
                                                 f"internal error: {type(exc).__name__}: "
                                                 f"{exc} (please report this)"))
    return result


_LINE_MENTION = re.compile(r"\(?\bline (\d+)\)?")
_QUOTED = re.compile(r"`([A-Za-z_][A-Za-z0-9_]*)`")


def _diagnostic(err: SwarmError, result: Analysis) -> Diagnostic:
    span = err.span or Span.point(result.filename, 1, 1)
    severity = err.severity if err.severity in ("error", "warning") else "information"
    return Diagnostic(Range.of(span), severity, err.message, err.hint,
                      tuple(_related(err.message, result)))


def _related(message: str, result: Analysis) -> list[Related]:
    """The places a message points to by line (`already declared (line 3)`, `bound by
    a let after this (line 9)`): the named thing on that line when the message quotes
    it, else the line itself."""
    lines = result.text.splitlines()
    out = []
    names = _QUOTED.findall(message)
    for m in _LINE_MENTION.finditer(message):
        n = int(m.group(1))
        if not 1 <= n <= len(lines):
            continue
        text = lines[n - 1]
        where = None
        for name in names:
            hit = re.search(rf"\b{re.escape(name)}\b", text)
            if hit:
                where = Range(n - 1, hit.start(), n - 1, hit.end())
                break
        if where is None:
            start = len(text) - len(text.lstrip())
            where = Range(n - 1, start, n - 1, max(len(text), start + 1))
        what = f"`{names[0]}` here" if names else "this line"
        out.append(Related(where, f"{what} (line {n})"))
    return out
