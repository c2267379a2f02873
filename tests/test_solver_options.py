"""SolverOptions: the typed options of ``solve`` and its keyword form."""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.core.errors import UsageError
from posecrb.sim.generators import random_graph
from posecrb.solver import SolverOptions, solve
from posecrb.solver.trust_region import TROptions


def test_keyword_form_maps_trust_region_fields_and_rejects_unknown_names():
    opts = SolverOptions.from_keywords(anchor=2, theta=1.0, decrement_tol=1e-9)
    assert opts.anchor == 2 and dict(opts.trust_region) == {"theta": 1.0, "decrement_tol": 1e-9}
    assert TROptions(max_iterations=opts.max_iterations, **opts.trust_region).theta == 1.0
    with pytest.raises(UsageError, match="bogus"):
        SolverOptions.from_keywords(bogus=1)
    with pytest.raises(UsageError, match="bogus"):
        SolverOptions(trust_region={"bogus": 1})
    with pytest.raises(UsageError):
        solve(random_graph(np.random.default_rng(0), 5, 6, 2), not_an_option=3)


def test_typed_and_keyword_calls_give_the_same_estimate():
    g = random_graph(np.random.default_rng(7), 12, 20, 3, info="isotropic", noise="isotropic")
    a = solve(g, SolverOptions(anchor=3, rmax=6))
    b = solve(g, anchor=3, rmax=6)
    c = solve(g, SolverOptions(anchor=0), anchor=3, rmax=6)   # keywords refine the options
    for other in (b, c):
        assert other.objective == a.objective and np.array_equal(other.rot, a.rot)
    assert np.allclose(a.rot[3], np.eye(3), atol=0) and np.all(a.trans[3] == 0)
