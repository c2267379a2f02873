"""Shared fixtures: the real datasets ($POSECRB_DATA) and small random pose graphs."""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from .fileserver import server  # noqa: F401 -- a fixture for every test folder
from .helpers import make_random_graph

if TYPE_CHECKING:
    from posecrb.core.result import Result


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


@pytest.fixture(scope="session")
def public_results(tmp_path_factory) -> dict[str, Result]:
    """One instance of every public result type, from the library's own calls on small graphs (2D and
    3D), parts included."""
    import posecrb

    d = tmp_path_factory.mktemp("protocol")
    for name in ("g2d.g2o", "g3d.g2o"):
        shutil.copy(Path(__file__).resolve().parent / "data" / "cli_json" / name, d)
    g2, g3 = posecrb.load(d / "g2d.g2o"), posecrb.load(d / "g3d.g2o")
    sol = posecrb.solve(g2)
    bounds = posecrb.bounds(g3)
    select = posecrb.select(g2, budget=0.5, certify=True, objective="fim", estimate=sol)
    crlb3 = posecrb.crlb(g3, poses="all")
    line = posecrb.timeline(g3, estimate="vertices", every=2)
    out: dict[str, Result] = {
        "SolveResult": sol, "BoundsResult": bounds, "GraphBounds": bounds.bounds, "FimAtEstimate": bounds.fim,
        "FimResult": posecrb.fim(g3, model="sed", frame="body"), "CrlbResult": crlb3, "InverseAccuracy": crlb3.accuracy,
        "SelectResult": select, "FixedEdges": select.fixed, "SelectionCertificate": select.certificate,
        "CertificateBounds": select.certificate.bounds, "Estimate": posecrb.Estimate(sol.rot, sol.trans),
        "TimelineResult": line, "LoopClosure": line.closures[0], "Monotonicity": line.monotonicity["lb"]["raw"],
        "VerifyResult": posecrb.verify(g2, sol),
    }
    return out
