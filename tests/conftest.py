"""Shared fixtures: the real datasets ($POSECRB_DATA) and small random pose graphs."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from .helpers import make_random_graph


@pytest.fixture(scope="session")
def shared_datasets() -> Path:
    """The first directory of $POSECRB_DATA: the real datasets (see docs/getting-started.md); skip without it."""
    first = os.environ.get("POSECRB_DATA", "").split(os.pathsep)[0]
    if not first or not Path(first).is_dir():
        pytest.skip("real-data tests need $POSECRB_DATA pointing at the datasets directory")
    return Path(first)


@pytest.fixture
def isolated_cache(tmp_path, monkeypatch) -> Path:
    """The user cache points into tmp_path and $POSECRB_DATA is unset, so a real
    ~/.cache/posecrb or data directory cannot change results; returns the cache directory."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    return tmp_path / "xdg" / "posecrb"


@pytest.fixture
def random_graph():
    return make_random_graph
