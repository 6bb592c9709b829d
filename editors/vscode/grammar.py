"""Writes `syntaxes/swarm.tmLanguage.json`, the TextMate grammar editors highlight
.swarm files with before (or without) the language server.

Its words come from the compiler: the keywords from the grammar's own terminals
(`compiler/parse.keywords`), the built-in functions, aggregates, actions and long
actions from their tables, so the highlighting knows the language swarmdsl knows
(tests/test_vscode.py fails when the file is out of date). Run from the repository
root after changing the language: `python editors/vscode/grammar.py`.
"""

from __future__ import annotations

import json
from pathlib import Path

OUT = Path(__file__).resolve().parent / "syntaxes" / "swarm.tmLanguage.json"
NAME = r"[A-Za-z_][A-Za-z0-9_]*"
DECLARING = ("param", "var", "attr", "let", "field", "region", "food", "obstacle", "nest",
             "robot", "agent", "tree", "metric", "objective", "invariant", "eventually",
             "always", "status")


def _words(words) -> str:
    return r"\b(?:" + "|".join(sorted(words, key=lambda w: (-len(w), w))) + r")\b"


def build() -> dict:
    from swarmdsl.compiler import extensions  # noqa: F401  (registers their tables)
    from swarmdsl.compiler.actions import ACTIONS
    from swarmdsl.compiler.builtins import AGGREGATES, CONSTANTS, FUNCTIONS
    from swarmdsl.compiler.info import AGENT_STATE, GLOBAL_STATE
    from swarmdsl.compiler.parse import keywords
    from swarmdsl.compiler.tree_ast import LONG_ACTIONS
    from swarmdsl.compiler.typing_rules import CALL_RULES

    words = set(keywords())
    literals = {"true", "false"}
    operators = {"and", "or", "not"}
    control = words - literals - operators
    functions = {*FUNCTIONS, *AGGREGATES, *ACTIONS, *LONG_ACTIONS, *CALL_RULES,
                 "neighbors", "neighbours"}
    return {
        "$schema": "https://raw.githubusercontent.com/martinring/tmlanguage/master/"
                   "tmlanguage.json",
        "name": "swarmdsl",
        "scopeName": "source.swarm",
        "fileTypes": ["swarm"],
        "patterns": [
            {"include": "#comment"}, {"include": "#string"}, {"include": "#declaration"},
            {"include": "#transition"}, {"include": "#member"}, {"include": "#number"},
            {"include": "#literal"},
            {"include": "#keyword"}, {"include": "#call"}, {"include": "#state"},
            {"include": "#operator"},
        ],
        "repository": {
            "comment": {"name": "comment.line.number-sign.swarm", "match": "#.*$"},
            "string": {"name": "string.quoted.double.swarm", "match": r'"[^"\n]*"'},
            "number": {"name": "constant.numeric.swarm",
                       "match": r"(?<![A-Za-z0-9_.])(?:\d+(?:\.\d+)?|\.\d+)"
                                r"(?:[eE][+-]?\d+)?"},
            "literal": {"name": "constant.language.swarm", "match": _words(literals)},
            "declaration": {
                "match": rf"\b((?:final\s+)?(?:{'|'.join(DECLARING)}))\s+"
                         rf"(?!{_words(words)})({NAME})",
                "captures": {"1": {"name": "keyword.other.declaration.swarm"},
                             "2": {"name": "entity.name.swarm"}}},
            "transition": {
                "match": rf"(->)\s*({NAME})",
                "captures": {"1": {"name": "keyword.operator.transition.swarm"},
                             "2": {"name": "entity.name.tag.status.swarm"}}},
            "member": {"name": "variable.other.member.swarm",
                       "match": rf"(?<=\.){NAME}"},
            "keyword": {"patterns": [
                {"name": "keyword.operator.word.swarm", "match": _words(operators)},
                {"name": "keyword.control.swarm", "match": _words(control)},
            ]},
            "call": {"patterns": [
                {"match": rf"{_words(functions)}(?=\s*\()",
                 "name": "support.function.builtin.swarm"},
                {"match": rf"\b{NAME}(?=\s*\()", "name": "entity.name.function.swarm"},
            ]},
            "state": {"patterns": [
                {"name": "variable.language.swarm",
                 "match": _words({"other", "dist", *AGENT_STATE, *GLOBAL_STATE})},
                {"name": "constant.other.swarm", "match": _words(CONSTANTS)},
            ]},
            "operator": {"name": "keyword.operator.swarm",
                         "match": r"->|\.\.|[-+*/]=|[<>]=|==|!=|[-+*/%^<>=]"},
        },
    }


def main() -> None:
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(build(), indent=2) + "\n")


if __name__ == "__main__":
    main()
