"""The LALR parser of `grammar.lark`, built once per process (its tables cached between
processes), for `parse.py` and its error messages (`syntax_messages.py`)."""

from __future__ import annotations

import functools

from lark import Lark

from swarmdsl.compiler.grammar_cache import build_cached


class _DropNewlinesInBrackets:
    """Post-lexer: a newline inside ( ) continues the line, as in Python."""

    always_accept = ("_SEP",)

    def process(self, stream):
        depth = 0
        for tok in stream:
            if tok.type == "LPAR":
                depth += 1
            elif tok.type == "RPAR":
                depth = max(depth - 1, 0)
            elif tok.type == "_SEP" and depth > 0:
                if ";" in tok:
                    yield tok  # a `;` inside brackets is a real error; let the parser say so
                continue
            yield tok


@functools.cache
def parser() -> Lark:
    """The LALR parser, built once per process and its tables cached between processes.

    Building the tables costs ~150 ms; loading them from the user's cache folder ~10 ms
    (`grammar_cache.py`).
    """
    return build_cached(functools.partial(
        Lark.open_from_package,
        "swarmdsl",
        "grammar.lark",
        parser="lalr",
        lexer="contextual",
        propagate_positions=True,
        maybe_placeholders=True,
        postlex=_DropNewlinesInBrackets(),
    ), "grammar")


def grammar_parser_without_postlex() -> Lark:
    """The same grammar without the post-lexer, for grammar-driven fuzzing."""
    return Lark.open_from_package(
        "swarmdsl", "grammar.lark", parser="lalr", lexer="contextual", maybe_placeholders=True
    )
