"""The language's operators and built-in functions: one row each, with every evaluator.

A row holds what the checker, the constant folder, the numpy closures and the numba
kernels each need of one operator or function: its type rule, its value on constants,
its array kernel and its scalar form (a plain function numba compiles when a kernel
first uses it). Compiler and backends both read these tables, and this package
imports numpy alone (no compiler, no backend, no numba), so adding a builtin or an
operator is one row here. `tests/test_ops_rows.py` checks that every row's evaluators
agree bit for bit on edge values.
"""
