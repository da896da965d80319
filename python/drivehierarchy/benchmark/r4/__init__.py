"""benchmark/r4."""
