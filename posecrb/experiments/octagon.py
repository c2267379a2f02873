"""The paper's T- vs D-optimality experiment (section IX-A, Fig. 2-5).

Eight poses on a regular octagon joined by an odometry chain 0-1-...-7, every
measurement with ``delta^2 = 1e-4`` (tau = 1e4) and kappa = 5e3. Extra
measurements are added "from one edge to 21 edges without repetition", never
touching the anchor (pose 0): the 21 candidates are all pairs of poses 1..7
(``posecrb.sim.generators.octagon_candidate_edges``). For each number k of extra edges
we take every subset when there are at most ``trials`` of them, otherwise
``trials`` distinct random subsets. The FIM is evaluated at the ground truth:
with noise-free measurements the truth is the maximum-likelihood (SE-Sync)
estimate, so this equals "the FIM after using SE-Sync" of the paper.

Per graph: the exact T-optimality ``trace(F)`` (eq. 69), its graph-only
approximation eq. (73) (``c * total node degree`` with equal weights, eq. 78),
the D-optimality ``log det F`` (Cholesky) and the lower bound ``lb`` (eq. 75).
Graphs are flagged when some graph with fewer edges has a larger log det
(the red circle of Fig. 5).
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import InternalError, UsageError
from ..models.paper.bounds import compute_bounds
from ..models.paper.fim import fim_logdet, paper_fim, trace_fim
from ..sim.generators import octagon, octagon_candidate_edges
from ..sim.montecarlo import Task, make_tasks, run_tasks, seed_record

DEFAULT_RADIUS = 0.1   # the paper gives no size; small enough that sum tau ||p||^2 is small (sec. IX-A)


@dataclass(frozen=True)
class OctagonGraph:
    extra: tuple[tuple[int, int], ...]   # extra pose pairs (ids 1..7)
    m: int                               # number of measurements (7 + k)
    total_degree: int                    # sum of the node degrees of the free poses (eq. 78)
    trace: float                         # trace(F), eq. (69)
    trace_eq73: float                    # graph-only approximation, eq. (73)
    logdet: float                        # log det F
    lb: float                            # d logdet L_tau + d_r logdet L_w, eq. (75)
    worse_than_fewer: bool = False       # some graph with fewer edges has a larger log det


@dataclass(frozen=True)
class OctagonLevel:
    extra_edges: int
    m: int
    graphs: int
    total_degree: int
    trace_min: float
    trace_max: float
    trace_eq73: float
    logdet_min: float
    logdet_max: float
    best_fewer_logdet: float | None      # max log det over graphs with fewer edges
    flagged: int                         # graphs here worse than some graph with fewer edges


@dataclass
class OctagonResult:
    graphs: list[OctagonGraph]
    levels: list[OctagonLevel]
    trials: int
    seed: int
    radius: float
    tau: float
    kappa: float
    corr_trace_degree: float             # Pearson correlation over all graphs
    corr_logdet_degree: float
    trace_slope: float                   # least-squares trace(F) ~ slope * total_degree (through 0)
    flagged: int
    seeds: list[dict] = field(default_factory=list)

    def rows(self) -> list[dict]:
        return [dict(vars(lv)) for lv in self.levels]

    def graph_rows(self) -> list[dict]:
        return [{**{k: v for k, v in vars(g).items() if k != "extra"},
                 "extra": ";".join(f"{i}-{j}" for i, j in g.extra)} for g in self.graphs]


def _subsets(k: int, trials: int, rng: np.random.Generator, n_cand: int) -> list[tuple[int, ...]]:
    total = math.comb(n_cand, k)
    if total <= trials:
        return list(itertools.combinations(range(n_cand), k))
    seen: set[tuple[int, ...]] = set()
    out: list[tuple[int, ...]] = []
    while len(out) < trials:       # trials < total, so distinct subsets always exist
        s = tuple(sorted(rng.choice(n_cand, size=k, replace=False).tolist()))
        if s not in seen:
            seen.add(s)
            out.append(s)
    return out


def _octagon_level(context: dict, task: Task) -> list[OctagonGraph]:
    """All graphs with ``context['k']`` extra edges (one Monte Carlo task per k)."""

    cand = octagon_candidate_edges()
    out = []
    for subset in _subsets(context["k"], context["trials"], task.rng(), len(cand)):
        extra = tuple(cand[p] for p in subset)
        g = octagon(list(extra), radius=context["radius"], tau=context["tau"], kappa=context["kappa"])
        if g.vertex_rot is None or g.vertex_trans is None:  # octagon() stores the true poses as vertices
            raise InternalError("octagon graph without its poses")
        fim = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=0)
        b = compute_bounds(g, anchor=0)   # lb (eq. 75), eq. (73) and the total degree of the free poses
        out.append(OctagonGraph(extra, g.m, b.total_degree, trace_fim(fim), b.t_opt_graph, fim_logdet(fim),
                                float(b.lb)))
    return out


def octagon_experiment(trials: int = 50, seed: int = 0, *, radius: float = DEFAULT_RADIUS,
                       tau: float = 1e4, kappa: float = 5e3, executor: str = "serial", jobs: int = 1,
                       scheduler: str | None = None, progress: Callable[[int], None] | None = None
                       ) -> OctagonResult:
    """Fig. 4/5: T- and D-optimality of octagon graphs with 0..21 extra edges."""

    if trials < 1:
        raise UsageError("trials must be >= 1")
    n_cand = len(octagon_candidate_edges())
    levels = list(range(n_cand + 1))
    tasks = make_tasks(seed, 1, [(k,) for k in levels])
    contexts = [{"k": k, "trials": trials, "radius": radius, "tau": tau, "kappa": kappa} for k in levels]
    per_level = run_tasks(_octagon_level, contexts, tasks, executor=executor, jobs=jobs,
                          scheduler=scheduler, progress=progress)
    graphs: list[OctagonGraph] = []
    rows: list[OctagonLevel] = []
    best_so_far = -np.inf
    for k, gs in zip(levels, per_level):
        best_fewer = best_so_far if k > 0 else None
        flagged = [g.logdet < best_so_far for g in gs]
        gs = [OctagonGraph(**{**vars(g), "worse_than_fewer": bool(f)}) for g, f in zip(gs, flagged)]
        graphs.extend(gs)
        tr = np.array([g.trace for g in gs])
        ld = np.array([g.logdet for g in gs])
        rows.append(OctagonLevel(k, gs[0].m, len(gs), gs[0].total_degree, float(tr.min()), float(tr.max()),
                                 gs[0].trace_eq73, float(ld.min()), float(ld.max()),
                                 None if best_fewer is None else float(best_fewer), int(sum(flagged))))
        best_so_far = max(best_so_far, float(ld.max()))
    deg = np.array([g.total_degree for g in graphs], dtype=float)
    tr = np.array([g.trace for g in graphs])
    ld = np.array([g.logdet for g in graphs])
    return OctagonResult(
        graphs=graphs, levels=rows, trials=trials, seed=seed, radius=radius, tau=tau, kappa=kappa,
        corr_trace_degree=float(np.corrcoef(deg, tr)[0, 1]), corr_logdet_degree=float(np.corrcoef(deg, ld)[0, 1]),
        trace_slope=float(deg @ tr / (deg @ deg)), flagged=int(sum(r.flagged for r in rows)),
        seeds=[{"level": k, **seed_record(t)} for k, t in zip(levels, tasks)],
    )
