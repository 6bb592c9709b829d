"""`swarmdsl lsp` without its extra says how to install it (exit 2), no traceback."""

from __future__ import annotations

import sys

from swarmdsl.cli import main


def test_lsp_without_pygls_names_the_extra(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "pygls", None)     # `import pygls` fails
    assert main(["lsp"]) == 2
    err = capsys.readouterr().err
    assert "swarmdsl lsp needs pygls: pip install 'swarmdsl[lsp]'" in err
    assert "Traceback" not in err
