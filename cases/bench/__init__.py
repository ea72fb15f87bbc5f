"""Benchmarks: `python -m cases.bench.NAME` (sgim, pack, meshquery, dda, sphere_block, adapters, study)."""
