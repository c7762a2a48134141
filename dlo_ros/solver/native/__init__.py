"""Native code: the compiled Newton drivers (``*.c``), their settings, build and cache."""
