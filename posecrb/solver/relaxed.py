"""The rank-r relaxation of SE-Sync as the trust region sees it: cost, gradient, Hessian-vector product, projection.

``f(Z) = tr(Z^T Q Z)`` on ``St(d, r)^n`` in the row layout of problem.py (``Z_i = Y_i^T``), with
the translations eliminated (SE-Sync, Rosen et al. IJRR 2019, section 4). At a point,
``Lambda = SymBlockDiag(Q Z Z^T)`` blockwise, the Riemannian gradient is
``2 (Q Z - Lambda Z)`` and the Riemannian Hessian ``2 Proj_Z(Q V - Lambda V)`` (SE-Sync eq. 46
in this layout). Preconditioning is not part of the problem: posecrb.solver.policy.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .problem import Problem
from .stiefel import gram_eigh, hessian_blocks, project, sym_block_diag_product, to_components


@dataclass
class State:
    """One evaluated point of the relaxation. The cached layouts below are computed once per
    point: truncated CG applies the Hessian, the projection and the preconditioner many times at
    one point."""

    Z: np.ndarray          # (n, d, r) point
    f: float               # objective
    QZ: np.ndarray         # (n, d, r) Q Z (Euclidean gradient / 2)
    lam: np.ndarray        # (n, d, d) Lambda blocks sym(QZ_i Z_i^T)
    grad: np.ndarray       # (n, d, r) Riemannian gradient

    @cached_property
    def Zt(self) -> np.ndarray:
        """Z component-major, (d, r, n): the layout of the block kernels (stiefel.to_components)."""
        return to_components(self.Z)

    @cached_property
    def lamt(self) -> np.ndarray:
        """Lambda component-major, (d, d, n)."""
        return to_components(self.lam)

    @cached_property
    def gram(self) -> tuple[np.ndarray, np.ndarray]:
        """``gram_eigh(Z)``: the eigenpairs of the r x r Gram matrix ``Z^T Z`` (stiefel.gram_eigh)."""
        return gram_eigh(self.Z)


class RelaxedProblem:
    """The rank-r relaxation ``min tr(Z^T Q Z)`` over ``St(d, r)^n`` of one problem.

    Examples
    --------
    >>> import numpy as np
    >>> from posecrb.sim.generators import grid
    >>> from posecrb.solver.problem import Problem
    >>> from posecrb.solver.relaxed import RelaxedProblem
    >>> from posecrb.solver.stiefel import random_point
    >>> relaxed = RelaxedProblem(Problem.from_graph(grid(2, 3)))
    >>> state = relaxed.evaluate(random_point(9, 2, 3, np.random.default_rng(0)))
    >>> state.grad.shape, bool(state.f > 0)
    ((9, 2, 3), True)
    """

    def __init__(self, problem: Problem) -> None:
        self.problem = problem

    def evaluate(self, Z: np.ndarray) -> State:
        """Cost, Lambda and Riemannian gradient at ``Z`` (n, d, r); the cost is summed edge by
        edge with the optimal translations (problem.objective_from_translations)."""
        p = self.problem
        n, d, r = Z.shape
        Zf = Z.reshape(n * d, r)
        QZf, trans = p.Q_product_and_translations(Zf)
        f = p.objective_from_translations(Zf, trans)
        QZ = QZf.reshape(n, d, r)
        lam = sym_block_diag_product(QZ, Z)
        grad = 2.0 * (QZ - lam @ Z)
        return State(Z, f, QZ, lam, grad)

    def hvp(self, state: State, V: np.ndarray) -> np.ndarray:
        """Riemannian Hessian: ``2 Proj_Z(Q V - Lambda V)`` (SE-Sync eq. 46 in this layout)."""
        n, d, r = V.shape
        QV = self.problem.Q_product(V.reshape(n * d, r)).reshape(n, d, r)
        return hessian_blocks(state.Zt, state.lamt, V, QV)

    def project(self, state: State, W: np.ndarray) -> np.ndarray:
        """Orthogonal projection of W onto the tangent space at ``state``'s point."""
        return project(state.Z, W, state.Zt)
