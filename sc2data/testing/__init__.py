"""Testing helpers: synthetic datasets and pair sets for tests and benchmarks (not used by the
pipeline itself)."""
