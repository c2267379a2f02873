"""What a selection may choose from and how many: the budget K and the split of the edges into
fixed edges F and candidates C (docs/design.md#glossary).

A budget is ``K`` edges or a fraction of the candidates (rounded down, as MAC does); the command
line's ``--budget`` spells the fraction ``P%`` (``budget_value``). ``--fixed`` is
``odometry`` (the edges between consecutive pose ids, joined into a connected set by the heaviest
candidates where the chain is broken) or a text file of pose-id pairs, read through the input
layer (``posecrb.io.lines.read_lines``).
"""
from __future__ import annotations

import logging
import math
import numbers
import re
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..core.errors import ArgumentError, ParseError, PosecrbError
from ..core.graph import PoseGraph, connected_components
from ..core.integers import IntegerError, parse_int
from ..io.lines import read_lines

log = logging.getLogger("posecrb")

FIXED_RULES = ("odometry",)


class DisconnectedFixedSet(PosecrbError):
    """The fixed edges do not connect the graph, so the base objective is -inf."""


def budget_count(budget: int | float, n_candidates: int) -> int:
    """K from a budget: a number of edges K (an integer), or a fraction of the candidates in (0, 1]
    (a float, rounded down as MAC does). ``ArgumentError`` naming ``budget`` otherwise: not a
    number, K < 1, more than the candidates, a fraction outside (0, 1] or rounding down to 0."""
    if isinstance(budget, (bool, np.bool_)) or not isinstance(budget, numbers.Real):
        raise ArgumentError("budget", budget, "is not a number of edges K (an integer) or a fraction of the "
                            "candidates in (0, 1] (a float)")
    if isinstance(budget, numbers.Integral):
        k = int(budget)
        if k <= 0:
            raise ArgumentError("budget", k, "is not a number of edges >= 1")
        if k > n_candidates:
            raise ArgumentError("budget", k, f"exceeds the {n_candidates} candidate edge(s)")
        return k
    fraction = float(budget)
    if not (math.isfinite(fraction) and 0 < fraction <= 1):
        raise ArgumentError("budget", budget, "is not a fraction of the candidates in (0, 1] (a number of edges "
                            "is an integer)")
    k = math.floor(fraction * n_candidates + 1e-9)
    if k < 1:
        raise ArgumentError("budget", budget, f"of {n_candidates} candidate edge(s) rounds down to 0 edges")
    return k


def budget_value(spec: str | int | float) -> int | float:
    """The command line's budget (``K`` or ``P%`` of the candidates) as the library takes it: the
    integer K or the fraction P / 100 (numbers pass as they are). ``ArgumentError`` naming
    ``budget`` for anything else, or a percentage outside (0, 100]."""
    if isinstance(spec, (int, float)) and not isinstance(spec, bool):
        return spec
    text = str(spec).strip()
    m = re.fullmatch(r"([0-9]+(?:\.[0-9]*)?|\.[0-9]+)\s*%", text)
    if m:
        pct = float(m.group(1))
        if not 0 < pct <= 100:
            raise ArgumentError("budget", text, "is not a percentage in (0, 100]")
        return pct / 100.0
    if re.fullmatch(r"[+-]?[0-9]+", text) is None:
        raise ArgumentError("budget", text, "is not K or P%: expected a number of edges K or a percentage P% of "
                            "the candidates")
    try:
        return parse_int(text)
    except IntegerError:       # beyond int64 (never int() of thousands of digits): too many edges, or < 1
        return -1 if text.startswith("-") else 2 ** 63


def budget_spec(budget: int | float) -> str:
    """How a budget is shown (the JSON's ``budget_spec``): K, or the fraction as a percentage."""
    if isinstance(budget, numbers.Integral):
        return str(int(budget))
    return f"{100 * float(budget):.12g}%"


def parse_budget(spec: str | int | float, n_candidates: int) -> int:
    """``K`` or ``P%`` of the candidates (``budget_value``) -> K (``budget_count``)."""
    return budget_count(budget_value(spec), n_candidates)


@dataclass(frozen=True)
class EdgeSplit:
    """Fixed edges and candidates, as indices into the graph's edges (file order)."""

    fixed: np.ndarray            # (f,) sorted
    candidates: np.ndarray       # (c,) sorted
    rule: str                    # "odometry" or the path of a pairs file
    connectivity: np.ndarray     # edges added to the odometry chain to connect it (subset of fixed)


def _connecting_edges(graph: PoseGraph, fixed_mask: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Candidate edges that connect the components of the fixed edges: a maximum-weight spanning
    forest of the graph whose nodes are those components (heaviest parallel edge per pair)."""
    nc, labels = connected_components(graph.n, graph.src[fixed_mask], graph.dst[fixed_mask])
    if nc == 1:
        return np.zeros(0, dtype=np.int64)
    # scipy.sparse.csgraph loads scipy.sparse.linalg and scipy.linalg, a large part of a small
    # command's start-up (docs/decisions/fixed-costs.md): only a broken chain pays
    from scipy.sparse.csgraph import minimum_spanning_tree  # noqa: PLC0415 -- lazy: start-up time

    cand = np.flatnonzero(~fixed_mask)
    a, b = labels[graph.src[cand]], labels[graph.dst[cand]]
    cross = a != b
    cand, a, b = cand[cross], a[cross], b[cross]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((cand, -weight[cand], hi, lo))   # per pair: heaviest first, then file order
    cand, lo, hi = cand[order], lo[order], hi[order]
    first = np.ones(cand.size, dtype=bool)
    first[1:] = (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
    cand, lo, hi = cand[first], lo[first], hi[first]
    # minimum spanning forest on 1/w = maximum weight (distinct pairs, so no duplicate summing)
    mst = minimum_spanning_tree(sp.coo_matrix((1.0 / weight[cand], (lo, hi)), shape=(nc, nc))).tocoo()
    pair_pos = np.searchsorted(lo * nc + hi, np.minimum(mst.row, mst.col) * nc + np.maximum(mst.row, mst.col))
    # lo*nc+hi is sorted because of the lexsort on (lo, hi)
    return np.sort(cand[pair_pos])


def split_edges(graph: PoseGraph, fixed: str = "odometry") -> EdgeSplit:
    """Fixed edges and candidates.

    ``"odometry"``: every edge between poses that are consecutive in id order (MAC's
    ``|i - j| = 1`` on contiguous ids), plus, when that chain does not connect the graph, the
    heaviest candidates (translation precision tau) of a spanning forest joining its pieces
    (listed in ``connectivity``). Otherwise ``fixed`` is the path of a text file of pose-id
    pairs ``i j`` (one per line, ``#`` comments), every edge between a listed pair is fixed;
    the fixed set must connect the graph. Raises DisconnectedGraph when the whole graph is
    disconnected, ParseError for a pair that is no edge, DisconnectedFixedSet otherwise.
    """
    graph.require_connected()
    if fixed == "odometry":
        mask = np.abs(graph.src - graph.dst) == 1
        extra = _connecting_edges(graph, mask, graph.tau)
        if extra.size:
            log.warning("%s: the odometry chain is not connected; %d loop closure(s) fixed to connect it: %s",
                        graph.name, extra.size, ", ".join(f"{graph.ids[graph.src[e]]}-{graph.ids[graph.dst[e]]}"
                                                          for e in extra[:8]) + (" ..." if extra.size > 8 else ""))
            mask[extra] = True
        rule = "odometry"
    else:
        mask = _fixed_from_file(graph, fixed)
        extra = np.zeros(0, dtype=np.int64)
        nc, labels = connected_components(graph.n, graph.src[mask], graph.dst[mask])
        if nc > 1:
            sizes = np.bincount(labels)
            raise DisconnectedFixedSet(
                f"{fixed}: the fixed edges leave the graph in {nc} pieces (sizes "
                f"{', '.join(map(str, sorted(sizes.tolist(), reverse=True)[:6]))}{', ...' if nc > 6 else ''}); "
                "the fixed set must connect every pose (add odometry pairs or use --fixed odometry)")
        rule = str(fixed)
    fixed_idx = np.flatnonzero(mask)
    cand = np.flatnonzero(~mask)
    return EdgeSplit(fixed=fixed_idx, candidates=cand, rule=rule, connectivity=extra)


def _fixed_from_file(graph: PoseGraph, path: str) -> np.ndarray:
    pairs, where = [], []
    # the input layer: regular files only, size-guarded, gzip, UTF-8, the g2o reader's line rules
    for line in read_lines(path):
        tok = line.fields()
        if not tok:
            continue
        if len(tok) != 2 or not all(re.fullmatch(r"[0-9]{1,18}", t) for t in tok):
            raise ParseError(path, line.number, f"expected two pose ids 'i j', got {line.text.strip()!r}")
        pairs.append((int(tok[0]), int(tok[1])))
        where.append(line.number)
    if not pairs:
        raise ParseError(path, None, "no pose-id pairs in the fixed-edge file")
    p = np.array(pairs, dtype=np.int64)
    # pose ids -> internal indices (ids are sorted); unknown ids make the pair unknown
    pos = np.minimum(np.searchsorted(graph.ids, p), graph.n - 1)
    known = (graph.ids[pos] == p).all(axis=1)
    lo, hi = np.minimum(pos[:, 0], pos[:, 1]), np.maximum(pos[:, 0], pos[:, 1])
    n = graph.n
    ekey = np.minimum(graph.src, graph.dst) * n + np.maximum(graph.src, graph.dst)
    pkey = np.where(known, lo * n + hi, -1)
    known &= np.isin(pkey, ekey)
    if not known.all():
        k = int(np.flatnonzero(~known)[0])
        raise ParseError(path, where[k], f"no edge between pose ids {pairs[k][0]} and {pairs[k][1]} in {graph.name}")
    return np.isin(ekey, pkey)
