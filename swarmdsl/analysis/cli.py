"""`swarmdsl graph FILE`: each agent kind's status graph as DOT or Mermaid."""

from __future__ import annotations

import sys
from pathlib import Path

from swarmdsl.command_args import path_arg
from swarmdsl.errors import SwarmOptionError

_SUFFIXES = {".dot": "dot", ".gv": "dot", ".mmd": "mermaid", ".mermaid": "mermaid",
             ".md": "mermaid"}


def register(sub) -> None:
    p = sub.add_parser(
        "graph", help="draw each agent kind's status graph (DOT or Mermaid)",
        description="Print the status graph of every agent kind: statuses, transitions "
        "labelled with their conditions, the initial status, unreachable statuses and "
        "statuses with no way out; and each status's behaviour tree beside it (DOT: "
        "one cluster per tree; Mermaid: one flowchart per tree after the status diagram).")
    p.add_argument("file", type=path_arg("file", "a .swarm program file", text=True),
                   help="the .swarm program")
    p.add_argument("--format", choices=("dot", "mermaid"), help="output format (default: "
                   "from the -o file's suffix, else dot)")
    p.add_argument("--kind", action="append", metavar="NAME",
                   help="only this agent kind; repeatable")
    p.add_argument("-o", "--out", type=path_arg("-o", "a file name, e.g. graph.dot"),
                   metavar="FILE",
                   help="write to FILE (.dot or .gv: DOT; .mmd or .md: Mermaid) instead "
                   "of standard output")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a param; repeatable")
    p.set_defaults(func=cmd_graph)


def cmd_graph(args) -> int:
    from swarmdsl.analysis.render import to_dot, to_mermaid
    from swarmdsl.analysis.tree_render import dot_clusters, mermaid_flowcharts
    from swarmdsl.command_args import parse_sets
    from swarmdsl.compiler import compile_file
    from swarmdsl.compiler.status_graph import kind_graphs

    if args.out is not None:
        from swarmdsl.runtime.outputs import check_file

        check_file(args.out, "-o", example="graph.dot")
    fmt = _format(args.format, args.out)
    program = compile_file(args.file, parse_sets(args.set))
    info = program.info
    graphs = kind_graphs(info.kinds, info.params)
    if args.kind:
        names = [g.kind for g in graphs]
        unknown = [k for k in args.kind if k not in names]
        if unknown:
            raise SwarmOptionError(f"--kind {unknown[0]}: the program has no agent kind "
                                   f"`{unknown[0]}` (kinds: {', '.join(names)})")
        graphs = [g for g in graphs if g.kind in args.kind]
    kinds = {g.kind for g in graphs}
    if fmt == "dot":
        text = to_dot(graphs, program.source, Path(args.file).stem)
        trees = dot_clusters(info, program.source, kinds)
        if trees:   # inside the one digraph, before its closing brace
            text = text[: text.rstrip().rfind("}")] + "\n".join(trees) + "\n}\n"
        charts = [text]
    else:
        charts = [to_mermaid(graphs, program.source),
                  *mermaid_flowcharts(info, program.source, kinds)]
    text = "\n".join(charts)
    if args.out is None:
        sys.stdout.write(text)
    else:
        if args.out.suffix.lower() == ".md" and fmt == "mermaid":
            text = "\n".join(f"```mermaid\n{c}```\n" for c in charts)
        try:
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(text, encoding="utf-8")
        except OSError as exc:
            raise SwarmOptionError(f"-o {args.out}: cannot write: {exc.strerror}") from None
    return 0


def _format(given: str | None, out: Path | None) -> str:
    """The format to write: `--format`, else the -o file's suffix, else DOT. A suffix
    that is not a graph file's (`-o graph.png`), or that contradicts `--format`, is
    refused: the file would hold text that the program its name picks cannot open."""
    if out is None:
        return given or "dot"
    implied = _SUFFIXES.get(out.suffix.lower())
    if implied is None:
        raise SwarmOptionError(f"-o {out}: the file must end in .dot, .gv, .mmd or .md "
                               "(graph writes text; Graphviz draws a picture of it: "
                               "dot -Tpng graph.dot -o graph.png)")
    if given is not None and given != implied:
        raise SwarmOptionError(f"--format {given}: -o {out} names a {implied} file; "
                               f"give -o a {'.dot' if given == 'dot' else '.mmd'} name or "
                               "leave out --format")
    return implied
