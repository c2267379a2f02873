"""Figures of the experiments (matplotlib, Agg backend: no display needed).

Each function takes an experiment result and a path, writes one small PNG and
returns the path. They mirror the paper's Fig. 4-7 and the thesis's Graphs 6.8-6.9.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from ..core.files import atomic_write

DPI = 100


def _save(fig, path) -> Path:
    """savefig to a temporary in the target directory, renamed into place (atomic_write);
    the format follows the suffix (PNG without one)."""

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fig.tight_layout()
        with atomic_write(path, "wb") as fh:
            fig.savefig(fh, dpi=DPI, format=path.suffix[1:].lower() or "png")
    finally:
        plt.close(fig)
    return path


def plot_crlb_sweep(result, path) -> Path:
    """Fig. 6 / 7: MSE per pose of the certified MLE vs the CRLB per pose, over k_c."""
    kc = np.array([lv.kc for lv in result.levels])
    mse = np.array([lv.mse for lv in result.levels])
    se = np.array([lv.mse_stderr for lv in result.levels])
    bound = np.array([lv.mse_bound for lv in result.levels])
    variant = getattr(result, "fim_variant", "consistent")
    what = ("Fisher information of the model" if variant == "consistent" else "eq. (64) as printed")
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    ax.errorbar(kc, mse, yerr=2 * se, fmt="o", ms=4, capsize=2, color="k",
                label=f"MSE of the certified MLE ({result.trials} trials, ±2 s.e.)")
    ax.plot(kc, bound, "-", color="tab:blue", label=f"CRLB trace(F$^{{-1}}$)/$n_p$, F = {what}")
    curv = [lv.mse_bound_curvature for lv in result.levels]
    if result.dim == 3 and all(c is not None for c in curv):
        ax.plot(kc, np.array(curv, dtype=float), "--", color="tab:blue", alpha=0.6,
                label="... with the curvature term (eq. 68)")
    ax.set_yscale("log")
    ax.set_xlabel("$k_c$ (noise scaled by 1/$k_c$: " + ("rotation and translation" if result.scale == "both"
                                                       else "rotation only") + ")")
    ax.set_ylabel("MSE per pose")
    ax.set_title(f"{result.dataset}: {result.n - 1} free poses, {result.m} edges")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def plot_thesis(result, path) -> Path:
    """Graphs 6.8 / 6.9: ||Cov - CRB||_F vs m (log-log), anchored and quotient, with the relative error."""
    fig, axes = plt.subplots(1, 2, figsize=(8.0, 3.6))
    for form, marker in (("anchored", "o"), ("quotient", "s")):
        rows = [r for r in result.rows() if r["formulation"] == form]
        m = np.array([r["m"] for r in rows])
        axes[0].loglog(m, [r["frob"] for r in rows], marker + "-", label=form)
        axes[1].semilogx(m, [r["frob_rel"] for r in rows], marker + "-", label=form)
    axes[0].set_xlabel("measurements per arc m")
    axes[0].set_ylabel(r"$\|\widehat{\mathrm{Cov}} - \mathrm{CRB}\|_F$")
    axes[1].set_xlabel("measurements per arc m")
    axes[1].set_ylabel(r"$\|\widehat{\mathrm{Cov}} - \mathrm{CRB}\|_F / \|\mathrm{CRB}\|_F$")
    axes[1].axhline(0, color="k", lw=0.5)
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"thesis ch. 6 case study ({result.trials} trials per m)", fontsize=10)
    return _save(fig, path)


def plot_octagon(result, path) -> Path:
    """Fig. 4 / 5: T-optimality and D-optimality against the total node degree."""
    deg = np.array([g.total_degree for g in result.graphs], dtype=float)
    tr = np.array([g.trace for g in result.graphs])
    ld = np.array([g.logdet for g in result.graphs])
    flag = np.array([g.worse_than_fewer for g in result.graphs])
    rng = np.random.default_rng(0)                     # horizontal jitter only, for visibility
    jit = rng.uniform(-0.25, 0.25, deg.size)
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.8))
    axes[0].plot(deg + jit, tr, ".", color="k", ms=3, label="trace(F)")
    lv_deg = np.array([lv.total_degree for lv in result.levels], dtype=float)
    axes[0].plot(lv_deg, [lv.trace_eq73 for lv in result.levels], "-", color="tab:red",
                 label="eq. (73): c × total degree")
    axes[0].set_ylabel("T-optimality trace(F)")
    axes[0].set_title(f"corr(trace, degree) = {result.corr_trace_degree:.4f}", fontsize=9)
    axes[1].plot(deg[~flag] + jit[~flag], ld[~flag], ".", color="k", ms=3, label="log det F")
    axes[1].plot(deg[flag] + jit[flag], ld[flag], "o", mfc="none", color="tab:red", ms=5,
                 label=f"worse than a graph with fewer edges ({int(flag.sum())})")
    axes[1].set_ylabel("D-optimality log det F")
    axes[1].set_title(f"corr(log det, degree) = {result.corr_logdet_degree:.4f}", fontsize=9)
    for ax in axes:
        ax.set_xlabel("total node degree (free poses)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"octagon: 8 poses, odometry + 0..21 extra edges ({len(result.graphs)} graphs)", fontsize=10)
    return _save(fig, path)
