"""Figures (matplotlib, Agg backend: no display needed).

Each function takes a result and a path, writes one small figure (PNG, SVG or PDF, by the
path's extension, through the file layer: ``save_figure``) and returns the path. They mirror the
paper's Fig. 4-7 and the thesis's Graphs 6.8-6.9; ``plot_tables`` summarises Tables I-IV in one figure.
"""
from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from ..core.arguments import check_output_argument
from ..core.errors import ArgumentError
from ..core.outputs import check_output_file
from ..evaluation.published import paper_row
from .figures import FIGURE_EXTENSIONS, save_figure

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from ..experiments.crlb_sweep import CrlbSweepResult
    from ..experiments.octagon import OctagonResult
    from ..experiments.sparsify import SparsifyResult
    from ..experiments.thesis import ThesisResult
    from ..incremental.result import TimelineResult

DPI = 100
FIGURE_FORMATS = FIGURE_EXTENSIONS
# The legends of the wide figures (tables, sparsify), which the documentation shows scaled down to
# its column: at this size they stay readable there.
LEGEND_FONTSIZE = 10


def check_figure_path(path: str | os.PathLike) -> Path:
    """The figure target, checked before any work (``posecrb.core.outputs.check_output_file``):
    extension .png, .svg or .pdf, not a directory, its directory existing and writable. Raises
    UsageError (exit 2)."""
    return check_output_file(path, option=None, extensions=FIGURE_EXTENSIONS)


def plot_crlb_sweep(result: CrlbSweepResult, path: str | os.PathLike) -> Path:
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
    return save_figure(fig, path)


def plot_thesis(result: ThesisResult, path: str | os.PathLike) -> Path:
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
    return save_figure(fig, path)


def plot_octagon(result: OctagonResult, path: str | os.PathLike) -> Path:
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
    return save_figure(fig, path)


# Table I/II quantities: colour per quantity, the same in both panels.
_COLOURS = {"fim": "tab:blue", "ub": "tab:orange", "lb": "tab:green", "fim_build": "tab:purple",
            "laplacians_build": "tab:brown"}
_TIMES = (  # (our column, paper key, label, marker, colour)
    ("fim_time", "fim_time", "FIM log-det (Table I/II)", "o", _COLOURS["fim"]),
    ("ub_time", "ub_time", "ub (Table I/II)", "^", _COLOURS["ub"]),
    ("lb_time", "lb_time", "lb (Table I/II)", "v", _COLOURS["lb"]),
    ("fim_build_time", "fim_build_time", "whole FIM construction (III/IV)", "s", _COLOURS["fim_build"]),
    ("laplacians_build_time", "laplacians_build_time", "weighted Laplacians (III/IV)", "D",
     _COLOURS["laplacians_build"]),
)


def _legend_row(fig: Any, cell: Any) -> Axes:
    """An axes with no axis of its own in the grid ``cell`` under a figure's panels, for
    ``_legends_below``: the figure's tight layout (``save_figure``) keeps it clear of the panels'
    tick labels, and it is as wide as the panels together."""
    row = fig.add_subplot(cell)
    row.axis("off")
    return row


def _legends_below(row: Axes, legends: Sequence[tuple[list, list, dict]]) -> None:
    """Legends in ``row`` (``_legend_row``), where they hide no point and are as wide as the figure.
    ``legends``: (handles, labels, placement) each, the placement's ``bbox_to_anchor`` in ``row``'s
    axes coordinates."""
    from matplotlib.legend import Legend  # noqa: PLC0415 -- with matplotlib, already loaded

    for handles, labels, where in legends:
        legend = Legend(row, handles, labels, fontsize=LEGEND_FONTSIZE, title_fontsize=LEGEND_FONTSIZE,
                        frameon=False, **where)
        row.add_artist(legend).set_clip_on(False)    # may overhang the row: not clipped, and in the layout


def _plottable(rows: Iterable[dict]) -> list[dict]:
    return [r for r in rows if all(isinstance(r.get(k), (int, float)) for k in ("lb", "ub", "fim_logdet"))
            and r["lb"] > 0]


def plot_tables(rows: Sequence[dict], path: str | os.PathLike, note: str | None = None) -> Path:
    """Tables I-IV at a glance, one column per dataset (2D then 3D).

    Top: the FIM log-det and ub as their relative distance above lb, ``(x - lb)/lb``
    (log scale; lb itself is the floor, 0). Bottom: each measured time divided by the
    paper's printed time for the same quantity (log scale; 1 = as fast as printed, below
    = faster), for the datasets the paper has. ``rows`` are ``posecrb.evaluation.tables`` rows; rows
    without lb/ub/FIM (not found, failed) are left out. Raises ValueError when none is left.
    """

    data = _plottable(rows)
    if not data:
        raise ValueError("no dataset with lb, ub and FIM log-det to plot")
    data.sort(key=lambda r: r.get("dim", 0))          # stable: 2D rows first, each in table order
    x = np.arange(len(data))
    lb = np.array([r["lb"] for r in data], dtype=float)
    gap_fim = (np.array([r["fim_logdet"] for r in data], dtype=float) - lb) / lb
    gap_ub = (np.array([r["ub"] for r in data], dtype=float) - lb) / lb

    fig = plt.figure(figsize=(max(8.5, 0.42 * len(data) + 5.0), 8.0))
    # the two panels close together in one cell, the legends in a row of their own below
    outer = fig.add_gridspec(2, 1, height_ratios=[1, 0.14])
    panels = outer[0].subgridspec(2, 1, hspace=0.06)
    top = fig.add_subplot(panels[0])
    bottom = fig.add_subplot(panels[1], sharex=top)
    top.tick_params(labelbottom=False)
    top.vlines(x, np.minimum(gap_fim, gap_ub), np.maximum(gap_fim, gap_ub), color="0.75", lw=1.5, zorder=1)
    top.scatter(x, gap_fim, marker="o", color=_COLOURS["fim"], zorder=3,
                label="FIM log-det\n(certified optimum)")
    top.scatter(x, gap_ub, marker="^", color=_COLOURS["ub"], zorder=3, label="upper bound ub (eq. 75)")
    top.set_yscale("log")
    top.set_ylabel("(x − lb) / lb\n(log; lb, eq. 75, is the floor)")

    shown = 0
    for col, key, label, marker, colour in _TIMES:
        xs, ys = [], []
        for k, r in enumerate(data):
            p = paper_row(r["dataset"])
            ours, theirs = r.get(col), (p or {}).get(key)
            if p is not None and isinstance(ours, (int, float)) and theirs and ours > 0:
                xs.append(k)
                ys.append(ours / theirs)
        if xs:
            bottom.scatter(np.array(xs) + (shown - 2) * 0.08, ys, marker=marker, color=colour, s=22,
                           label=label, zorder=3)
            shown += 1
    bottom.axhline(1.0, color="k", lw=0.8)
    bottom.set_yscale("log")
    bottom.set_ylabel("our time / paper's time\n(log; below 1: faster)")
    # the legends in a row below the panels, where they hide no point
    legends: list[tuple[list, list, dict[str, Any]]] = [
        (*top.get_legend_handles_labels(),
         {"bbox_to_anchor": (0, 1), "loc": "upper left", "title": "above the lower bound lb"})]
    if shown:
        legends.append((*bottom.get_legend_handles_labels(),
                        {"bbox_to_anchor": (1, 1), "loc": "upper right", "ncols": 2,
                         "title": "time of ... vs the paper's (its machine, not this one)"}))
    else:
        bottom.text(0.5, 0.5, "no dataset of the paper among these rows", ha="center", va="center",
                    transform=bottom.transAxes, color="0.4")

    labels = [r["dataset"] + ("" if paper_row(r["dataset"]) else " *")
              + (" (uncertified)" if r.get("status") == "uncertified" else "") for r in data]
    bottom.set_xticks(x, labels, rotation=60, ha="right", fontsize=8)
    dims = [r.get("dim") for r in data]
    for ax in (top, bottom):
        ax.grid(True, which="major", axis="y", alpha=0.3)
        ax.set_xlim(-0.6, len(data) - 0.4)
        for k in range(1, len(data)):
            if dims[k] != dims[k - 1]:
                ax.axvline(k - 0.5, color="0.5", ls=":", lw=1)
    groups = [(d, [k for k, v in enumerate(dims) if v == d]) for d in sorted({d for d in dims if d})]
    if groups:
        sec = top.secondary_xaxis("top")
        sec.set_xticks([(ks[0] + ks[-1]) / 2 for _, ks in groups],
                       [f"{d}D (Table {'I/III' if d == 2 else 'II/IV'})" for d, _ in groups], fontsize=9)
        sec.tick_params(length=0)
    footer = "* not in the paper" if any(paper_row(r["dataset"]) is None for r in data) else ""
    if note:
        footer = f"{note}   {footer}".strip()
    _legends_below(_legend_row(fig, outer[1]), legends)
    if footer:
        fig.text(0.01, 0.005, footer, fontsize=7, color="0.35", ha="left", va="bottom")
    return save_figure(fig, path)



def plot_timeline(result: TimelineResult, path: str | os.PathLike) -> Path:
    """The information timeline (``posecrb timeline --plot``): against the number of poses, the
    D-optimality log-det (lb-ub band, FIM log-det) raw and per dimension (divided by q (K - 1),
    Carrillo et al.'s D-criterion scale), and the gain of each step's loop closures, the top 10
    marked with their pose ids. Disconnected prefixes are gaps.

    ``path`` is checked first (``ArgumentError``): a figure's extension, a writable directory, and
    none of the files the result was computed from (``result.input_paths()``). A result without
    any value (every prefix of its range disconnected) is an ``ArgumentError`` too: nothing to draw."""
    check_output_argument("path", path, result.input_paths(), extensions=FIGURE_EXTENSIONS)
    rows = result.rows
    if not np.isfinite(rows.lb).any():
        raise ArgumentError("result", f"TimelineResult of {result.dataset}", "has no values to draw: every prefix "
                            f"from {result.first} to {result.last} poses is disconnected", sep=": ")
    k = rows.poses.astype(float)
    q = result.dim + (1 if result.dim == 2 else 3)
    dims = q * np.maximum(k - 1, 1)
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8.0, 7.2), gridspec_kw={"height_ratios": [0.8, 1.3, 1]})
    top = result.top_closures()
    for ax, scale, label in ((axes[0], 1.0, "log det"), (axes[1], dims, "log det / (q (K − 1))")):
        lb, ub = rows.lb / scale, rows.ub / scale
        ok = np.isfinite(lb) & np.isfinite(ub)
        ax.fill_between(k, lb, ub, where=ok, color=_COLOURS["ub"], alpha=0.25, lw=0,
                        label="lb – ub band (eq. 75, graph only)")
        ax.plot(k, lb, "-", color=_COLOURS["lb"], lw=0.8, label="lb")
        ax.plot(k, ub, "-", color=_COLOURS["ub"], lw=0.8, label="ub")
        if rows.fim_logdet is not None:
            src = result.estimate.source if result.estimate is not None else ""
            ax.plot(k, rows.fim_logdet / scale, "-", color=_COLOURS["fim"], lw=0.9,
                    label=f"FIM log det (at {src})")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    gain = np.where(np.isfinite(rows.gain), rows.gain, 0.0)
    has = rows.loop_closures > 0
    axes[2].vlines(k[has], 0, gain[has], color="0.35", lw=0.6 if has.sum() < 2000 else 0.3,
                   label="gain of a step's loop closures")
    for rank, c in enumerate(top):
        # labels staggered in height so that neighbours stay readable
        axes[2].annotate(str(c.pose), (c.poses, c.gain or 0.0), fontsize=7, color="tab:red",
                         xytext=(0, 3 + 9 * (rank % 3)), textcoords="offset points", ha="center", va="bottom")
        for ax in axes[:2]:
            ax.axvline(c.poses, color="tab:red", lw=0.5, alpha=0.4)
    if top:
        axes[2].plot([c.poses for c in top], [c.gain for c in top], "v", color="tab:red", ms=4,
                     label=f"top {len(top)} loop closures (new pose id)")
        axes[2].set_ylim(0, 1.3 * max(c.gain or 0.0 for c in top))
    axes[2].set_ylabel("gain: increase of lb\nby the loop closures")
    axes[2].set_xlabel("poses K (step: the K poses with the smallest ids)")
    axes[2].grid(True, alpha=0.3)
    # one legend, in the raw panel's empty upper left (the curves rise from the lower left)
    handles = [h for ax in (axes[0], axes[2]) for h in ax.get_legend_handles_labels()[0]]
    axes[0].legend(handles=handles, fontsize=8, loc="upper left", framealpha=0.9)
    where = "every step" if result.every == 1 else f"every {result.every}-th step"
    fig.suptitle(f"{result.dataset}: information timeline ({result.dim}D, {where})", fontsize=10)
    return save_figure(fig, path)


def plot_sparsify(result: SparsifyResult, path: str | os.PathLike) -> str:
    """Share of the full graph's gain in the objective (``(f(S) - f(F)) / (f(all) - f(F))``),
    lambda_2 and ATE against the budget, one line per method; written atomically through the output
    layer (``save_figure``: format by the extension, .png, .svg or .pdf)."""
    fig = plt.figure(figsize=(13.0, 4.4))
    grid = fig.add_gridspec(2, 3, height_ratios=[1, 0.06])
    axes = [fig.add_subplot(grid[0, k]) for k in range(3)]
    names = {"tree": "tree bound (eq. 75)", "fim": "logdet FIM", "fiedler": "$\\lambda_2$"}
    key = "fim_logdet" if result.objective == "fim" else result.objective
    top, bottom = result.reference[key], result.reference["fixed_only"][key]
    for label in result.methods:
        rows = sorted((r for r in result.rows if r["method"] == label), key=lambda r: r["percent"])
        pct = [r["percent"] for r in rows]
        axes[0].plot(pct, [(r[key] - bottom) / (top - bottom) for r in rows], marker="o", ms=3, label=label)
        axes[1].plot(pct, [r["fiedler"] for r in rows], marker="o", ms=3, label=label)
        axes[2].plot(pct, [r["ate_trans"] for r in rows], marker="o", ms=3, label=label)
    axes[0].set_ylabel(f"{names[result.objective]}: share of the full gain")
    axes[1].set_ylabel("algebraic connectivity $\\lambda_2$")
    axes[2].set_ylabel("ATE translation vs full-graph optimum")
    axes[2].set_yscale("symlog", linthresh=1e-3)
    for ax in axes:
        ax.set_xlabel("% of loop closures kept")
        ax.grid(True, alpha=0.3)
    _legends_below(_legend_row(fig, grid[1, :]), [(*axes[0].get_legend_handles_labels(),
                   {"bbox_to_anchor": (0.5, 1), "loc": "upper center", "ncols": len(result.methods)})])
    fig.suptitle(f"{result.dataset}: {result.candidates} candidate loop closures, {result.fixed} fixed edges")
    return os.fspath(save_figure(fig, path))
