"""The parse rules language extensions add: parse-tree -> AST methods that `parse.ToAst`
takes on, registered by the module that owns the syntax.

Why a registry rather than `parse.py` importing each extension's rules: a statement or
declaration of its own syntax is then its grammar rule and its module (AST class, parse
rule, check, compile, row) and nothing in the parser. The core's tree syntax registers
here like any other; `parse.py` imports the extensions (`compiler/extensions.py`) only
when a parse meets a rule no method builds yet, so formatting or parsing a program
without extension syntax loads no more than before.
"""

from __future__ import annotations

MIXINS: list[type] = []


def register(mixin: type) -> type:
    """Class decorator: `mixin`'s public methods are `ToAst` rules named after grammar
    rules, called as `rule(self, meta, children)` with `ToAst`'s helpers on `self`."""
    MIXINS.append(mixin)
    return mixin
