"""Compiler fuzzing: grammar-derived programs and mutants of the shipped programs raise
nothing but SwarmError; the mutants that compile also run 3 ticks raising nothing else.

CI runs a small number of examples; the long run is
`HYPOTHESIS_PROFILE=long python -m pytest -m slow tests/test_fuzz.py`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.lark import from_lark

from swarmdsl.compiler import compile_source
from swarmdsl.compiler.errors import SwarmError
from swarmdsl.compiler.parse import grammar_parser_without_postlex
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = sorted((Path(__file__).resolve().parent.parent / "programs").glob("*.swarm"))

# Names the checker knows (state, statuses, builtins, options) and some it does not.
_NAMES = ["n", "x", "speed", "pos", "velocity", "status", "id", "tick", "count", "sum",
          "mean", "min", "max", "all", "any", "neighbors", "normalize", "random", "idle",
          "busy", "a", "size", "grid", "edges", "wrap", "place", "uniform", "sense",
          "max_speed", "initial", "other", "dist", "dot", "nn", "unit", "heading", "seek"]


def _explicit(grammar) -> dict:
    """Every terminal narrowed to a few spellings, padded with spaces so neighbouring
    tokens lex apart (hypothesis adds ignored whitespace only now and then)."""
    out = {t.name: st.just(f" {t.pattern.value} ") for t in grammar.terminals
           if t.pattern.type == "str"}
    pad = lambda *words: st.sampled_from(words).map(lambda w: f" {w} ")  # noqa: E731
    out.update({
        "NAME": pad(*_NAMES),
        "NUMBER": pad("0", "1", "2", "0.5", "3", "10", "1e3", ".25"),
        "STRING": pad('""', '"models/x.pt"', '"a"'),
        "REGION_KW": pad("region", "food", "obstacle", "nest"),
        "ASSIGN_OP": pad("+=", "-=", "*=", "/="),
        "CMP_OP": pad("<", "<=", "==", "!=", ">", ">="),
        "MUL_OP": pad("*", "/", "%"),
        "_SEP": st.sampled_from(["\n", ";", "\n  "]),
        "WS": st.just(" "),
        "COMMENT": st.just(" # c"),
    })
    return out


FUZZ = settings(deadline=None, suppress_health_check=list(HealthCheck))


def _grammar_programs():
    grammar = grammar_parser_without_postlex()
    return from_lark(grammar, explicit=_explicit(grammar))


def _compile_only_swarm_errors(text: str):
    try:
        return compile_source(text, "fuzz.swarm")
    except SwarmError:
        return None


def _small_enough(prog) -> bool:
    """Mutants can ask for a billion agents or a huge grid; those only compile."""
    w = prog.world
    cells = (w.width / max(w.grid, 1e-9)) * (w.height / max(w.grid, 1e-9))
    return sum(k.count for k in prog.kinds) <= 2000 and cells <= 1e6


def _run_three_ticks(prog):
    if not _small_enough(prog):
        return
    try:
        sim = Simulation(prog, seed=0)
        with np.errstate(all="ignore"):
            sim.run(3)
    except SwarmError:
        pass


@settings(FUZZ, max_examples=30)
@given(_grammar_programs())
def test_grammar_programs_raise_only_swarm_errors(text):
    prog = _compile_only_swarm_errors(text)
    if prog is not None:
        _run_three_ticks(prog)


# ---- mutations ----

def _tokens(text: str) -> list[str]:
    import re

    return re.findall(r"\s+|[A-Za-z_][A-Za-z0-9_]*|\d+(?:\.\d+)?|.", text)


@st.composite
def mutants(draw, text: str):
    """`text` with 1-3 edits: delete, duplicate or swap characters or whole tokens."""
    for _ in range(draw(st.integers(1, 3))):
        by_token = draw(st.booleans())
        units = _tokens(text) if by_token else list(text)
        if len(units) < 2:
            break
        i = draw(st.integers(0, len(units) - 1))
        op = draw(st.sampled_from(["delete", "duplicate", "swap"]))
        if op == "delete":
            del units[i]
        elif op == "duplicate":
            units.insert(i, units[i])
        else:
            j = draw(st.integers(0, len(units) - 1))
            units[i], units[j] = units[j], units[i]
        text = "".join(units)
    return text


@pytest.mark.parametrize("path", PROGRAMS, ids=[p.stem for p in PROGRAMS])
def test_mutants_of_shipped_programs_raise_only_swarm_errors(path):
    source = path.read_text()

    @settings(FUZZ, max_examples=25)
    @given(mutants(source))
    def check(text):
        try:
            prog = compile_source(text, str(path), program_dir=path.parent)
        except SwarmError:
            return
        _run_three_ticks(prog)

    check()


@pytest.mark.slow
@FUZZ
@given(_grammar_programs())
def test_grammar_programs_long(text):
    prog = _compile_only_swarm_errors(text)
    if prog is not None:
        _run_three_ticks(prog)


@pytest.mark.slow
@pytest.mark.parametrize("path", PROGRAMS, ids=[p.stem for p in PROGRAMS])
def test_mutants_long(path):
    source = path.read_text()

    @FUZZ
    @given(mutants(source))
    def check(text):
        try:
            prog = compile_source(text, str(path), program_dir=path.parent)
        except SwarmError:
            return
        _run_three_ticks(prog)

    check()
