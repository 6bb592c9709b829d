"""Compiler fuzzing: grammar-derived programs and mutants of the shipped programs raise
nothing but SwarmError; the mutants that compile also run 3 ticks raising nothing else.
Well-typed generated programs (`welltyped.py`) reach the runtime: they run on both
backends, stop only with a located SwarmError, and end alike.

CI runs a small number of examples; the long run is
`HYPOTHESIS_PROFILE=long python -m pytest -m slow tests/test_fuzz.py`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
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
    except SwarmError as err:
        _assert_located(err, "fuzz.swarm")
        return None


def _assert_located(err: SwarmError, filename: str) -> None:
    """A compile error always points into the program: file:line:col, a quotable line."""
    assert err.span is not None, f"error without a position: {err}"
    assert str(err).startswith(f"{filename}:{err.span.line}:{err.span.col}: error: ")


def _small_enough(prog) -> bool:
    """Mutants can ask for a billion agents or a huge grid; those only compile."""
    w = prog.world
    cells = (w.width / max(w.grid, 1e-9)) * (w.height / max(w.grid, 1e-9))
    return sum(k.count for k in prog.kinds) <= 2000 and cells <= 1e6


OUTCOMES = {"rejected", "too large to run", "ran", "runtime fault"}


def _run_three_ticks(prog) -> str:
    """Run a compiled program 3 ticks; any exception but SwarmError propagates."""
    if not _small_enough(prog):
        return "too large to run"
    try:
        sim = Simulation(prog, seed=0)
        with np.errstate(all="ignore"):
            sim.run(3)
    except SwarmError:
        return "runtime fault"
    assert sim.tick == 3
    return "ran"


def _outcome(text: str) -> str:
    prog = _compile_only_swarm_errors(text)
    return "rejected" if prog is None else _run_three_ticks(prog)


@settings(FUZZ, max_examples=30)
@given(_grammar_programs())
def test_grammar_programs_raise_only_swarm_errors(text):
    assert _outcome(text) in OUTCOMES


# ---- expressions in context ----
# from_lark draws whole programs that are mostly tiny; these draw typed-or-not expressions
# (bounded by st.recursive) into every slot a program has: let, assignment, `when`,
# velocity, per-agent and swarm properties, so the checker and codegen see deep trees.

_ATOMS = st.sampled_from([
    "0", "1", "2.5", "-3", "true", "false", "speed", "pos", "vel", "status", "idle", "busy",
    "u", "b", "v", "n", "tick", "id", "pos.x", "other.pos", "other.u", "dist", "near",
    "neighbors(5)", "random()", "pi", "a", "heading", "max_speed", "count()", "e",
])
_OPS = ["+", "-", "*", "/", "^", "%", "<", "<=", "==", "!=", "and", "or", "where"]
_CALLS = ["count", "sum", "mean", "min", "max", "any", "all", "abs", "sqrt", "normalize",
          "length", "nearest", "clamp", "dot", "rotate", "unit", "chance", "vec", "previous"]


def _grow(inner):
    return st.one_of(
        st.tuples(inner, st.sampled_from(_OPS), inner).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        inner.map(lambda e: f"not {e}"),
        inner.map(lambda e: f"-{e}"),
        st.tuples(st.sampled_from(_CALLS), st.lists(inner, max_size=3)).map(
            lambda t: f"{t[0]}({', '.join(t[1])})"),
        st.tuples(st.sampled_from(_CALLS), inner, inner).map(
            lambda t: f"{t[0]}({t[1]} : {t[2]})"),
        st.tuples(st.sampled_from(["mean", "min", "nearest"]), inner, inner, inner).map(
            lambda t: f"{t[0]}({t[1]} : {t[2]} else {t[3]})"),
        st.tuples(inner, inner).map(lambda t: f"({t[0]}, {t[1]})"),
        st.tuples(inner, inner, inner).map(lambda t: f"(if {t[0]} then {t[1]} else {t[2]})"),
        inner.map(lambda e: f"{e}.x"),
    )


EXPRS = st.recursive(_ATOMS, _grow, max_leaves=6)
_CONTEXT = """param n = 4 in 1..8
world {{ size 50 x 50 }}
agent a {{
  count n
  sense 10
  var u = 1
  var b = false
  var v = (1, 0)
  status idle {{
    let near = neighbors(5)
    let e = {0}
    u = {1}
    when {2} -> busy
  }}
  status busy {{ velocity = {3}; when b -> idle }}
  invariant p: {4}
  eventually r within 3: {5}
}}
invariant q: {6}
"""


_SAFE = ["1", "1", "false", "(0, 0)", "true", "true", "true"]   # well-typed slot fillers


_SLOTS = st.lists(st.one_of(st.none(), st.none(), st.none(), EXPRS), min_size=7, max_size=7)


@settings(FUZZ, max_examples=60)
@given(_SLOTS)
def test_expressions_in_every_slot_raise_only_swarm_errors(slots):
    assert _compile_and_run_slots(slots) in OUTCOMES


@pytest.mark.slow
@FUZZ
@given(_SLOTS)
def test_expressions_in_every_slot_long(slots):
    assert _compile_and_run_slots(slots) in OUTCOMES


def _compile_and_run_slots(slots) -> str:
    """Compile the filled context; run it 3 ticks with its properties checked."""
    filled = [safe if e is None else e for e, safe in zip(slots, _SAFE, strict=True)]
    prog = _compile_only_swarm_errors(_CONTEXT.format(*filled))
    if prog is None:
        return "rejected"
    from swarmdsl.testing import run_program

    result = run_program(prog, 3, stop_at_first=False)
    return "ran" if result.fault is None else "runtime fault"


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


def _check_mutants(path, examples: int | None) -> None:
    """Every mutant of a shipped program is rejected with a located error, or runs."""
    source = path.read_text()
    seen: list[str] = []

    @settings(FUZZ, max_examples=examples) if examples else FUZZ
    @given(mutants(source))
    def check(text):
        try:
            prog = compile_source(text, str(path), program_dir=path.parent)
        except SwarmError as err:
            _assert_located(err, str(path))
            seen.append("rejected")
            return
        seen.append(_run_three_ticks(prog))

    check()
    assert seen and set(seen) <= OUTCOMES


@pytest.mark.parametrize("path", PROGRAMS, ids=[p.stem for p in PROGRAMS])
def test_mutants_of_shipped_programs_raise_only_swarm_errors(path):
    _check_mutants(path, examples=25)


@pytest.mark.slow
@FUZZ
@given(_grammar_programs())
def test_grammar_programs_long(text):
    assert _outcome(text) in OUTCOMES


@pytest.mark.slow
@pytest.mark.parametrize("path", PROGRAMS, ids=[p.stem for p in PROGRAMS])
def test_mutants_long(path):
    _check_mutants(path, examples=None)


# ---- well-typed programs: the runtime on both backends ----
# A grammar alone almost never reaches the runtime (the checker refuses nearly all it
# draws); `welltyped.programs()` draws programs the checker accepts, with aggregates,
# filters, lets, fields, regions and behaviour trees, and each runs on both backends:
# nothing but a located SwarmError may stop it, and both backends must end alike.

from conftest import backend_names, by_id  # noqa: E402
from test_compiled import assert_same_bits  # noqa: E402
from welltyped import programs  # noqa: E402


def _run_on_both_backends(text: str) -> str:
    """Compile (a generated program must compile), run 3 ticks on every installed
    backend: the reference's located fault or none, and its agents, bit for bit."""
    try:
        prog = compile_source(text, "gen.swarm")
    except SwarmError as err:
        raise AssertionError(f"a well-typed program was refused: {err}\n{text}") from err
    sims, faults = [], []
    for backend in backend_names():
        try:
            with np.errstate(all="ignore"):
                sim = Simulation(prog, seed=0, backend=backend)   # placing may fault
                sims.append(sim)
                sim.run(3)
            faults.append(None)
        except SwarmError as err:
            assert err.span is not None, f"a runtime fault without a line: {err}"
            faults.append(str(err))
    assert faults == faults[:1] * len(faults), text
    if faults[0] is None:
        for sim in sims[1:]:
            for col in sims[0].agents.cols:
                assert_same_bits(by_id(sims[0], col), by_id(sim, col), f"{col}\n{text}")
    return "ran" if faults[0] is None else "runtime fault"


# found by the campaign: a fault while placing, before the first tick
_PLACING_FAULT = """world { size 100 x 80 }
agent a { count 1; place uniform; velocity ((0 / (0 + 0 * index)), 0); status a0 { } }
"""


@settings(FUZZ, max_examples=3, derandomize=True)
@given(programs())
@example(_PLACING_FAULT)
def test_well_typed_programs_run_alike_on_both_backends(text):
    assert _run_on_both_backends(text) in OUTCOMES


@pytest.mark.slow
@FUZZ
@given(programs())
def test_well_typed_programs_long(text):
    assert _run_on_both_backends(text) in OUTCOMES
