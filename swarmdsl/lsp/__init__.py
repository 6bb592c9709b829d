"""The language server (`swarmdsl lsp`): the checker's diagnostics, names and types
offered to any editor through the Language Server Protocol.

Every feature reads one `Analysis` of the text (`analysis.py`): the parser's AST, the
checker's resolutions and diagnostics, and an index of every name's occurrences
(`index.py`). Nothing here parses the language a second way. pygls and lsprotocol (the
`lsp` extra) are imported only by `server.py`, so the rest is plain Python that the
studio and the tests call directly.
"""
