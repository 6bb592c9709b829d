"""`swarmdsl studio`: a program's editor, its swarm, sliders and live plots in the browser
(`server.py`, `static/`), and the same view as a notebook widget (`widget.py`).

`session.Session` holds the run both drive; `wire` is the binary frame format. The web
server (starlette, uvicorn) and the widget (anywidget) are the `studio` extra, imported
only by the command and by `swarmdsl.show`.
"""
