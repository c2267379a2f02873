"""Hostile pose-graph inputs (generated; see corpus.py) for tests/hostile/test_hostile_input.py."""
