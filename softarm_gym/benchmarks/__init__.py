"""Benchmarks behind ``softarm bench`` (solver, peers, environments)."""
