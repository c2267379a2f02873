"""Property tests of SO(2), SO(3), SE(2), SE(3): one parametrised suite for the four groups.

Each group is described once (``GROUPS``) by the library's closed forms: Exp, Log, composition,
inverse, adjoint and right Jacobian, with Lie algebra coordinates as in docs/design.md#lie-groups
(rotation first for SE(d)). Every test states a group identity that holds exactly in real
arithmetic, so the only slack is rounding; tolerances are bounds on the conditioning of the
checked expression (see ``_tol``), not values read off a run.

Hypothesis runs derandomized with a fixed number of examples, so every CI run checks the same cases.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from posecrb.lie.se import (
    from_homogeneous,
    se2_adjoint,
    se2_exp,
    se2_jr,
    se2_jr_inv,
    se2_log,
    se3_adjoint,
    se3_exp,
    se3_jr,
    se3_jr_inv,
    se3_log,
    se_compose,
    se_inverse,
    to_homogeneous,
)
from posecrb.lie.so import so2_exp, so2_log, so3_exp, so3_jr, so3_jr_inv, so3_log

from ..helpers import hat_ref
from ..numerics import EPS

PROPERTY = settings(derandomize=True, max_examples=50, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])


# ---------------------------------------------------------------- the four groups
# Elements are handled as matrices: the rotation itself for SO(d), the homogeneous matrix for
# SE(d). Composition and inversion of SE(d) go through the library's se_compose / se_inverse.
@dataclass(frozen=True)
class Group:
    name: str
    dof: int                                      # tangent dimension
    rot_dof: int                                  # leading rotation coordinates
    exp: Callable[[np.ndarray], np.ndarray]       # (dof,) -> matrix
    log: Callable[[np.ndarray], np.ndarray]       # matrix -> (dof,)
    compose: Callable[[np.ndarray, np.ndarray], np.ndarray]
    inverse: Callable[[np.ndarray], np.ndarray]
    adjoint: Callable[[np.ndarray], np.ndarray]   # matrix -> (dof, dof)
    jr: Callable[[np.ndarray], np.ndarray]        # (dof,) -> (dof, dof)
    jr_inv: Callable[[np.ndarray], np.ndarray]

    @property
    def identity(self) -> np.ndarray:
        return self.exp(np.zeros(self.dof))


def _se_group(name, dof, rot_dof, exp, log, adjoint, jr, jr_inv) -> Group:
    def compose(a, b):
        return to_homogeneous(*se_compose(*from_homogeneous(a), *from_homogeneous(b)))

    return Group(
        name, dof, rot_dof,
        exp=lambda xi: to_homogeneous(*exp(xi)),
        log=lambda x: log(*from_homogeneous(x)),
        compose=compose,
        inverse=lambda x: to_homogeneous(*se_inverse(*from_homogeneous(x))),
        adjoint=lambda x: adjoint(*from_homogeneous(x)),
        jr=jr, jr_inv=jr_inv,
    )


GROUPS = {
    "SO2": Group(
        "SO2", 1, 1,
        exp=lambda xi: so2_exp(xi[0]),
        log=lambda r: np.array([so2_log(r)]),
        compose=lambda a, b: a @ b,
        inverse=lambda r: r.T,
        adjoint=lambda r: np.ones((1, 1)),         # SO(2) is abelian
        jr=lambda xi: np.ones((1, 1)),
        jr_inv=lambda xi: np.ones((1, 1)),
    ),
    "SO3": Group(
        "SO3", 3, 3,
        exp=so3_exp, log=so3_log,
        compose=lambda a, b: a @ b,
        inverse=lambda r: r.T,
        adjoint=lambda r: r,                       # Ad_R w = R w
        jr=so3_jr, jr_inv=so3_jr_inv,
    ),
    "SE2": _se_group("SE2", 3, 1, se2_exp, se2_log, se2_adjoint, se2_jr, se2_jr_inv),
    "SE3": _se_group("SE3", 6, 3, se3_exp, se3_log, se3_adjoint, se3_jr, se3_jr_inv),
}
NAMES = sorted(GROUPS)


def for_each_group(test):
    """Run ``test(name, data)`` for every group, with hypothesis drawing from ``data``."""
    return pytest.mark.parametrize("name", NAMES)(PROPERTY(given(data=st.data())(test)))


# ---------------------------------------------------------------- strategies
# Rotation angles stay below ANGLE_MAX where Log must invert Exp (Log is only a local inverse; at
# angle pi it is discontinuous) and are unrestricted (up to 3 pi) where only Exp(Log X) = X is used.
ANGLE_MAX = 3.0
TRANS_MAX = 10.0


def _components(k: int, bound: float) -> st.SearchStrategy[list[float]]:
    return st.lists(st.floats(-bound, bound, allow_nan=False, allow_subnormal=False), min_size=k, max_size=k)


@st.composite
def tangents(draw, group: Group, angle_max: float = ANGLE_MAX, trans_max: float = TRANS_MAX) -> np.ndarray:
    """A tangent vector whose rotation part has norm <= angle_max; scaled so that tiny, moderate
    and large rotations are all drawn (the closed forms switch to series near zero)."""
    rot = np.array(draw(_components(group.rot_dof, 1.0)))
    scale = draw(st.sampled_from([0.0, 1e-9, 1e-5, 1e-2, 0.3, 1.0, angle_max]))
    norm = float(np.linalg.norm(rot))
    rot = rot * (scale / norm) if norm > 0 else rot
    trans = np.array(draw(_components(group.dof - group.rot_dof, trans_max)))
    return np.concatenate([rot, trans])


def _tol(*norms: float) -> float:
    """Rounding bound for the identities below: every closed form is accurate to a few ulps relative
    to the size of its entries, and each composition multiplies by matrices whose entries grow like
    (1 + |t|); 64 eps per factor covers the handful of products and the mild conditioning of Log
    (the norm of Jr^-1 is below 1.6 for angles <= 3)."""
    return 64 * EPS * math.prod(1.0 + n for n in norms)


def _norm(x: np.ndarray) -> float:
    return float(np.linalg.norm(x))


# ---------------------------------------------------------------- Exp / Log
@for_each_group
def test_log_inverts_exp_below_angle_pi(name, data):
    g = GROUPS[name]
    xi = data.draw(tangents(g))
    np.testing.assert_allclose(g.log(g.exp(xi)), xi, rtol=0, atol=_tol(_norm(xi), _norm(xi)))


@for_each_group
def test_exp_inverts_log_everywhere(name, data):
    g = GROUPS[name]
    x = g.exp(data.draw(tangents(g, angle_max=3 * math.pi)))
    np.testing.assert_allclose(g.exp(g.log(x)), x, rtol=0, atol=_tol(_norm(x), _norm(x)))


@for_each_group
def test_exp_is_a_one_parameter_subgroup(name, data):
    """Exp(s xi) Exp(u xi) = Exp((s + u) xi)."""
    g = GROUPS[name]
    xi = data.draw(tangents(g, angle_max=1.0))
    s, u = data.draw(st.floats(-2, 2)), data.draw(st.floats(-2, 2))
    lhs = g.compose(g.exp(s * xi), g.exp(u * xi))
    np.testing.assert_allclose(lhs, g.exp((s + u) * xi), rtol=0, atol=_tol(3 * _norm(xi), 3 * _norm(xi)))


def _hat(name: str, xi: np.ndarray) -> np.ndarray:
    """The Lie algebra element of ``xi``, written out here (rotation first for SE(d), as hat_ref)."""
    if name == "SO2":
        return np.array([[0.0, -xi[0]], [xi[0], 0.0]])
    if name == "SO3":
        return hat_ref(np.r_[xi, 0.0, 0.0, 0.0])[:3, :3]
    return hat_ref(xi)


@for_each_group
def test_exp_is_the_matrix_exponential(name, data):
    """Exp(xi) = expm(hat(xi)): the closed forms against scipy's Pade scaling-and-squaring."""
    g = GROUPS[name]
    xi = data.draw(tangents(g))
    n = _norm(xi)
    # expm is accurate to a modest multiple of eps ||hat(xi)|| relative to ||expm|| <= e^{|xi|};
    # on this domain that stays within the closed forms' own bound
    np.testing.assert_allclose(g.exp(xi), expm(_hat(name, xi)), rtol=0, atol=_tol(n, n))


# ---------------------------------------------------------------- group axioms
@for_each_group
def test_exp_and_compose_stay_in_the_group(name, data):
    """Closure: rotation blocks orthonormal with determinant +1, homogeneous last row exactly [0 ... 0 1]."""
    g = GROUPS[name]
    a, b = g.exp(data.draw(tangents(g))), g.exp(data.draw(tangents(g)))
    d = a.shape[0] - (0 if name.startswith("SO") else 1)
    for x in (a, b, g.compose(a, b), g.inverse(a)):
        r = x[:d, :d]
        # orthonormality is preserved by the closed forms to a few ulps (entries of R are <= 1)
        np.testing.assert_allclose(r.T @ r, np.eye(d), rtol=0, atol=_tol(1.0, 1.0))
        assert abs(np.linalg.det(r) - 1.0) <= _tol(1.0, 1.0)
        if d < x.shape[0]:
            np.testing.assert_array_equal(x[d], np.r_[np.zeros(d), 1.0])


@for_each_group
def test_identity_and_inverse(name, data):
    g = GROUPS[name]
    x = g.exp(data.draw(tangents(g)))
    e = g.identity
    np.testing.assert_array_equal(e, np.eye(e.shape[0]))
    np.testing.assert_allclose(g.compose(e, x), x, rtol=0, atol=_tol())
    np.testing.assert_allclose(g.compose(x, e), x, rtol=0, atol=_tol())
    tol = _tol(_norm(x), _norm(x))
    np.testing.assert_allclose(g.compose(x, g.inverse(x)), e, rtol=0, atol=tol)
    np.testing.assert_allclose(g.compose(g.inverse(x), x), e, rtol=0, atol=tol)
    np.testing.assert_allclose(g.inverse(g.inverse(x)), x, rtol=0, atol=tol)
    # the inverse is the matrix inverse (independent of the library's closed form)
    np.testing.assert_allclose(g.inverse(x), np.linalg.inv(x), rtol=0, atol=tol)


@for_each_group
def test_associativity(name, data):
    g = GROUPS[name]
    a, b, c = (g.exp(data.draw(tangents(g))) for _ in range(3))
    lhs = g.compose(g.compose(a, b), c)
    rhs = g.compose(a, g.compose(b, c))
    np.testing.assert_allclose(lhs, rhs, rtol=0, atol=_tol(_norm(a), _norm(b), _norm(c)))
    # and composition is the matrix product
    np.testing.assert_allclose(g.compose(a, b), a @ b, rtol=0, atol=_tol(_norm(a), _norm(b)))


@for_each_group
def test_log_of_inverse_is_minus_log(name, data):
    g = GROUPS[name]
    xi = data.draw(tangents(g))
    np.testing.assert_allclose(g.log(g.inverse(g.exp(xi))), -xi, rtol=0, atol=_tol(_norm(xi), _norm(xi)))


# ---------------------------------------------------------------- adjoint
@for_each_group
def test_adjoint_conjugates_the_exponential(name, data):
    """Exp(Ad_X xi) = X Exp(xi) X^-1."""
    g = GROUPS[name]
    x = g.exp(data.draw(tangents(g)))
    xi = data.draw(tangents(g, angle_max=1.0, trans_max=1.0))
    lhs = g.exp(g.adjoint(x) @ xi)
    rhs = g.compose(g.compose(x, g.exp(xi)), g.inverse(x))
    np.testing.assert_allclose(lhs, rhs, rtol=0, atol=_tol(_norm(x), _norm(x), _norm(x), _norm(xi)))


@for_each_group
def test_adjoint_is_a_homomorphism(name, data):
    """Ad_{XY} = Ad_X Ad_Y and Ad_{X^-1} = Ad_X^-1."""
    g = GROUPS[name]
    x, y = g.exp(data.draw(tangents(g))), g.exp(data.draw(tangents(g)))
    tol = _tol(_norm(x), _norm(x), _norm(y), _norm(y))
    np.testing.assert_allclose(g.adjoint(g.compose(x, y)), g.adjoint(x) @ g.adjoint(y), rtol=0, atol=tol)
    np.testing.assert_allclose(g.adjoint(g.inverse(x)) @ g.adjoint(x), np.eye(g.dof), rtol=0, atol=tol)


# ---------------------------------------------------------------- right Jacobian
_H = 1e-5  # central differences: truncation ~ H^2 |third derivative|, rounding ~ eps |X| / H


@for_each_group
def test_right_jacobian_matches_central_differences(name, data):
    """Jr(xi) d = Log(Exp(xi)^-1 Exp(xi + d)) to first order (right-perturbation convention)."""
    g = GROUPS[name]
    xi = data.draw(tangents(g, angle_max=2.5, trans_max=3.0))
    x_inv = g.inverse(g.exp(xi))
    fd = np.empty((g.dof, g.dof))
    for k in range(g.dof):  # dof <= 6 columns
        step = np.zeros(g.dof)
        step[k] = _H
        plus = g.log(g.compose(x_inv, g.exp(xi + step)))
        minus = g.log(g.compose(x_inv, g.exp(xi - step)))
        fd[:, k] = (plus - minus) / (2 * _H)
    # truncation: the third derivatives of Exp/Log are O((1 + |xi|)^2) on this domain; rounding:
    # each Log carries ~100 eps relative error on entries of size (1 + |xi|)^2, divided by 2 H
    n = _norm(xi)
    tol = _H ** 2 * (1 + n) ** 2 + 100 * EPS / _H * (1 + n) ** 2
    np.testing.assert_allclose(g.jr(xi), fd, rtol=0, atol=tol)


@for_each_group
def test_inverse_right_jacobian(name, data):
    g = GROUPS[name]
    xi = data.draw(tangents(g))
    prod = g.jr_inv(xi) @ g.jr(xi)
    # |Jr^-1| <= 1 + |xi| on this domain, |Jr| <= 1 + |xi|
    np.testing.assert_allclose(prod, np.eye(g.dof), rtol=0, atol=_tol(_norm(xi), _norm(xi), _norm(xi)))


@for_each_group
def test_left_and_right_jacobians_are_related_by_the_adjoint(name, data):
    """Jl(xi) = Ad_{Exp(xi)} Jr(xi), with Jl(xi) = Jr(-xi)."""
    g = GROUPS[name]
    xi = data.draw(tangents(g))
    np.testing.assert_allclose(g.jr(-xi), g.adjoint(g.exp(xi)) @ g.jr(xi), rtol=0,
                               atol=_tol(_norm(xi), _norm(xi), _norm(xi)))
