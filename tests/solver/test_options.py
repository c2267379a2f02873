"""SolverOptions: the typed options of ``solve`` and its keyword form."""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.core.errors import UsageError
from posecrb.sim.random_graphs import random_graph
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


# ---- the preconditioner: one typed choice, expert settings, the keywords of earlier versions ----

@pytest.mark.parametrize(("keywords", "choice", "settings"), [
    ({"precondition": False}, "none", {}),
    ({"precondition": True}, "auto", {}),
    ({"tangent_precond": None}, "auto", {}),
    ({"tangent_precond": True}, "tangent", {}),
    ({"tangent_precond": False}, "base", {}),
    ({"precondition": False, "tangent_precond": True}, "none", {}),
    ({"base_precond": "rotation"}, "auto", {"base": "rotation"}),
    ({"precond_max_cond": 1e4}, "auto", {"max_condition": 1e4}),
    ({"adaptive_precond": None}, "auto", {"adaptive_shift": None}),
    ({"refactor_hvps": 5}, "auto", {"refactor_hvps": 5}),
    ({"split_precond": False}, "auto", {"split_after_escape": False}),
    ({"tangent_precond": False, "base_precond": "schur", "adaptive_precond": None}, "base",
     {"base": "schur", "adaptive_shift": None}),
])
def test_the_old_preconditioner_keywords_still_work_and_name_their_new_form(keywords, choice, settings):
    from posecrb.solver import PreconditionerSettings

    with pytest.warns(DeprecationWarning) as record:
        opts = SolverOptions.from_keywords(**keywords)
    assert opts.preconditioner == choice
    assert opts.preconditioner_settings == PreconditionerSettings(**settings)
    messages = [str(w.message) for w in record]
    assert len(messages) == len(keywords)
    for name in keywords:
        message = next(m for m in messages if f"solve({name}=" in m)
        assert ("preconditioner=" if name in ("precondition", "tangent_precond") else "PreconditionerSettings(") \
            in message


def test_an_old_keyword_solves_as_its_new_form():
    from posecrb.solver import PreconditionerSettings

    g = random_graph(np.random.default_rng(3), 30, 60, 3, info="isotropic", noise="isotropic")
    with pytest.warns(DeprecationWarning):
        old = solve(g, tangent_precond=False, base_precond="rotation", refactor_hvps=2)
    new = solve(g, preconditioner="base", preconditioner_settings=PreconditionerSettings(base="rotation",
                                                                                         refactor_hvps=2))
    assert old.objective == new.objective and old.hessian_vector_products == new.hessian_vector_products
    assert old.preconditioner_solves == new.preconditioner_solves and "rotation" in new.preconditioner_solves
    with pytest.warns(DeprecationWarning, match="preconditioner='none'"):
        bare = solve(g, precondition=False)
    assert bare.preconditioner_solves == {} and bare.objective == solve(g, preconditioner="none").objective


def test_the_library_passes_old_keywords_through_with_their_warning():
    import posecrb

    g = random_graph(np.random.default_rng(4), 20, 40, 2, info="isotropic", noise="isotropic")
    with pytest.warns(DeprecationWarning, match=r"solve\(tangent_precond=False\) is deprecated; "
                                                r"use solve\(preconditioner='base'\)"):
        res = posecrb.solve(g, tangent_precond=False)
    assert res.certified and set(res.preconditioner_solves) <= {"schur", "adaptive"}


def test_preconditioner_choices_and_settings_are_checked():
    from posecrb.solver import PreconditionerSettings

    with pytest.raises(UsageError, match="unknown preconditioner 'jacobi'"):
        SolverOptions(preconditioner="jacobi")  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="preconditioner_settings must be"):
        SolverOptions(preconditioner_settings={"base": "schur"})  # type: ignore[arg-type]
    for bad in ({"max_condition": 1.0}, {"max_condition": float("nan")}, {"adaptive_shift": -1.0},
                {"refactor_hvps": -1}, {"refactor_hvps": 2.5}, {"split_after_escape": "no"}):
        with pytest.raises(UsageError):
            PreconditionerSettings(**bad)
    # an old keyword next to its replacement is ambiguous
    with pytest.raises(UsageError, match="preconditioner= alone"):
        SolverOptions.from_keywords(preconditioner="base", tangent_precond=True)
    with pytest.raises(UsageError, match="preconditioner_settings= alone"):
        SolverOptions.from_keywords(preconditioner_settings=PreconditionerSettings(), split_precond=False)
    with pytest.raises(UsageError, match="tangent_precond must be"):
        SolverOptions.from_keywords(tangent_precond="yes")
