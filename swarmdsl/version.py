"""The package version, in a module of its own: what run outputs, checkpoints and kernel
caches record, read without importing anything else of the package."""

__version__ = "0.1.0"


def libraries() -> str:
    """The versions that computed a run, beside swarmdsl's own: Python and the array
    libraries (read from the installed packages' metadata, nothing imported). The bits
    do not depend on them (docs/backends.md); they say what ran, for the record."""
    import platform
    from importlib import metadata

    parts = [f"python {platform.python_version()}"]
    for name in ("numpy", "numba", "scipy", "torch"):
        try:
            parts.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            continue
    return ", ".join(parts)
