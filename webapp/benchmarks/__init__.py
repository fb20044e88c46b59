"""Benchmarks that need the whole app (HTTP server, database, media store)."""
