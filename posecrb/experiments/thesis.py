"""The thesis's chapter 6 case study: empirical covariance of the intrinsic MLE vs the
anchored and quotient intrinsic CRBs on SE(2)^5 (Bertini, sections 6.1-6.7).

Setting (``posecrb.models.sed.example``): five poses, six directed arcs forming two
components {1, 2} and {3, 4, 5}, heteroscedastic left noise ``H = Exp(xi) T_i T_j^{-1}``,
``xi ~ N(0, Sigma_ij)`` (4.3), ``m`` i.i.d. measurements per arc (4.10), so
``F_m = m F_1`` (4.12) with ``F_1`` the FIM (4.6) at the truth (nullity 6 = 3 c).

Per trial and per m:

* anchored MLE (5.7): poses 1 and 3 fixed at the truth, the others estimated by
  Levenberg-Marquardt on SE(2) with the analytic Jacobians (4.7)
  ``J_i = -Jr^{-1}(r) Ad_{T_i}``, ``J_j = Jr^{-1}(r) Ad_{T_i}`` (closed-form right Jacobians,
  ``posecrb.models.sed.fim.edge_kinematics``), right-perturbation updates ``T_k <- T_k Exp(delta_k)``,
  started from the measurements composed along each component (not from the truth);
* intrinsic error ``delta_k = Log(T_true_k^{-1} T_est_k)``: the coordinates of the
  FIM's right perturbation ``T_k Exp(delta)``;
* quotient (5.8): the anchored MLE is a representative of the quotient MLE (the
  likelihood is constant on gauge orbits); each component is moved by the right
  action ``T_k G_c`` (5.3) chosen by Newton's method so that the errors of the
  component have zero mean, i.e. the error is horizontal (orthogonal to the
  kernel ``[delta; ...; delta]``, Th. 4.8.1), exactly, not only to first order.

Empirical covariance = mean of ``e e^T`` over trials (the error's second moment about
the truth). Compared with ``(Pi F_m Pi)^+`` (5.1) and ``F_m^+`` (5.5) by the Frobenius
norm of the difference and the eigenvalues of ``Sym(Cov - CRB)`` on the 9-dimensional
identifiable subspace. ``||Cov - CRB||_F`` shrinks like 1/m simply because both terms
do; the relative error ``||Cov - CRB||_F / ||CRB||_F`` is the scale-free check, and
``frob_rel_noise`` is its expected Monte Carlo level for an efficient estimator,
``sqrt((||C||_F^2 + tr(C)^2) / N) / ||C||_F`` (Gaussian errors, N trials).
Dense linear algebra is used throughout: the problem has 15 unknowns by construction.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import UsageError
from ..core.graph import PoseGraph
from ..lie.se import se_compose, se_exp, se_inverse, se_jr_inv, se_log
from ..models.sed.example import ANCHORS, left_information, sample_graph, thesis_graph, true_estimate, true_poses
from ..models.sed.fim import edge_kinematics, kernel_basis, sed_fim
from ..sim.montecarlo import Task, make_tasks, run_tasks

DEFAULT_M = (1, 2, 5, 10, 20, 50, 100, 150)
QUICK_M = (1, 10, 100)
Q = 3          # dim SE(2)
N_POSES = 5


# ---------------------------------------------------------------- SE(2) helpers on (R, t) pairs
def _poses_T() -> tuple[np.ndarray, np.ndarray]:

    return true_poses()


def _to_x(rot: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:

    return se_inverse(rot, trans)


def intrinsic_errors(rot_true: np.ndarray, trans_true: np.ndarray, rot_est: np.ndarray,
                     trans_est: np.ndarray) -> np.ndarray:
    """(n, q) ``Log(T_true^{-1} T_est)``: coordinates of the right perturbation T_true Exp(delta)."""

    ri, ti = se_inverse(rot_true, trans_true)
    return se_log(*se_compose(ri, ti, rot_est, trans_est))


def _retract(rot, trans, delta):
    """T_k <- T_k Exp(delta_k)."""

    er, et = se_exp(delta)
    return se_compose(rot, trans, er, et)


# ---------------------------------------------------------------- the MLE
@dataclass(frozen=True)
class MleResult:
    rot: np.ndarray        # (n, 2, 2) thesis poses T_i
    trans: np.ndarray      # (n, 2)
    iterations: int
    converged: bool
    cost: float


def _cost_grad_hess(graph, omega, rot, trans, free_dofs):
    """0.5 sum r^T Omega r, its gradient and Gauss-Newton Hessian over the free dofs (4.5-4.7)."""

    xr, xt = _to_x(rot, trans)
    res, a = edge_kinematics(graph, xr, xt)          # r_ij, A = Jr^{-1}(r) Ad_{T_i}
    w_r = np.einsum("eab,eb->ea", omega, res)
    cost = 0.5 * float(np.einsum("ea,ea->", res, w_r))
    g_e = np.einsum("eba,eb->ea", a, w_r)            # A^T Omega r
    h_e = np.swapaxes(a, 1, 2) @ omega @ a           # A^T Omega A
    n = graph.n
    grad = np.zeros((n, Q))
    np.add.at(grad, graph.src, -g_e)                 # J_i = -A
    np.add.at(grad, graph.dst, g_e)                  # J_j = +A
    hess = np.zeros((n, n, Q, Q))
    np.add.at(hess, (graph.src, graph.src), h_e)
    np.add.at(hess, (graph.dst, graph.dst), h_e)
    np.add.at(hess, (graph.src, graph.dst), -h_e)
    np.add.at(hess, (graph.dst, graph.src), -h_e)
    hess = hess.transpose(0, 2, 1, 3).reshape(n * Q, n * Q)
    return cost, grad.ravel()[free_dofs], hess[np.ix_(free_dofs, free_dofs)]


def _initial_poses(graph: PoseGraph, anchors: Sequence[int], rot_anchor: np.ndarray,
                   trans_anchor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Compose the measurements outward from the anchors (one pass over a BFS tree of the arcs)."""

    n = graph.n
    rot = np.repeat(np.eye(2)[None], n, 0)
    trans = np.zeros((n, 2))
    known = np.zeros(n, bool)
    for a in anchors:
        rot[a], trans[a], known[a] = rot_anchor[a], trans_anchor[a], True
    # H_ij ~ T_i T_j^{-1}: T_j = H_ij^{-1} T_i, T_i = H_ij T_j. Loop over the (at most n) tree
    # steps, each vectorised over the arcs that reach a new pose.
    for _ in range(n):
        fwd = known[graph.src] & ~known[graph.dst]
        bwd = known[graph.dst] & ~known[graph.src]
        if not (fwd.any() or bwd.any()):
            break
        if fwd.any():
            e = np.flatnonzero(fwd)
            _, first = np.unique(graph.dst[e], return_index=True)
            e = e[first]
            hr, ht = se_inverse(graph.rot[e], graph.trans[e])
            r, t = se_compose(hr, ht, rot[graph.src[e]], trans[graph.src[e]])
            rot[graph.dst[e]], trans[graph.dst[e]], known[graph.dst[e]] = r, t, True
        bwd = known[graph.dst] & ~known[graph.src]
        if bwd.any():
            e = np.flatnonzero(bwd)
            _, first = np.unique(graph.src[e], return_index=True)
            e = e[first]
            r, t = se_compose(graph.rot[e], graph.trans[e], rot[graph.dst[e]], trans[graph.dst[e]])
            rot[graph.src[e]], trans[graph.src[e]], known[graph.src[e]] = r, t, True
    return rot, trans


def anchored_mle(graph: PoseGraph, omega: np.ndarray, anchors: Sequence[int], rot_anchor: np.ndarray,
                 trans_anchor: np.ndarray, *, max_iterations: int = 100, tol: float = 1e-12) -> MleResult:
    """MLE on the anchored submanifold (5.7): Levenberg-Marquardt, analytic Jacobians (4.7).

    ``graph`` holds measurements ``H_ij`` as ``(rot, trans)`` (= ``T_i T_j^{-1}``);
    ``omega`` (m, q, q) the left-noise information; anchors keep the given poses.
    Returns the thesis poses ``T_i``.
    """
    n = graph.n
    free = np.setdiff1d(np.arange(n), np.asarray(anchors))
    free_dofs = (free[:, None] * Q + np.arange(Q)).ravel()
    rot, trans = _initial_poses(graph, anchors, rot_anchor, trans_anchor)
    cost, g, h = _cost_grad_hess(graph, omega, rot, trans, free_dofs)
    lam = 1e-4
    converged = False
    it = 0
    for it in range(1, max_iterations + 1):  # noqa: B007 -- the count is returned after the loop
        damp = h + lam * np.diag(np.diag(h))
        step = -np.linalg.solve(damp, g)
        delta = np.zeros((n, Q))
        delta[free] = step.reshape(-1, Q)
        r_new, t_new = _retract(rot, trans, delta)
        c_new, g_new, h_new = _cost_grad_hess(graph, omega, r_new, t_new, free_dofs)
        if c_new <= cost:
            small = np.linalg.norm(step) < tol * (1.0 + np.linalg.norm(trans[free]))
            rot, trans, cost, g, h = r_new, t_new, c_new, g_new, h_new
            lam = max(lam / 10.0, 1e-12)
            if small or np.linalg.norm(g) < 1e-12 * (1.0 + cost):
                converged = True
                break
        else:
            lam *= 10.0
            if lam > 1e12:
                converged = np.linalg.norm(g) < 1e-8 * (1.0 + cost)
                break
    return MleResult(rot, trans, it, converged, cost)


def horizontal_errors(rot_true: np.ndarray, trans_true: np.ndarray, rot_est: np.ndarray, trans_est: np.ndarray,
                      labels: np.ndarray,
                      iterations: int = 20) -> np.ndarray:
    """(n, q) errors after the right gauge action ``T_k G_c`` that makes each component's mean error zero.

    Newton on ``sum_{k in c} Log(T_true_k^{-1} T_est_k G_c Exp(eps)) = 0`` with
    ``d Log(Exp(delta) Exp(eps)) = Jr^{-1}(delta) eps``.
    """

    rot, trans = np.array(rot_est, float), np.array(trans_est, float)
    n_comp = int(labels.max()) + 1
    for _ in range(iterations):
        e = intrinsic_errors(rot_true, trans_true, rot, trans)
        s = np.zeros((n_comp, Q))
        np.add.at(s, labels, e)
        if np.max(np.abs(s)) < 1e-15:
            break
        jac = np.zeros((n_comp, Q, Q))
        np.add.at(jac, labels, se_jr_inv(e))
        eps = -np.linalg.solve(jac, s[..., None])[..., 0]
        rot, trans = _retract(rot, trans, eps[labels])
    return intrinsic_errors(rot_true, trans_true, rot, trans)


# ---------------------------------------------------------------- Monte Carlo
def _thesis_trial(context: dict, task: Task) -> dict:

    m = context["m"]
    graph = sample_graph(task.rng(), m)
    omega = np.repeat(left_information(), m, axis=0)
    rt, tt = _poses_T()
    mle = anchored_mle(graph, omega, ANCHORS, rt, tt)
    e_anch = intrinsic_errors(rt, tt, mle.rot, mle.trans)
    e_quot = horizontal_errors(rt, tt, mle.rot, mle.trans, graph.component_labels)
    return {"anchored": e_anch.ravel(), "quotient": e_quot.ravel(),
            "iterations": mle.iterations, "converged": mle.converged}


def thesis_bounds(m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(F_m, (Pi F_m Pi)^+, F_m^+, N)``: dense 15 x 15 bounds of the case study at the truth."""

    g = thesis_graph()
    f1 = sed_fim(g, *true_estimate(), information=left_information()).matrix.toarray()
    fm = m * f1
    free = np.setdiff1d(np.arange(N_POSES), ANCHORS)
    dofs = (free[:, None] * Q + np.arange(Q)).ravel()
    anch = np.zeros_like(fm)
    anch[np.ix_(dofs, dofs)] = np.linalg.inv(fm[np.ix_(dofs, dofs)])
    nb = kernel_basis(g)
    proj = np.eye(fm.shape[0]) - nb @ nb.T
    quot = proj @ anch @ proj            # F^+ = P G P for the generalised inverse G (sed module doc)
    return fm, anch, quot, nb


@dataclass(frozen=True)
class ThesisRow:
    m: int
    formulation: str             # "anchored" | "quotient"
    trials: int
    frob: float                  # ||Cov - CRB||_F
    frob_rel: float              # / ||CRB||_F
    frob_rel_noise: float        # expected Monte Carlo level of frob_rel for an efficient estimator
    trace_cov: float
    trace_crb: float
    eig_min: float               # eigenvalues of Sym(Cov - CRB) on the 9-dim identifiable space
    eig_max: float
    nullity: int                 # of F_m
    not_converged: int


@dataclass
class ThesisResult:
    trials: int
    seed: int
    ms: list[int]
    table: list[ThesisRow]
    eigenvalues: dict[str, dict[int, np.ndarray]] = field(default_factory=dict, repr=False)
    covariances: dict[str, dict[int, np.ndarray]] = field(default_factory=dict, repr=False)
    bounds: dict[str, dict[int, np.ndarray]] = field(default_factory=dict, repr=False)
    seeds: list[dict] = field(default_factory=list)

    def rows(self) -> list[dict]:
        return [dict(vars(r)) for r in self.table]

    def eigenvalue_rows(self) -> list[dict]:
        """``eigenvalues.csv``: per formulation and m, the eigenvalues ``eig0, eig1, ...``."""
        return [{"m": m, "formulation": f, **{f"eig{k}": float(v) for k, v in enumerate(self.eigenvalues[f][m])}}
                for f in ("anchored", "quotient") for m in self.ms]


def thesis_experiment(ms: Sequence[int] = DEFAULT_M, trials: int = 200, seed: int = 0, *,
                      executor: str = "serial", jobs: int = 1, scheduler: str | None = None,
                      progress: Callable[[int], None] | None = None) -> ThesisResult:
    """Graphs 6.8 / 6.9 of the thesis, with the scale-free companion metrics."""
    ms = sorted({int(m) for m in ms})
    if not ms or ms[0] < 1:
        raise UsageError("m values must be >= 1")
    if trials < 2:
        raise UsageError("trials must be >= 2")
    tasks = make_tasks(seed, trials, [(m,) for m in ms])
    results = run_tasks(_thesis_trial, [{"m": m} for m in ms], tasks, executor=executor, jobs=jobs,
                        scheduler=scheduler, progress=progress)
    table: list[ThesisRow] = []
    eigs: dict[str, dict[int, np.ndarray]] = {"anchored": {}, "quotient": {}}
    covs: dict[str, dict[int, np.ndarray]] = {"anchored": {}, "quotient": {}}
    bnds: dict[str, dict[int, np.ndarray]] = {"anchored": {}, "quotient": {}}
    for gidx, m in enumerate(ms):
        rs = [r for r, t in zip(results, tasks) if t.group == gidx]
        fm, anch, quot, nb = thesis_bounds(m)
        ev = np.linalg.eigvalsh(fm)
        nullity = int(np.sum(np.abs(ev) <= 1e-9 * np.abs(ev).max()))
        not_conv = int(sum(not r["converged"] for r in rs))
        for form, crb in (("anchored", anch), ("quotient", quot)):
            e = np.stack([r[form] for r in rs])
            cov = e.T @ e / e.shape[0]
            diff = 0.5 * ((cov - crb) + (cov - crb).T)
            # orthonormal basis of the identifiable subspace: the range of the bound
            w, v = np.linalg.eigh(crb)
            basis = v[:, w > 1e-12 * w.max()]
            lam = np.linalg.eigvalsh(basis.T @ diff @ basis)
            nrm = np.linalg.norm(crb)
            table.append(ThesisRow(
                m=m, formulation=form, trials=len(rs), frob=float(np.linalg.norm(cov - crb)),
                frob_rel=float(np.linalg.norm(cov - crb) / nrm),
                frob_rel_noise=float(np.sqrt((nrm ** 2 + np.trace(crb) ** 2) / len(rs)) / nrm),
                trace_cov=float(np.trace(cov)), trace_crb=float(np.trace(crb)),
                eig_min=float(lam.min()), eig_max=float(lam.max()), nullity=nullity, not_converged=not_conv))
            eigs[form][m] = lam
            covs[form][m] = cov
            bnds[form][m] = crb
    return ThesisResult(trials=trials, seed=seed, ms=ms, table=table, eigenvalues=eigs, covariances=covs,
                        bounds=bnds, seeds=[{"m": m, "entropy": int(seed), "spawn_key": [m], "children": trials}
                                            for m in ms])
