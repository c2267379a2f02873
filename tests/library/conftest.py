"""The library tests' fixture: one instance of every public result type (the session's ``public_results``)."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def results(public_results):
    return public_results
