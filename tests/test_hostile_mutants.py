"""Shipped programs mutated as a careless user or a generator would: each mutant either
compiles and runs a few ticks, or fails with a located SwarmError; nothing else.

Mutations aim at what broke before: numbers replaced by extreme values, expressions
wrapped in deep or long operator stacks, lines dropped or repeated, a byte-order mark.
The default run draws a few dozen mutants; `-m slow` draws many more.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmdsl.compiler import compile_source
from swarmdsl.compiler.errors import SwarmError
from swarmdsl.runtime.runner import Run

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
SOURCES = {p.name: p.read_text() for p in sorted(PROGRAMS.glob("*.swarm"))}
NUMBER = re.compile(r"(?<![\w.])\d+(\.\d+)?([eE][+-]?\d+)?(?![\w.])")
EXTREME = ["inf", "-inf", "nan", "inf - inf", "1e400", "10 ^ 400", "9 ^ 9 ^ 9", "1e15",
           "1e-300", "-1e300", "0", "-0", "0 ^ -1", "2 ^ 1023 * 2", "1 / 0", "(-1) ^ 0.5",
           "4294967296", "1e16"]
MAX_AGENTS_TO_RUN = 20_000


def _mutate(src: str, data) -> str:
    kind = data.draw(st.sampled_from(["number", "deep", "chain", "drop", "repeat", "bom"]))
    numbers = list(NUMBER.finditer(src))
    if kind in ("number", "deep", "chain") and numbers:
        m = data.draw(st.sampled_from(numbers))
        if kind == "number":
            new = data.draw(st.sampled_from(EXTREME))
        elif kind == "deep":
            depth = data.draw(st.integers(1, 400))
            prefix = data.draw(st.sampled_from(["-", "abs(", "(", "-("]))
            closing = ")" * depth if "(" in prefix else ""
            new = prefix * depth + m.group(0) + closing
        else:
            n = data.draw(st.integers(2, 3000))
            op = data.draw(st.sampled_from([" + ", " * ", " - ", " / "]))
            new = "(" + op.join([m.group(0)] + ["1"] * (n - 1)) + ")"
        return src[:m.start()] + f"({new})" + src[m.end():]
    lines = src.splitlines()
    if kind == "drop" and lines:
        i = data.draw(st.integers(0, len(lines) - 1))
        return "\n".join(lines[:i] + lines[i + 1:])
    if kind == "repeat" and lines:
        i = data.draw(st.integers(0, len(lines) - 1))
        return "\n".join(lines[:i + 1] + [lines[i]] + lines[i + 1:])
    return "\ufeff" + src


def _located(name: str, err: SwarmError) -> None:
    shown = err.render()
    assert re.match(rf"{re.escape(name)}:\d+:\d+: (error|warning)", shown) or \
        err.phase == "option", shown


def _judge(name: str, text: str) -> None:
    try:
        program = compile_source(text, name, program_dir=PROGRAMS)
    except SwarmError as err:
        _located(name, err)
        return
    if sum(k.count for k in program.kinds) > MAX_AGENTS_TO_RUN:
        return  # valid, but too big to run in a test
    try:
        run = Run(program, seed=0, steps=2)
    except SwarmError as err:  # placing agents runs program code
        _located(name, err)
        return
    outcome = run.execute(headless=True)
    assert outcome in ("completed", "fault"), outcome
    if outcome == "fault":
        assert isinstance(run.fault, SwarmError)


def _check_mutants(data) -> None:
    name = data.draw(st.sampled_from(sorted(SOURCES)))
    text = SOURCES[name]
    for _ in range(data.draw(st.integers(1, 3))):
        text = _mutate(text, data)
    _judge(name, text)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_mutated_programs_fail_cleanly_or_run(data):
    _check_mutants(data)


@pytest.mark.slow
@settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_many_mutated_programs_fail_cleanly_or_run(data):
    _check_mutants(data)
