"""Riemannian truncated-Newton trust region with preconditioned Steihaug-Toint CG.

Absil, Baker & Gallivan, "Trust-region methods on Riemannian manifolds" (2007), with
the tCG of Steihaug (1983) / Toint (1981) as in Manopt's ``trustregions``/``tCG``: the
trust region is measured in the norm induced by the inverse preconditioner, which
is tracked through the recurrences (no extra operator applications). SE-Sync runs
this method at every level of the Riemannian staircase (Rosen et al., Algorithm 1).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .relaxed import State
from .stiefel import inner, retract

log = logging.getLogger("posecrb")


# The relative decrease of f below which an accepted step is "converging": the default of
# TROptions.certified_rel_decrease, and what the preconditioner's prepare() is told when that option is None.
CONVERGING_REL_DECREASE = 1e-9


class Objective(Protocol):
    """What the trust region needs of a problem on St(d, r)^n (posecrb.solver.relaxed.RelaxedProblem)."""

    def evaluate(self, Z: np.ndarray) -> State: ...

    def hvp(self, state: State, V: np.ndarray) -> np.ndarray: ...

    def project(self, state: State, W: np.ndarray) -> np.ndarray: ...


class Preconditioning(Protocol):
    """What the trust region needs of a preconditioner (posecrb.solver.policy.PreconditionerPolicy)."""

    def prepare(self, state: State, last_hvps: int | None = None, converging: bool = False) -> None: ...

    def apply(self, state: State, R: np.ndarray) -> np.ndarray: ...

    def exact(self, state: State) -> bool: ...

    def certified(self, state: State) -> bool: ...


class _Identity:
    """No preconditioner."""

    def prepare(self, state: State, last_hvps: int | None = None, converging: bool = False) -> None:
        return None

    def apply(self, state: State, R: np.ndarray) -> np.ndarray:
        return R

    def exact(self, state: State) -> bool:
        return False

    def certified(self, state: State) -> bool:
        return False


@dataclass
class TROptions:
    max_iterations: int = 500
    max_inner: int = 1000
    kappa: float = 0.1           # tCG linear convergence target
    # tCG superlinear exponent: ||r|| <= ||r0|| min(kappa, ||r0||^theta). 0.5 rather than Manopt's 1:
    # fewer products per run on ill-conditioned levels (2D 10^5-pose grid at rank 4: 794 -> 467 HVPs;
    # ais2klinik 283 -> 237) with the same stopping tests, so the same optimum.
    theta: float = 0.5
    rho_accept: float = 0.1
    grad_tol: float = 0.0        # absolute Riemannian gradient norm
    # Stop when 0.5 <g, P g> <= decrement_tol * max(|f|, 1). Kept tight: 1e-9 saved ~20% of the
    # Hessian-vector products but moved f by up to 2.3e-10 relatively, which the trace of the CRLB
    # at the estimate amplified to 7e-6 on sphere_bignoise (regress tolerance 1e-6).
    decrement_tol: float = 1e-11
    # The same stop where the preconditioner is the exact inverse Hessian (its ``exact(state)``):
    # the decrement is then the distance f - f* itself to second order, which other
    # preconditioners overestimate, so the test stops only at its rounding level;
    # one more Newton step costs a product or two (posecrb.solver.tangent; intel's CRLB at the
    # estimate agrees with a converged one to 1.5e-11 relative, against 1.4e-7 at 1e-11).
    exact_decrement_tol: float = 1e-15
    rel_decrease_tol: float = 1e-12
    step_tol: float = 0.0
    delta0: float | None = None
    # Stop as soon as an accepted iterate is certified (the preconditioner's factorization
    # there proves lambda_min(Q - Lambda) >= -eta) and its step decreased f by at most this much,
    # relatively: past that point further iterations only polish a certified optimum (they
    # changed f by < 1e-10 relatively where measured), and they are the slowest ones at a
    # rank-deficient optimum (after a staircase escape). None: never.
    certified_rel_decrease: float | None = CONVERGING_REL_DECREASE


@dataclass
class TRResult:
    state: State
    iterations: int
    hvps: int
    status: str


def _tcg(objective: Objective, precond: Preconditioning, state: State, delta: float,
         opt: TROptions) -> tuple[np.ndarray, np.ndarray, int, str, bool]:
    """Steihaug-Toint truncated CG on the trust-region subproblem; returns (eta, Heta, hvps, reason, boundary)."""
    grad = state.grad
    eta = np.zeros_like(grad)
    Heta = np.zeros_like(grad)
    r = grad
    r_r = inner(r, r)
    norm_r0 = math.sqrt(r_r)
    z = precond.apply(state, r)
    z_r = inner(z, r)
    d_Pd = z_r
    delta_dir = -z
    e_Pd = 0.0
    e_Pe = 0.0
    model_value = 0.0
    hvps = 0
    stop = norm_r0 * min(opt.kappa, norm_r0 ** opt.theta)
    for _j in range(opt.max_inner):
        Hd = objective.hvp(state, delta_dir)
        hvps += 1
        d_Hd = inner(delta_dir, Hd)
        alpha = z_r / d_Hd if d_Hd != 0 else math.inf
        e_Pe_new = e_Pe + 2.0 * alpha * e_Pd + alpha * alpha * d_Pd
        if d_Hd <= 0 or e_Pe_new >= delta * delta:
            tau = (-e_Pd + math.sqrt(max(e_Pd * e_Pd + d_Pd * (delta * delta - e_Pe), 0.0))) / d_Pd
            eta = eta + tau * delta_dir
            Heta = Heta + tau * Hd
            return eta, Heta, hvps, ("negative curvature" if d_Hd <= 0 else "exceeded radius"), True
        new_eta = eta + alpha * delta_dir
        new_Heta = Heta + alpha * Hd
        new_model = inner(new_eta, grad) + 0.5 * inner(new_eta, new_Heta)
        if new_model >= model_value:
            return eta, Heta, hvps, "model increased", False
        eta, Heta, e_Pe, model_value = new_eta, new_Heta, e_Pe_new, new_model
        r = r + alpha * Hd
        r_r = inner(r, r)
        if math.sqrt(r_r) <= stop:
            return eta, Heta, hvps, "converged", False
        z = precond.apply(state, r)
        zold_rold = z_r
        z_r = inner(z, r)
        beta = z_r / zold_rold
        w = beta * delta_dir - z
        delta_dir = objective.project(state, w)
        e_Pd = beta * (e_Pd + alpha * d_Pd)
        d_Pd = z_r + beta * beta * d_Pd
    return eta, Heta, hvps, "max inner", False


def trust_region(objective: Objective, Z0: np.ndarray, opt: TROptions, state: State | None = None,
                 preconditioner: Preconditioning | None = None) -> TRResult:
    """Minimise ``objective`` on St(d, r)^n from Z0 (or a given evaluated state), preconditioned by
    ``preconditioner`` (None: not at all)."""
    precond: Preconditioning = _Identity() if preconditioner is None else preconditioner
    x = state or objective.evaluate(Z0)
    hvps = 0
    precond.prepare(x)
    pg = precond.apply(x, x.grad)
    decrement = 0.5 * inner(pg, x.grad)
    delta = opt.delta0 if opt.delta0 is not None else max(math.sqrt(2.0 * max(decrement, 1e-300)), 1e-12)
    delta_max = 1e6 * delta
    status = "iteration limit"
    # a step this small marks a converging iterate (the preconditioner may try to certify there)
    converged_rel = (opt.certified_rel_decrease if opt.certified_rel_decrease is not None
                     else CONVERGING_REL_DECREASE)
    it = 0
    for it in range(1, opt.max_iterations + 1):
        gnorm = math.sqrt(inner(x.grad, x.grad))
        if gnorm <= opt.grad_tol:
            status = "gradient norm"
            it -= 1
            break
        exact = precond.exact(x)
        if decrement <= (opt.exact_decrement_tol if exact else opt.decrement_tol) * max(abs(x.f), 1.0):
            status = "Newton decrement"
            it -= 1
            break
        eta, Heta, k, reason, boundary = _tcg(objective, precond, x, delta, opt)
        hvps += k
        model_decrease = -(inner(x.grad, eta) + 0.5 * inner(eta, Heta))
        cand = objective.evaluate(retract(x.Z, eta))
        reg = max(1.0, abs(x.f)) * np.finfo(float).eps * 1e3
        rho = (x.f - cand.f + reg) / (model_decrease + reg)
        step = math.sqrt(inner(eta, eta))
        accepted = rho > opt.rho_accept and cand.f <= x.f
        if rho < 0.25 or not accepted:
            delta *= 0.25
        elif rho > 0.75 and boundary:
            delta = min(2.0 * delta, delta_max)
        log.debug("TR it %d f=%.12g |g|=%.3e dec=%.3e rho=%.3f delta=%.3e tCG %d (%s)%s", it, x.f, gnorm,
                  decrement, rho, delta, k, reason, "" if accepted else " rejected")
        if accepted:
            rel = (x.f - cand.f) / max(abs(x.f), 1e-300)
            x = cand
            precond.prepare(x, k, rel <= converged_rel)
            if (opt.certified_rel_decrease is not None and rel <= opt.certified_rel_decrease
                    and precond.certified(x)):
                status = "certified"
                break
            pg = precond.apply(x, x.grad)
            decrement = 0.5 * inner(pg, x.grad)
            if rel <= opt.rel_decrease_tol:
                status = "relative decrease"
                break
        else:
            precond.prepare(x, k)   # a rejected but expensive tCG: a better preconditioner at the same point
        if model_decrease <= 1e-15 * max(abs(x.f), 1e-300):
            status = "model decrease below machine precision"
            break
        if step <= opt.step_tol or delta < 1e-14 * max(1.0, math.sqrt(2 * max(abs(x.f), 1e-300))):
            status = "step size"
            break
    return TRResult(x, it, hvps, status)
