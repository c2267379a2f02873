"""All shared datasets against SE-Sync C++'s certified optima (issue 3). Slow: run with -m slow."""
from __future__ import annotations

import pytest

from posecrb.io import load
from posecrb.sesync import solve

REFERENCE = {
    "CSAIL": 31.703715992, "MIT": 61.154116091, "intel": 52.348227593, "kitti_05": 276.51437895,
    "manhattan": 6431.3913895, "kitti_02": 108.35114045, "kitti_00": 125.69351454, "city10000": 638.62462187,
    "ais2klinik": 188.50180666, "tinyGrid3D": 18.519386873, "smallGrid3D": 1025.3980207,
    "parking-garage": 1.2624855350, "sphere2500": 1687.0056783, "sphere_bignoise_vertex3": 2961756.5055,
    "torus3D": 24227.041546, "cubicle": 717.13404328,
}
# Measured disagreements with the reference table, (low, high) relative bounds:
# tinyGrid3D and cubicle: posecrb's certified value is LOWER than SE-Sync's (a feasible estimate,
# objective re-checked edge by edge), i.e. the reference stopped early; parking-garage: posecrb's
# value is 3.1e-5 higher while S + 1e-11 I factors (SDP optimum for these data to ~5e-8),
# so the reference was computed from different data. See the issue-3 report.
KNOWN = {"tinyGrid3D": (-2e-6, 1e-6), "cubicle": (-1.2e-5, 1e-6), "parking-garage": (-1e-6, 3.2e-5)}
TORO = ["csail.toro", "w100.graph", "sphere_smallnoise.graph", "sphere_bignoise.graph", "w10000.graph"]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(REFERENCE))
def test_g2o_dataset_certified_and_optimal(shared_datasets, name):
    res = solve(load(shared_datasets / f"{name}.g2o"))
    assert res.certified, res.reason
    lo, hi = KNOWN.get(name, (-1e-6, 1e-6))
    assert lo <= (res.objective - REFERENCE[name]) / REFERENCE[name] <= hi


@pytest.mark.slow
@pytest.mark.parametrize("name", TORO)
def test_toro_dataset_certified(shared_datasets, name):
    res = solve(load(shared_datasets / "toro" / name))
    assert res.certified, res.reason
    if name == "csail.toro":   # same graph as CSAIL.g2o
        assert res.objective == pytest.approx(REFERENCE["CSAIL"], rel=1e-6)
