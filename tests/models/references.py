"""Dense references for the graph-only bounds, straight from the paper's definitions."""
from __future__ import annotations

import mpmath as mp
import numpy as np

from ..numerics import EPS, MARGIN, logdet_atol, sum_atol


def omega_ref(k):
    mp.mp.dps = 50
    x = 2 * mp.mpf(float(k))
    i = [mp.besseli(v, x) for v in range(4)]
    return float(k ** 2 * (2 * i[0] - i[1] - 2 * i[2] + i[3]) / (2 * i[0] - 2 * i[1]))


def dense_reference(g, anchor):
    """Every quantity straight from the paper's definitions, one edge at a time."""
    d, dr, n = g.dim, g.rot_dim, g.n
    a0 = np.zeros((n, g.m))
    tau, w = np.zeros(g.m), np.zeros(g.m)
    psi = np.zeros((n, dr, dr))
    xi = np.zeros(n)
    for e in range(g.m):
        i, j = g.src[e], g.dst[e]
        a0[i, e], a0[j, e] = -1, 1
        tau[e] = d / np.trace(np.linalg.inv(g.info[e, :d, :d]))
        if d == 2:
            w[e] = 2 * g.info[e, 2, 2]
        else:
            w[e] = omega_ref(3 / (2 * np.trace(np.linalg.inv(g.info[e, 3:, 3:])))) / 3
        p = g.trans[e]
        if d == 2:
            psi[i] += tau[e] * p @ p
            xi[i] += tau[e] * p @ p
        else:
            psi[i] += 0.5 * tau[e] * ((p @ p) * np.eye(3) - np.outer(p, p))
            xi[i] += 0.5 * tau[e] * p @ p
    keep = np.arange(n) != anchor
    a = a0[keep]
    l_tau, l_w = a @ np.diag(tau) @ a.T, a @ np.diag(w) @ a.T
    big = np.kron(l_w, np.eye(dr))
    for r, i in enumerate(np.flatnonzero(keep)):
        big[r * dr:(r + 1) * dr, r * dr:(r + 1) * dr] += psi[i]
    ld = lambda m: np.linalg.slogdet(m)[1]
    lam_inf = xi[keep].max()
    eig_w = np.linalg.eigvalsh(l_w)
    deg = np.abs(a0).sum(1)
    big_tol = logdet_atol(big)
    return {
        "tol": {"lb": d * logdet_atol(l_tau) + dr * logdet_atol(l_w),
                "ub": d * logdet_atol(l_tau) + big_tol,
                "ub_lambda": d * logdet_atol(l_tau) + dr * logdet_atol(l_w + lam_inf * np.eye(len(l_w))),
                "lambda_min_rot": MARGIN * len(l_w) * EPS * np.abs(eig_w).max(),
                "lambda_inf": sum_atol(xi),
                "t_opt_graph": sum_atol(np.concatenate([tau, w])) * 4},
        "lb": d * ld(l_tau) + dr * ld(l_w),
        "ub": d * ld(l_tau) + ld(big),
        "ub_lambda": d * ld(l_tau) + dr * np.sum(np.log(eig_w + lam_inf)),  # eq. 75 via eigenvalues
        "lambda_inf": lam_inf,
        "lambda_min_rot": eig_w[0],
        "gap_bound": dr * (n - 1) * np.log(1 + lam_inf / eig_w[0]),
        "t_opt_graph": sum(d * tau[e] + dr * w[e] for e in range(g.m) for v in (g.src[e], g.dst[e]) if v != anchor),
        "t_opt_approx": None,
        "total_degree": deg[keep].sum(),
        "psi_trace_sum": sum(np.trace(psi[i]) for i in np.flatnonzero(keep)),
    }
