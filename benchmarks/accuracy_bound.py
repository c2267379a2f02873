"""The FIM log-det's rounding-error bound: the exact sum over the factor's pattern against a norm bound.

``posecrb.linalg.accuracy.logdet_accuracy`` bounds the error of ``log det A`` computed by Cholesky
by ``gamma * sum_ij |(A^{-1})_ij| (|L| |L^T|)_ij`` (one selected inversion, about twice the
factorization's flops). Bounding each ``|(A^{-1})_ij|`` by ``||A^{-1}||_2`` instead gives
``gamma * || |L|^T 1 ||^2 * ||A^{-1}||_2``: one pass over L and a few dozen solves for the norm
(Lanczos on ``A^{-1}``), so seconds where the selected inversion takes tens of seconds, but looser.
For each file (the anchored paper FIM at the file's vertices, or at an odometry estimate for
edge-only files, as ``posecrb bounds --estimate vertices`` factors it) this prints the log-det,
both bounds, their ratio, the warning threshold (1e-6 |log det|: ``LOGDET_WARN``) and the
seconds of each, timed as ``--repeat auto`` times a stage (``posecrb.core.timing``: one run when
it takes a second or more, else the median of the runs that fit in about 2 s); --repeat K: a
warm-up and the median of K.
Usage: python benchmarks/accuracy_bound.py [--repeat K] [NAME ...]
"""
from __future__ import annotations

import numpy as np
from _common import dataset_args
from fim import graphs_at_estimates
from scipy.sparse.linalg import LinearOperator, eigsh

from posecrb.core.timing import timed
from posecrb.linalg.accuracy import LOGDET_WARN, logdet_accuracy
from posecrb.models.paper.fim import fim_symbolic, paper_fim

EPS = float(np.finfo(float).eps)


def norm_bound(factor, n: int) -> tuple[float, float, float]:
    """(gamma || |L|^T 1 ||^2 ||A^{-1}||_2, ||A^{-1}||_2, gamma) for the factor of an n x n matrix A;
    ``||A^{-1}||_2`` is the largest eigenvalue of A^{-1} by Lanczos (ARPACK, relative 1e-6)."""
    lower = factor.L().tocsc()
    colcount = int(np.diff(lower.indptr).max())
    gamma = (colcount + 2) * EPS
    colsum = np.asarray(abs(lower).sum(axis=0)).ravel()        # |L|^T 1
    inverse = LinearOperator((n, n), matvec=lambda v: factor.solve_A(v), dtype=float)
    inv_norm = float(eigsh(inverse, k=1, which="LA", tol=1e-6, return_eigenvectors=False,
                           v0=np.ones(n))[0])
    return gamma * float(colsum @ colsum) * inv_norm, inv_norm, gamma


def main() -> None:
    args, files = dataset_args(__doc__.splitlines()[0], repeat=0)
    runs = args.repeat or "auto"
    print(f"{'dataset':30s} {'rows':>7s} {'log det':>14s} {'exact bound':>12s} {'norm bound':>11s} {'ratio':>9s} "
          f"{'warn at':>9s} {'||A^-1||':>9s} {'exact s':>8s} {'norm s':>7s}")
    for g, rot, trans in graphs_at_estimates(files, 30):
        fim = paper_fim(g, rot, trans)
        factor, logdet = fim_symbolic(fim, "auto").factor_logdet(fim.matrix, name="paper FIM")
        exact, t_exact = timed(lambda: logdet_accuracy(factor, logdet, "paper FIM"), runs)
        n = fim.matrix.shape[0]
        (bound, inv_norm, _), t_norm = timed(lambda: norm_bound(factor, n), runs)
        print(f"{g.name:30s} {n:7d} {logdet:14.6f} {exact.error_bound:12.3e} {bound:11.3e} "
              f"{bound / exact.error_bound:9.3g} {LOGDET_WARN * max(1.0, abs(logdet)):9.3g} {inv_norm:9.3g} "
              f"{t_exact:8.3f} {t_norm:7.3f}")


if __name__ == "__main__":
    main()
