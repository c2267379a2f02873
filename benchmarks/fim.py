"""Paper-model FIM and CRLB timings per shared dataset.

For every dataset found (or the NAMEs given) prints, median of REPEAT runs after a warm-up:
  build     paper_fim (COO assembly from the edge arrays, anchor removed)
  logdet    fim_logdet with a fresh CHOLMOD analysis (analysis + factorization + log-det)
  b+ld      the two together (target: ais2klinik <= 0.25 s)
  blocks    every per-pose (q x q) diagonal block of F^{-1}: block padding, analysis,
            factorization and selected inversion (what GTSAM's Marginals.marginalCovariance
            over all poses computes; GTSAM 4.3 here: sphere2500 ~7.0 s, city10000 ~7.9 s)
  crlb      paper_crlb(per_pose=True) end to end: build + blocks (+ the 3D curvature term,
            which needs a second selected inversion of the rotation block)
The estimate is the file's vertices, or for edge-only files an odometry estimate composed
along a BFS spanning tree (the FIM's cost does not depend on the estimate's values).
Usage: python benchmarks/fim.py [--repeat K] [NAME ...]
"""
from __future__ import annotations

from collections import deque

import numpy as np
from _common import dataset_args, median_time

from posecrb import load
from posecrb.linalg.selinv import inverse_block_diagonal
from posecrb.models.paper.crlb import paper_crlb
from posecrb.models.paper.fim import fim_logdet, paper_fim

GTSAM = {"sphere2500": 7.0, "city10000": 7.9}




def odometry_estimate(g):
    """Compose measurements along a BFS tree from pose 0 (a loop: benchmark helper only)."""
    adj = [[] for _ in range(g.n)]
    for e, (i, j) in enumerate(zip(g.src, g.dst)):
        adj[i].append((e, j, True))
        adj[j].append((e, i, False))
    rot = np.repeat(np.eye(g.dim)[None], g.n, axis=0)
    trans = np.zeros((g.n, g.dim))
    seen = np.zeros(g.n, bool)
    seen[0] = True
    queue = deque([0])
    while queue:
        i = queue.popleft()
        for e, j, forward in adj[i]:
            if seen[j]:
                continue
            if forward:  # X_j = X_i Z
                rot[j] = rot[i] @ g.rot[e]
                trans[j] = trans[i] + rot[i] @ g.trans[e]
            else:        # X_j = X_i Z^{-1}
                rot[j] = rot[i] @ g.rot[e].T
                trans[j] = trans[i] - rot[j] @ g.trans[e]
            seen[j] = True
            queue.append(j)
    return rot, trans


def graphs_at_estimates(files, width: int):
    """(graph, rotations, translations) of each connected file: its vertices, or an odometry
    estimate for edge-only files; a disconnected one is a printed line (name padded to ``width``)."""
    for f in files:
        g = load(f)
        if g.n_components != 1:
            print(f"{g.name:{width}s} {g.n:6d} disconnected, skipped")
            continue
        yield (g, *((g.vertex_rot, g.vertex_trans) if g.has_vertices else odometry_estimate(g)))


def main() -> None:
    args, files = dataset_args(__doc__.splitlines()[0], repeat=5)
    print(f"{'dataset':26s} {'n':>6s} {'size':>6s} {'build':>7s} {'logdet':>7s} {'b+ld':>7s} "
          f"{'blocks':>7s} {'crlb':>7s} {'GTSAM':>6s} {'speedup':>7s}")
    for g, rot, trans in graphs_at_estimates(files, 26):
        t_build = median_time(lambda: paper_fim(g, rot, trans), args.repeat)
        fim = paper_fim(g, rot, trans)
        t_ld = median_time(lambda: fim_logdet(fim), args.repeat)
        fp = fim.to_layout("poses")
        t_blocks = median_time(lambda: inverse_block_diagonal(fp.matrix, fp.q), args.repeat)
        t_crlb = median_time(lambda: paper_crlb(g, rot, trans, per_pose=True), args.repeat)
        ref = GTSAM.get(g.name)
        extra = f"{ref:6.1f} {ref / t_blocks:6.1f}x" if ref else ""
        print(f"{g.name:26s} {g.n:6d} {fim.size:6d} {t_build:7.4f} {t_ld:7.4f} {t_build + t_ld:7.4f} "
              f"{t_blocks:7.4f} {t_crlb:7.4f} {extra}", flush=True)


if __name__ == "__main__":
    main()
