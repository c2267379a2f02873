"""Measurement selection: keep K of a pose graph's candidate edges, with a ratio certificate.

The paper's section VIII-B: D-optimal measurement selection (the k-ESP+ problem of Khosoussi et
al.) becomes cheap with the graph-only bounds, and extends to 3D (eq. 75). Given fixed edges F
(default: the odometry chain) and candidates C, choose S within C, |S| = K, maximising an
objective, and bound the best K-subset's value from above. One module per concept (the names are
those of docs/design.md#glossary-selection):

* ``budget``: the budget K (``K`` or ``P%``) and the split into fixed edges and candidates;
* ``objectives``: ``tree`` (eq. 75), ``fim`` (logdet of the anchored FIM) and ``fiedler``
  (lambda_2, MAC's objective) as functions of edge weights;
* ``greedy``: the incremental and lazy greedy (log-dets), MAC's GreedyEig (fiedler);
* ``rounds``: the round greedy (log-dets, large budgets on large graphs): exact gains once per round,
  local corrections within it;
* ``relaxation``: Frank-Wolfe on the concave relaxation, top-K and Madow rounding, the swap polish;
* ``certificate``: the ratio certificate (upper bounds, certified ratio);
* ``select``: the driver ``select_edges``; ``result``: ``SelectResult`` and the pruned graph.
"""
from __future__ import annotations

from .budget import DisconnectedFixedSet, EdgeSplit, parse_budget, split_edges
from .certificate import RatioCertificate
from .objectives import OBJECTIVES, FiedlerObjective, LogDetObjective, fim_objective, make_objective, tree_objective
from .relaxation import Relaxation, frank_wolfe, madow, polish_fiedler
from .result import SelectResult, pruned_graph
from .select import METHODS, select_edges

__all__ = [
    "METHODS", "OBJECTIVES", "DisconnectedFixedSet", "EdgeSplit", "FiedlerObjective", "LogDetObjective",
    "RatioCertificate", "Relaxation", "SelectResult", "fim_objective", "frank_wolfe", "madow",
    "make_objective", "parse_budget", "polish_fiedler", "pruned_graph", "select_edges", "split_edges",
    "tree_objective",
]
