"""The optional viewer extra: lazy access to pygame/imageio and the public viz names.

Importing this package imports neither pygame nor imageio, so the compiler, runtime and
headless CLI work without the `viz` extra installed. Each heavy module is imported inside
the function that needs it, through `require_pygame` / `require_imageio`, which turn a
missing package into a `SwarmError` that says how to install it.
"""

from __future__ import annotations

import importlib
import os
from typing import Any

from swarmdsl.errors import SwarmError

__all__ = [
    "FrameRenderer",
    "RenderOptions",
    "VideoWriter",
    "display_available",
    "fit_size",
    "legend_entries",
    "require_imageio",
    "require_pygame",
    "run_viewer",
]

_INSTALL_HINT = "pip install 'swarmdsl[viz]'"

# Public name -> submodule that defines it; resolved on first attribute access (PEP 562)
# so `import swarmdsl.viz` stays cheap and free of optional dependencies.
_LAZY = {
    "FrameRenderer": "frames",
    "RenderOptions": "frames",
    "fit_size": "frames",
    "legend_entries": "palette",
    "run_viewer": "viewer",
    "display_available": "viewer",
    "VideoWriter": "video",
}


def require_pygame() -> Any:
    """Import and return pygame, or raise a SwarmError naming the extra to install.

    Sets `PYGAME_HIDE_SUPPORT_PROMPT` first: pygame otherwise prints a banner to stdout,
    which would corrupt output that other tools parse.
    """
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    return _require("pygame", "the viewer needs pygame")


def require_imageio() -> Any:
    """Import and return `imageio.v3`, or raise a SwarmError naming the extra to install."""
    return _require("imageio.v3", "recording GIF/MP4 needs imageio")


def require_pillow() -> Any:
    """Import and return `PIL.Image` (GIFs are encoded with it) or raise SwarmError."""
    return _require("PIL.Image", "recording GIF needs Pillow")


def require_imageio_ffmpeg() -> Any:
    """Import and return imageio_ffmpeg (ships its own ffmpeg binary) or raise SwarmError."""
    return _require("imageio_ffmpeg", "recording MP4 needs imageio-ffmpeg")


def _require(module: str, needs: str) -> Any:
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise SwarmError(f"{needs}, which is not installed ({exc})",
                         hint=_INSTALL_HINT) from None


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'swarmdsl.viz' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"swarmdsl.viz.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
