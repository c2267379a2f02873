"""Hostile pose-graph inputs (generated; see corpus.py) for tests/test_hostile.py."""
