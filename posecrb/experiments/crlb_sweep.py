"""Monte Carlo validation of the CRLB (paper section IX-C, Fig. 6 and 7).

Ground truth: the certified SE-Sync estimate of the dataset (anchored so that the
anchor pose is the identity). For each noise level k_c, every trial regenerates
all measurements from the truth by eq. (80) (``posecrb.sim.sampling.perturb_measurements``:
Langevin rotation noise with concentration ``k_c kappa``, Gaussian translation
noise with precision ``k_c tau`` for ``scale="both"`` or ``tau`` for
``scale="rotation"``), solves the perturbed graph with the certified solver (the
MLE of that model, since the information matrices encode exactly the sampled
precisions), and measures the error in the FIM's own tangent coordinates:

* both estimate and truth have the anchor pose at the identity, so the anchored
  coordinates agree (the MLE is gauge invariant; fixing the anchor to its true
  value is the constrained MLE of the anchored FIM);
* translation error ``x_est - x_true`` (the FIM's ``dr/dx`` coordinates);
* rotation error along the FIM's right perturbation ``R_est = R_true Exp(delta)``:
  2D ``delta = angle(R_true^T R_est)`` (basis ``R_i E``, eq. 28), 3D
  ``delta = sqrt 2 * vee(Log(R_true^T R_est))`` (basis ``R_i E_k``, ``E_k = G_k / sqrt 2``,
  eq. 44). Then ``||delta||^2 = dist^2(R_est, R_true)`` of eq. (81).

MSE per pose = mean over trials of the squared error summed over poses, divided
by n_p; it is compared to ``trace(CRLB) / n_p`` with the FIM of the *scaled* noise
model evaluated at the truth (3D: with and without the curvature term of eq. 68).
The FIM is the Fisher information of the simulated model by default (``fim_variant=
"consistent"``); ``fim_variant="eq64"`` compares with eq. (64) as printed instead (the module
docstring of ``posecrb.models.paper.fim`` says why they differ in 3D). Every row names its variant.
"""
from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..core.errors import UsageError
from ..core.graph import PoseGraph
from ..core.status import OK, Status
from ..io.text import PRECISION_RANGE
from ..lie.so import so2_log, so3_log
from ..models.paper.crlb import paper_crlb
from ..models.paper.fim import FIM_VARIANTS
from ..sim.montecarlo import Task, level_key, make_tasks, mean_and_stderr, run_tasks
from ..sim.sampling import NOISE_SCALES, noise_model_graph, perturb_measurements
from ..solver import SolverOptions, solve
from ..solver.rounding import anchor_estimate

MAX_LEVELS = 1000
# The estimates are computed in double precision: positions of size S carry rounding errors of
# about eps S (the solver reaches a few eps on noise-free data: MSE 1.8e-29 per pose on a 16-pose
# grid of size 3, i.e. 3.7 eps per coordinate). A CRLB per pose below (d + d_r) (RESOLUTION eps S)^2
# is below what any double-precision estimate can resolve: its MSE measures rounding, not noise.
RESOLUTION = 100.0
# Within this factor of that floor the ratio MSE / CRLB is inflated by rounding: a warning.
RESOLUTION_MARGIN = 100.0


def parse_levels(spec: str) -> list[float]:
    """k_c levels from ``20``, ``1,5,20``, ``1:20`` (integers 1..20) or ``1:20:0.5`` (start:stop:step).

    Ranges include the stop value; levels must be > 0. Duplicates are dropped,
    order is increasing.
    """
    out: list[float] = []
    for part in str(spec).split(","):
        part = part.strip()
        if not part:
            continue
        if ":" in part:
            bits = part.split(":")
            if len(bits) not in (2, 3):
                raise UsageError(f"bad --kc range {part!r}; use START:STOP or START:STOP:STEP")
            try:
                start, stop = float(bits[0]), float(bits[1])
                step = float(bits[2]) if len(bits) == 3 else 1.0
            except ValueError as exc:
                raise UsageError(f"bad --kc range {part!r}: {exc}") from exc
            if not all(map(math.isfinite, (start, stop, step))):
                raise UsageError(f"bad --kc range {part!r}: START, STOP and STEP must be finite numbers")
            if step <= 0 or stop < start:
                raise UsageError(f"bad --kc range {part!r}: need STOP >= START and STEP > 0")
            count = int(math.floor((stop - start) / step + 1e-9)) + 1
            if count > MAX_LEVELS:
                raise UsageError(f"--kc {part!r} gives {count} levels (max {MAX_LEVELS})")
            out.extend(round(start + k * step, 12) for k in range(count))
        else:
            if not re.fullmatch(r"[0-9.eE+-]+", part):
                raise UsageError(f"bad --kc value {part!r}")
            try:
                out.append(float(part))
            except ValueError as exc:
                raise UsageError(f"bad --kc value {part!r}") from exc
    if not out:
        raise UsageError("--kc needs at least one level")
    if any(not (np.isfinite(v) and v > 0) for v in out):
        raise UsageError("--kc levels must be > 0")
    return sorted(set(out))


def level_range(graph: PoseGraph, scale: str = "both", tau: float | None = None,
                kappa: float | None = None) -> tuple[float, float]:
    """The k_c for which every scaled precision (k_c kappa, and k_c tau with ``scale="both"``) stays
    inside ``PRECISION_RANGE``, where every quantity built from it is finite (posecrb.io.text)."""
    lo_p, hi_p = PRECISION_RANGE
    k = np.asarray(graph.kappa if kappa is None else [kappa], dtype=float)
    scaled = [k] + ([np.asarray(graph.tau if tau is None else [tau], dtype=float)] if scale == "both" else [])
    lo = max(lo_p / float(v.min()) for v in scaled)
    hi = min(hi_p / float(v.max()) for v in scaled)
    return lo, hi


def check_levels(graph: PoseGraph, kcs: Sequence[float], scale: str = "both", tau: float | None = None,
                 kappa: float | None = None, name: str = "k_c") -> None:
    """UsageError for a level outside ``level_range``: its noise model's precisions would leave the
    range where the FIM, the solver and the sampler compute finite numbers."""
    lo, hi = level_range(graph, scale, tau, kappa)
    bad = [k for k in kcs if not lo <= k <= hi]
    if bad:
        raise UsageError(f"{name} {bad[0]:g}: outside [{lo:.3g}, {hi:.3g}] for {graph.name}, where the scaled "
                         f"precisions stay inside [{PRECISION_RANGE[0]:g}, {PRECISION_RANGE[1]:g}] (beyond it "
                         "the noise model's numbers overflow or underflow)")


# ---------------------------------------------------------------- errors in the FIM's coordinates
def rotation_errors(rot_true: np.ndarray, rot_est: np.ndarray) -> np.ndarray:
    """(n, d_r) rotation errors in the paper FIM's coordinates (right perturbation of the truth).

    2D: the angle of ``R_true^T R_est``; 3D: ``sqrt 2 * vee(Log(R_true^T R_est))``.
    """
    rel = np.swapaxes(rot_true, -1, -2) @ rot_est
    if rot_true.shape[-1] == 2:

        return so2_log(rel)[:, None]

    return np.sqrt(2.0) * so3_log(rel)


def pose_errors(rot_true: np.ndarray, trans_true: np.ndarray, rot_est: np.ndarray, trans_est: np.ndarray,
                anchor: int) -> tuple[np.ndarray, np.ndarray]:
    """(translation errors (n, d), rotation errors (n, d_r)) after anchoring both at ``anchor``."""
    rt, tt = anchor_estimate(rot_true, trans_true, anchor)
    re_, te = anchor_estimate(rot_est, trans_est, anchor)
    return te - tt, rotation_errors(rt, re_)


# ---------------------------------------------------------------- results
@dataclass(frozen=True)
class CrlbLevel:
    kc: float
    trials: int
    mse: float                          # mean over trials of the squared error per free pose
    mse_stderr: float
    mse_trans: float
    mse_rot: float
    mse_bound: float                    # trace(F^{-1}) / n_p of the chosen FIM variant
    mse_bound_trans: float
    mse_bound_rot: float
    mse_bound_curvature: float | None   # 3D: eq. (68) trace / n_p; None where eq. (68) does not hold
    ratio: float                        # mse / mse_bound
    ratio_curvature: float | None
    uncertified: int                    # trials whose solve was not certified (still counted)
    fim_variant: str = "consistent"
    curvature_status: dict | None = None  # posecrb.core.status JSON when eq. (68) is not ok at this level
    accuracy: dict | None = None          # posecrb.models.paper.crlb.InverseAccuracy of the bound (JSON form)
    ratio_status: dict | None = None      # posecrb.core.status JSON when the MSE is at the numerical floor

    def row(self) -> dict:
        r = dict(vars(self))
        if r["curvature_status"] is None:
            r.pop("curvature_status")
        if r["ratio_status"] is None:
            r.pop("ratio_status")
        elif r["ratio_status"]["status"] == "unavailable":
            r["ratio"] = None
            if r.get("ratio_curvature") is not None:
                r["ratio_curvature"] = None
        return r


def resolution_floor(trans: np.ndarray, dim: int) -> float:
    """MSE per pose below which double-precision estimates resolve nothing (``RESOLUTION``)."""
    scale = max(1.0, float(np.abs(trans).max()) if trans.size else 1.0)
    eps = float(np.finfo(float).eps)
    return (dim + (1 if dim == 2 else 3)) * (RESOLUTION * eps * scale) ** 2


def ratio_status(mse_bound: float, floor: float, kc: float) -> Status:
    """Whether MSE / CRLB at one level measures the noise or the rounding of the estimates."""
    if not mse_bound > floor:
        return Status.unavailable(
            f"the CRLB per pose ({mse_bound:.3g}) is below the numerical resolution of the estimates (about "
            f"{floor:.2g} per pose in double precision) at k_c = {kc:g}: the MSE measures rounding, not noise, "
            "so MSE/CRLB is meaningless", "use smaller k_c")
    if mse_bound <= RESOLUTION_MARGIN * floor:
        return Status.warning(
            f"the CRLB per pose ({mse_bound:.3g}) is within a factor {RESOLUTION_MARGIN:g} of the numerical "
            f"resolution of the estimates (about {floor:.2g}) at k_c = {kc:g}: rounding may inflate MSE/CRLB",
            "use smaller k_c")
    return OK


@dataclass
class CrlbSweepResult:
    dataset: str
    dim: int
    n: int
    m: int
    anchor_id: int
    scale: str
    tau: float | None                   # override of the base precisions (None: the file's)
    kappa: float | None
    trials: int
    seed: int
    truth_certified: bool
    truth_objective: float | None
    levels: list[CrlbLevel]
    trial_data: dict[float, dict[str, np.ndarray]] = field(default_factory=dict, repr=False)
    seeds: list[dict] = field(default_factory=list)
    elapsed: float = 0.0
    fim_variant: str = "consistent"

    def rows(self) -> list[dict]:
        rows = []
        for lv in self.levels:
            r = lv.row()
            if self.dim == 2:     # flat space: no curvature term
                for k in ("mse_bound_curvature", "ratio_curvature"):
                    r.pop(k)
            rows.append(r)
        return rows

    def trial_rows(self) -> list[dict]:
        """One row per trial (``trials.csv``): level, trial index, squared errors, certificate, objective."""
        return [{"kc": kc, "trial": t, "sq_trans": float(d["sq_trans"][t]), "sq_rot": float(d["sq_rot"][t]),
                 "certified": bool(d["certified"][t]), "objective": float(d["objective"][t])}
                for kc, d in self.trial_data.items() for t in range(len(d["sq_trans"]))]


# ---------------------------------------------------------------- the trial
def _solver_options(options: SolverOptions | Mapping[str, Any] | None, anchor: int) -> SolverOptions:
    """The solver's options with the sweep's anchor (a mapping is the keyword form of ``solve``)."""
    if not isinstance(options, SolverOptions):
        options = SolverOptions.from_keywords(**(options or {}))
    return replace(options, anchor=anchor)


def _crlb_trial(context: dict, task: Task) -> dict:

    rng = task.rng()
    graph = context["graph"]
    noisy = perturb_measurements(graph, context["rot"], context["trans"], rng, kc=context["kc"],
                                 scale=context["scale"], tau=context["tau"], kappa=context["kappa"])
    res = solve(noisy, _solver_options(context["solver_options"], context["anchor"]))
    et, er = pose_errors(context["rot"], context["trans"], res.rot, res.trans, context["anchor"])
    return {"sq_trans": float(np.sum(et * et)), "sq_rot": float(np.sum(er * er)),
            "certified": bool(res.certified), "objective": float(res.objective)}


def _bounds(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int, kc: float, scale: str,
            tau: float | None, kappa: float | None, variant: str = "consistent") -> dict:
    """Bounds per pose of the scaled noise model at the truth (``posecrb.models.paper.crlb.paper_crlb``:
    eq. 67, 3D eq. 68) from the FIM ``variant``: the simulated model's Fisher information
    (``"consistent"``) or eq. (64) as printed (``"eq64"``); the same matrix in 2D."""

    model = noise_model_graph(graph, kc, scale, tau, kappa)
    n_p = graph.n - 1
    res = paper_crlb(model, rot, trans, anchor=anchor, variant=variant)
    out: dict[str, Any] = {"mse_bound": float(res.trace_crlb) / n_p,
                           "mse_bound_trans": float(res.trace_translation) / n_p,
                           "mse_bound_rot": float(res.trace_rotation) / n_p}
    curv = res.trace_crlb_curvature if graph.dim == 3 else None
    out["mse_bound_curvature"] = None if curv is None else float(curv) / n_p
    out["curvature_status"] = None if res.curvature_status.ok else res.curvature_status.as_json()
    out["accuracy"] = None if res.accuracy is None else res.accuracy.to_dict()
    return out


def crlb_sweep(graph: PoseGraph, kcs: Sequence[float], trials: int = 100, seed: int = 0, *,
               scale: str = "both", tau: float | None = None, kappa: float | None = None,
               anchor: int | None = None, truth: tuple[np.ndarray, np.ndarray] | None = None,
               solver_options: SolverOptions | Mapping[str, Any] | None = None, executor: str = "serial", jobs: int = 1,
               scheduler: str | None = None, client: Any = None,
               progress: Callable[[int], None] | None = None, fim_variant: str = "consistent") -> CrlbSweepResult:
    """Fig. 6/7: MSE of the certified MLE vs trace(CRLB)/n_p for each k_c in ``kcs``.

    ``anchor`` is an internal index (default 0, the smallest id). ``truth`` defaults
    to the certified solution of ``graph`` itself. Trials of level k_c are seeded by
    ``SeedSequence(seed, spawn_key=(level_key(k_c),)).spawn(trials)``, so a level's
    numbers do not depend on the other levels requested nor on the executor.
    ``fim_variant``: the FIM the bound inverts (``posecrb.models.paper.fim.FIM_VARIANTS``).
    ``solver_options``: ``SolverOptions`` (or their keyword form) of every solve; the anchor is the sweep's.
    """

    t0 = time.perf_counter()
    if scale not in NOISE_SCALES:
        raise UsageError(f"--scale must be one of {', '.join(NOISE_SCALES)}")
    if fim_variant not in FIM_VARIANTS:
        raise UsageError(f"--fim-variant must be one of {', '.join(FIM_VARIANTS)}")
    if trials < 2:
        raise UsageError("--trials must be >= 2 (the MSE needs a standard error)")
    graph.require_connected()
    check_levels(graph, [float(k) for k in kcs], scale, tau, kappa)
    anchor = 0 if anchor is None else int(anchor)
    solver_options = _solver_options(solver_options, anchor)
    truth_certified, truth_objective = True, None
    if truth is None:
        res = solve(graph, solver_options)
        truth = (res.rot, res.trans)
        truth_certified, truth_objective = bool(res.certified), float(res.objective)
    rot, trans = anchor_estimate(np.asarray(truth[0], float), np.asarray(truth[1], float), anchor)
    kcs = sorted({float(k) for k in kcs})
    tasks = make_tasks(seed, trials, [(level_key(k),) for k in kcs])
    contexts = [{"graph": graph, "rot": rot, "trans": trans, "anchor": anchor, "kc": k, "scale": scale,
                 "tau": tau, "kappa": kappa, "solver_options": solver_options} for k in kcs]
    results = run_tasks(_crlb_trial, contexts, tasks, executor=executor, jobs=jobs, scheduler=scheduler,
                        client=client, progress=progress)
    n_p = graph.n - 1
    floor = resolution_floor(trans, graph.dim)
    levels, data = [], {}
    for g, kc in enumerate(kcs):
        rs = [r for r, t in zip(results, tasks) if t.group == g]
        sq_t = np.array([r["sq_trans"] for r in rs])
        sq_r = np.array([r["sq_rot"] for r in rs])
        cert = np.array([r["certified"] for r in rs])
        data[kc] = {"sq_trans": sq_t, "sq_rot": sq_r, "certified": cert,
                    "objective": np.array([r["objective"] for r in rs])}
        mse, se = mean_and_stderr((sq_t + sq_r) / n_p)
        b = _bounds(graph, rot, trans, anchor, kc, scale, tau, kappa, fim_variant)
        curv = b["mse_bound_curvature"]
        rst = ratio_status(b["mse_bound"], floor, kc)
        levels.append(CrlbLevel(
            kc=kc, trials=len(rs), mse=mse, mse_stderr=se, mse_trans=float(sq_t.mean() / n_p),
            mse_rot=float(sq_r.mean() / n_p), mse_bound=b["mse_bound"], mse_bound_trans=b["mse_bound_trans"],
            mse_bound_rot=b["mse_bound_rot"], mse_bound_curvature=curv, ratio=mse / b["mse_bound"],
            ratio_curvature=None if curv is None else mse / curv, uncertified=int((~cert).sum()),
            fim_variant=fim_variant, curvature_status=b["curvature_status"], accuracy=b["accuracy"],
            ratio_status=None if rst.ok else rst.as_json()))
    return CrlbSweepResult(
        dataset=graph.name, dim=graph.dim, n=graph.n, m=graph.m, anchor_id=int(graph.ids[anchor]),
        scale=scale, tau=tau, kappa=kappa, trials=trials, seed=seed, truth_certified=truth_certified,
        truth_objective=truth_objective, levels=levels, trial_data=data,
        seeds=[{"kc": k, "entropy": int(seed), "spawn_key": [level_key(k)], "children": trials} for k in kcs],
        elapsed=time.perf_counter() - t0, fim_variant=fim_variant)
