"""The compiler pipeline: text -> AST -> checked ProgramInfo -> Program of closures."""

from __future__ import annotations

from pathlib import Path

from swarmdsl.errors import SwarmError, SwarmOptionError


def compile_source(text: str, filename: str = "<string>", overrides=None,
                   program_dir: Path | None = None, *, lowering=None):
    """Parse, check and compile program text; errors carry the source for rendering.

    `lowering` (`compiler/lowering.py`) puts a backend's own closures in place of the
    reference ones now (`lowering.REFERENCE`: never); without it the program holds the
    reference closures, and a backend that has its own lowers the program when its
    first run starts (`Program.lower`). `swarmdsl check` never runs the program, so it
    lowers nothing (planning the numba paths imports the compiled backend's modules)."""
    from swarmdsl.compiler import extensions  # noqa: F401  (registers language extensions)
    from swarmdsl.compiler.checker import check
    from swarmdsl.compiler.parse import parse
    from swarmdsl.compiler.program import build_program

    text = text.removeprefix("\ufeff")  # a UTF-8 byte-order mark is not program text
    try:
        program_dir = program_dir or Path(filename).resolve().parent
        tree = parse(text, filename)
        info = check(tree, filename, overrides or {}, program_dir)
        return build_program(info, text, program_dir, lowering)
    except SwarmError as err:
        raise err.with_source(text) from None


def compile_file(path, overrides=None, *, lowering=None):
    """Compile the `.swarm` file at `path` (`lowering`: as `compile_source`)."""
    from swarmdsl.files import MAX_PROGRAM_BYTES, ContainmentError, read_regular

    if not str(path).strip():   # Path("") is the current folder
        raise SwarmOptionError("no program file given: the path is empty")
    p = Path(path)
    if not p.exists():
        raise SwarmOptionError(f"no such program file: {path}")
    if p.is_dir():
        raise SwarmOptionError(f"{path} is a folder, not a .swarm file")
    try:
        data = read_regular(p, "program file", MAX_PROGRAM_BYTES, str(path))
    except ContainmentError as exc:  # a FIFO, a device, or megabytes of text
        raise SwarmOptionError(exc.message) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _not_utf8(str(path), data, exc) from None
    return compile_source(text, str(path), overrides, p.resolve().parent, lowering=lowering)


def _not_utf8(filename: str, data: bytes, exc: UnicodeDecodeError):
    """A located error at the first byte that is not UTF-8 (the text before it is)."""
    from swarmdsl.errors import Span, SwarmSyntaxError, lone_cr_as_newline

    before = lone_cr_as_newline(data[:exc.start].decode("utf-8"))
    line = before.count("\n") + 1
    col = len(before) - (before.rfind("\n") + 1) + 1
    text = before + data[exc.start:].decode("utf-8", errors="replace")
    err = SwarmSyntaxError(f"the file is not UTF-8 text: byte 0x{data[exc.start]:02x} here; "
                           "save it as UTF-8", Span.point(filename, line, col))
    return err.with_source(text)
