"""MKL PARDISO's log-determinant through ctypes, for benchmarks/factor_candidates.py only.

PARDISO is Intel oneMKL's parallel sparse direct solver. This binding factors a symmetric
positive definite matrix (``mtype = 2``, Cholesky) with PARDISO's own nested dissection (METIS,
``iparm[1] = 2``) or a given fill-reducing ordering (``iparm[4] = 1``, the same convention as
CHOLMOD's ``P()``: the k-th pivot is row ``perm[k]``), and reads the log-determinant from the
factor's diagonal (``pardiso_getdiag`` after ``iparm[55] = 1``: for ``mtype = 2`` the diagonal
of the factorized matrix is L's squared pivots, so log det A is the sum of their logarithms).
The two-level factorization (``iparm[23] = 1``) is used: it ran faster than the classic one on the
3D grid of 21,952 poses, 7.35 against 8.88 s on two threads (Intel machine, 2026-11-27). The
flop count is PARDISO's own (``iparm[18]``, Mflop), never the flop limit's.

The library is found through ``$POSECRB_MKL_RT`` (the path of ``libmkl_rt.so``; for example from
``python -m venv mkl && mkl/bin/pip install mkl``, then ``mkl/lib/libmkl_rt.so.3``); where it is
unset or does not load, ``Unavailable`` says why and the candidate is skipped. The threads are
MKL's: ``MKL_NUM_THREADS`` (the candidate's ``1t`` sets it to 1).
"""
from __future__ import annotations

import ctypes
import os
import time

import numpy as np
import scipy.sparse as sp


class Unavailable(RuntimeError):
    pass


class NotPositiveDefinite(RuntimeError):
    pass


def library() -> ctypes.CDLL:
    """libmkl_rt from ``$POSECRB_MKL_RT``; ``Unavailable`` with the reason otherwise."""
    path = os.environ.get("POSECRB_MKL_RT")
    if not path:
        raise Unavailable("skipped: set POSECRB_MKL_RT to the path of MKL's libmkl_rt.so")
    try:
        lib = ctypes.CDLL(path)
        lib.pardiso, lib.pardiso_getdiag  # noqa: B018 -- both symbols must exist
    except (OSError, AttributeError) as exc:
        raise Unavailable(f"skipped: MKL PARDISO does not load from {path} ({exc})") from None
    return lib


def _int_p(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_int))


def _double_p(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


# PARDISO's error codes (oneMKL reference, ``pardiso``): the ones a log-det can meet
_ERRORS = {-1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
           -4: "zero pivot, numerical factorization or iterative refinement problem",
           -7: "diagonal matrix is singular", -8: "32-bit integer overflow problem",
           -10: "error opening OOC files", -11: "read/write error with OOC files"}


def logdet(a: sp.spmatrix, perm: np.ndarray | None = None) -> dict:
    """log det ``a`` (sparse SPD) by PARDISO: its ordering (or ``perm``), analysis and factorization
    wall times, flops and factor entries as PARDISO counts them; ``NotPositiveDefinite`` for a
    matrix PARDISO's Cholesky rejects."""
    lib = library()
    n = a.shape[0]
    upper = sp.triu(sp.csr_matrix(a)).tocsr()
    upper.sort_indices()
    ia = (upper.indptr + 1).astype(np.int32)
    ja = (upper.indices + 1).astype(np.int32)
    values = np.ascontiguousarray(upper.data, dtype=np.float64)
    handle = np.zeros(64, dtype=np.int64)
    iparm = np.zeros(64, dtype=np.int32)
    iparm[0] = 1            # these values, not the defaults
    iparm[1] = 2            # METIS nested dissection (when no ordering is given)
    iparm[17] = -1          # report the factor's entries
    iparm[18] = -1          # report the factorization's Mflops
    iparm[23] = 1           # two-level factorization
    iparm[55] = 1           # keep the factor's diagonal for pardiso_getdiag
    order = np.zeros(n, dtype=np.int32)
    if perm is not None:
        iparm[4] = 1
        order = (np.asarray(perm) + 1).astype(np.int32)
    ints = {name: ctypes.c_int(v) for name, v in (("maxfct", 1), ("mnum", 1), ("mtype", 2), ("n", n),
                                                  ("nrhs", 0), ("msglvl", 0), ("error", 0))}
    dummy = np.zeros(1)

    def call(phase: int, check: bool = True) -> None:
        ph = ctypes.c_int(phase)
        lib.pardiso(handle.ctypes.data_as(ctypes.c_void_p), ctypes.byref(ints["maxfct"]),
                    ctypes.byref(ints["mnum"]), ctypes.byref(ints["mtype"]), ctypes.byref(ph),
                    ctypes.byref(ints["n"]), _double_p(values), _int_p(ia), _int_p(ja), _int_p(order),
                    ctypes.byref(ints["nrhs"]), _int_p(iparm), ctypes.byref(ints["msglvl"]),
                    _double_p(dummy), _double_p(dummy), ctypes.byref(ints["error"]))
        code = ints["error"].value
        if code and check:
            reason = _ERRORS.get(code, f"error {code}")
            if code == -4:
                raise NotPositiveDefinite(f"not positive definite (PARDISO: {reason})")
            raise RuntimeError(f"PARDISO phase {phase}: {reason}")

    try:
        t0 = time.perf_counter()
        call(11)
        t1 = time.perf_counter()
        call(22)
        t2 = time.perf_counter()
        factored = np.zeros(n)
        original = np.zeros(n)
        lib.pardiso_getdiag(handle.ctypes.data_as(ctypes.c_void_p), _double_p(factored), _double_p(original),
                            ctypes.byref(ints["mnum"]), ctypes.byref(ints["error"]))
        if ints["error"].value:
            raise RuntimeError(f"pardiso_getdiag: error {ints['error'].value}")
    finally:
        call(-1, check=False)   # release PARDISO's memory, also after a failure (whose error counts)
    if not np.all(factored > 0):
        raise NotPositiveDefinite("not positive definite (a pivot of PARDISO's factor is not positive)")
    return {"analyse": t1 - t0, "factor": t2 - t1, "logdet": float(np.sum(np.log(factored))),
            "flops": float(iparm[18]) * 1e6, "lnz": float(iparm[17]), "two_level": int(iparm[23])}
