"""Performance benchmarks (run by hand, not by CI): `python -m benchmarks.bench_NAME`."""
