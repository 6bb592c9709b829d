"""The package version, in a module of its own: what run outputs, checkpoints and kernel
caches record, read without importing anything else of the package."""

__version__ = "0.1.0"
