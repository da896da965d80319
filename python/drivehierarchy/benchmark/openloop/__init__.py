"""benchmark/openloop."""
