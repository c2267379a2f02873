"""Puts benchmarks/ on sys.path, so that the peer scripts import the harness when run as files."""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
