"""Mistakes a first-time user of the language makes, each reported once, where it was
made, in the user's words: what a new-user pass over docs/language*.md found."""

from __future__ import annotations

import pytest

from swarmdsl.compiler.errors import SwarmError


def _errors(compile_src, text: str) -> list[str]:
    """Every error the checker reports for `text`, as `line:col: message`."""
    with pytest.raises(SwarmError) as err:
        compile_src(text)
    found = getattr(err.value, "diagnostics", [err.value])
    return [f"{d.span.line}:{d.span.col}: {d.message}" for d in found]


_STATUS_USING = {
    "map seen 10 0": "note(seen, 1); v = recall(seen)",
    "memory trail 0": "remember(trail); v = len(trail)",
    "memory trail 5; memory path 5": "v = len(trail) + len(path)",
    "message x": "broadcast(x, 1); v = max(heard() : msg.x)",
}


@pytest.mark.parametrize("option", list(_STATUS_USING))
def test_a_refused_kind_declaration_is_the_only_error(compile_src, option):
    """A map, memory or message line that is refused used to be followed by an
    "unknown name" (or "not in the message") error at every use of what it declared,
    hinting `speed` for `seen`: one mistake read as several."""
    text = (f"agent a {{ count 3; {option}; var v = 0\n"
            f"  status s {{ {_STATUS_USING[option]} }} }}\n")
    errors = _errors(compile_src, text)
    assert len(errors) == 1, errors
    assert errors[0].startswith("1:")


@pytest.mark.parametrize("shape", ["circle(50, 50, -5)", "rect(60, 60, 10, 10)",
                                   "circle(50, 50)", "square(1, 2, 3)"])
def test_a_refused_region_is_the_only_error(compile_src, shape):
    """A region whose shape is refused is not also an unknown name where it is used."""
    text = (f"world {{ size 100 x 100 }}\nregion z = {shape}\n"
            "agent a { count 3; var b = false; status s { b = inside(z) } }\n")
    assert [e[:4] for e in _errors(compile_src, text)] == ["2:12"]


def test_a_misspelt_name_is_still_unknown_beside_a_refused_map(compile_src):
    """Only the refused declaration's own name is spared its "unknown name"."""
    text = "agent a { count 3; map seen 10 0; var v = 0\n  status s { v = recall(sen) } }\n"
    assert _errors(compile_src, text)[1] == "2:25: unknown name `sen`"
