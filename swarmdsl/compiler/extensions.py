"""Imports the modules that extend the core language (each registers its names, calls,
actions and options in the tables of checker, codegen and runtime)."""
