"""Fisher information and Cramér-Rao bounds at the file's vertices: ``posecrb.fim`` and ``posecrb.crlb``,
the fill-reducing orderings of their factorizations, and the FIM log-det against its flop limit
(CHOLMOD's flop count and its BLAS's dgemm rate, read through ctypes)."""
from __future__ import annotations

from . import inputs
from .common import Benchmark

# The orderings compared (``ordering=`` of fim, crlb and bounds); auto is posecrb's rule.
ORDERINGS = ("auto", "amd", "metis", "nesdis")


class Fim(Benchmark):
    """The paper FIM (eq. 42 / 64), its log-det and the log-det's accuracy bound."""

    params = [inputs.WITH_VERTICES + inputs.GRIDS]

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.fim(graph, estimate="vertices"))

    def time_fim(self, name: str) -> None:
        self.call(self.input)

    def peakmem_fim(self, name: str) -> None:
        self.call(self.input)


class Crlb(Benchmark):
    """The paper model's CRLB trace (eq. 67, with eq. 68's curvature term in 3D)."""

    params = Fim.params

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.crlb(graph, estimate="vertices"))

    def time_crlb(self, name: str) -> None:
        self.call(self.input)

    def peakmem_crlb(self, name: str) -> None:
        self.call(self.input)


class CrlbPerPose(Benchmark):
    """Every pose's covariance block of the sed model's anchored bound in GTSAM's coordinates
    (``crlb(model="sed", frame="body", poses="all")``): what GTSAM's ``Marginals`` computes
    (benchmarks/peers/gtsam_marginals.py compares the two as whole processes)."""

    params = [(inputs.GRID_3D_SMALL,) if inputs.QUICK else ("intel", "city10000", "sphere2500", "torus3D")]

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.crlb(graph, model="sed", frame="body", estimate="vertices",
                                                      poses="all"))

    def time_crlb_per_pose(self, name: str) -> None:
        self.call(self.input)


class Orderings(Benchmark):
    """``fim`` with each fill-reducing ordering: the data behind ``ordering="auto"`` (the 3D grid of
    5,832 poses, not 21,952: there AMD's factor alone takes 895 Gflop, and its flop counts are in
    docs/decisions/orderings.md)."""

    params = [(inputs.GRID_3D_SMALL,) if inputs.QUICK else ("city10000", "sphere2500", "grid2d-100000", "grid3d-5000"),
              ORDERINGS]
    param_names = ["input", "ordering"]

    def setup(self, name: str, ordering: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.fim(graph, estimate="vertices", ordering=ordering))

    def time_fim(self, name: str, ordering: str) -> None:
        self.call(self.input)


class FimFlopLimit(Benchmark):
    """The FIM log-det at the file's vertices against its flop limit: the cost goal of at most 1.6x
    for the 3D grid of 21,952 poses (``grid3d-20000``), median of 3 runs.

    * measured: the ``fim_logdet`` stage time of ``posecrb.fim(estimate="vertices")``, posecrb's own
      path of the log-det as ``bounds`` and ``fim`` take it: the ordering (``--ordering auto``:
      METIS on the pose graph for 3D graphs from 10,000 poses, AMD below), CHOLMOD's analysis, the
      numeric factorization and the log-det of the anchored paper FIM (eq. 64), with posecrb's
      thread policy; the median of 3 calls.
    * flops: CHOLMOD's own count of that factorization, ``Common->fl`` of its symbolic analysis with
      the same ordering (``factor_flops``): the sum over the columns of L of the squared column
      count, diagonal included, before relaxed amalgamation adds explicit zeros.
    * limit: flops / the dgemm rate of the BLAS CHOLMOD calls, on every core of the process, measured
      in the same process right before the runs (``dgemm_rate``).

    ``track_limit_ratio`` is measured / limit; ``track_seconds``, ``track_gflop`` and
    ``track_dgemm_rate`` are its parts, all from one measurement (asv's ``setup_cache``). Skipped
    (asv's n/a) with the reason where CHOLMOD is not the 3.0.x binding ``cholmod_flops`` knows or
    its BLAS cannot be found."""

    params = [(inputs.GRID_3D_SMALL,) if inputs.QUICK else ("grid3d-20000",)]
    unit = "x flop limit"
    timeout = 1800.0

    def setup_cache(self) -> dict[str, dict[str, float] | str]:
        """Every input's figures (or the reason it cannot be measured), in one process."""
        out: dict[str, dict[str, float] | str] = {}
        for name in self.params[0]:
            try:
                out[name] = self.measure(name)
            except NotImplementedError as exc:
                out[name] = str(exc)
        return out

    def measure(self, name: str, runs: int = 3) -> dict[str, float]:
        """The figures of one input: the dgemm rate (3000 x 3000, best of 2 s; the quick suite's
        1000 x 1000, 0.3 s, only shows the benchmark runs), then ``runs`` calls of ``fim`` on the
        graph read once, then the flop count of the last call's matrix and ordering."""
        import statistics

        import posecrb

        self.warm_up(name, lambda graph: posecrb.fim(graph, estimate="vertices"))
        graph = posecrb.load(inputs.path(name))
        rate = dgemm_rate(*((1000, 0.3) if inputs.QUICK else (3000, 2.0)))
        times = []
        for _ in range(runs):
            res = posecrb.fim(graph, estimate="vertices")
            times.append(res.times["fim_logdet"])
        seconds = statistics.median(times)
        flops = factor_flops(res)
        return {"seconds": seconds, "gflop": flops / 1e9, "dgemm_rate": rate / 1e9,
                "limit_ratio": seconds * rate / flops}

    def setup(self, cache: dict, name: str) -> None:
        if isinstance(cache[name], str):
            raise NotImplementedError(cache[name])

    def track_limit_ratio(self, cache: dict, name: str) -> float:
        return cache[name]["limit_ratio"]

    def track_seconds(self, cache: dict, name: str) -> float:
        return cache[name]["seconds"]

    track_seconds.unit = "seconds"  # type: ignore[attr-defined]

    def track_gflop(self, cache: dict, name: str) -> float:
        return cache[name]["gflop"]

    track_gflop.unit = "Gflop"  # type: ignore[attr-defined]

    def track_dgemm_rate(self, cache: dict, name: str) -> float:
        return cache[name]["dgemm_rate"]

    track_dgemm_rate.unit = "GF/s"  # type: ignore[attr-defined]


# ---- CHOLMOD's flop count and its BLAS's dgemm rate, through ctypes ---------------------------------

# cholmod_common of CHOLMOD 3.0.x (SuiteSparse 5.x, LP64), offsets in bytes, read with offsetof from
# Debian 12's cholmod.h (SuiteSparse 5.12, CHOLMOD 3.0.14); cholmod_l_start's defaults are checked
# before any is trusted.
_COMMON_SIZE = 2664
_COMMON = {"supernodal": 48, "nmethods": 168, "method": 184, "postorder": 1864, "itype": 1960, "fl": 1976}
_METHOD_ORDERING = 132            # offset of ``ordering`` in the first cholmod_method_struct
_ORDERINGS = {"given": 1, "amd": 2, "metis": 3, "nesdis": 4}


def loaded_library(prefix: str) -> str:
    """The path of the shared library named ``prefix...`` that scikit-sparse's CHOLMOD extension
    brought into this process (``/proc/self/maps``); NotImplementedError where there is none."""
    import os

    import sksparse.cholmod  # noqa: F401  (CHOLMOD and the libraries it links)

    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "/" in line}
    except OSError:
        paths = set()
    found = sorted(p for p in paths if os.path.basename(p).startswith(prefix))
    if not found:
        raise NotImplementedError(f"no {prefix}* among the libraries of scikit-sparse's CHOLMOD (Linux only)")
    return found[0]


def _cholmod():
    """libcholmod as scikit-sparse loaded it, with the prototypes used here; NotImplementedError
    unless it is CHOLMOD 3.0.x (the struct layout ``_COMMON`` describes)."""
    import ctypes

    lib = ctypes.CDLL(loaded_library("libcholmod.so"))
    version = (ctypes.c_int * 3)()
    lib.cholmod_l_version(version)
    if (version[0], version[1]) != (3, 0):
        raise NotImplementedError(f"CHOLMOD {'.'.join(map(str, version))}: the flop count reads the struct layout "
                                  "of CHOLMOD 3.0.x only")
    vp = ctypes.c_void_p
    lib.cholmod_l_start.argtypes = lib.cholmod_l_finish.argtypes = [vp]
    lib.cholmod_l_analyze_p.argtypes = [vp, vp, vp, ctypes.c_size_t, vp]
    lib.cholmod_l_analyze_p.restype = vp
    lib.cholmod_l_free_factor.argtypes = [ctypes.POINTER(vp), vp]
    return lib


def cholmod_flops(a, ordering: str = "given", perm=None) -> float:
    """CHOLMOD's flop count (``Common->fl``) of the Cholesky factorization of the symmetric sparse
    ``a``: ``cholmod_l_analyze_p`` with the one ``ordering`` (amd, metis, nesdis, or ``given`` with
    the row permutation ``perm``, ``L L^T = A[perm][:, perm]``), simplicial, so that no
    supernodal amalgamation is analysed. The sum over the columns j of L of c_j^2 (c_j: the column
    count of L, diagonal included), independent of the etree postordering CHOLMOD applies."""
    import ctypes
    import struct

    import numpy as np
    import scipy.sparse as sp

    lib = _cholmod()
    common = ctypes.create_string_buffer(_COMMON_SIZE + 1024)
    lib.cholmod_l_start(common)
    try:
        defaults = [struct.unpack_from("<i", common, _COMMON[k])[0] for k in ("supernodal", "nmethods", "postorder",
                                                                             "itype")]
        if defaults != [1, 0, 1, 2]:      # CHOLMOD_AUTO, nmethods 0, postorder on, CHOLMOD_LONG
            raise NotImplementedError(f"cholmod_common's layout differs from CHOLMOD 3.0's (defaults read {defaults})")
        struct.pack_into("<i", common, _COMMON["supernodal"], 0)          # CHOLMOD_SIMPLICIAL
        struct.pack_into("<i", common, _COMMON["nmethods"], 1)
        struct.pack_into("<i", common, _COMMON["method"] + _METHOD_ORDERING, _ORDERINGS[ordering])
        upper = sp.triu(sp.csc_matrix(a), format="csc")
        upper.sort_indices()
        p, i = upper.indptr.astype(np.int64), upper.indices.astype(np.int64)
        x = np.ascontiguousarray(upper.data, dtype=np.float64)
        # cholmod_sparse: nrow, ncol, nzmax, p, i, nz, x, z, stype, itype, xtype, dtype, sorted, packed
        view = struct.pack("<3Q5Q6i", a.shape[0], a.shape[1], x.size, p.ctypes.data, i.ctypes.data, 0, x.ctypes.data,
                           0, 1, 2, 1, 0, 1, 1)
        order = None if perm is None else np.ascontiguousarray(perm, dtype=np.int64)
        if (ordering == "given") != (order is not None):
            raise ValueError("a permutation goes with ordering='given', and only with it")
        factor = ctypes.c_void_p(lib.cholmod_l_analyze_p(ctypes.create_string_buffer(view, len(view)),
                                                         None if order is None else order.ctypes.data, None, 0,
                                                         common))
        if not factor.value:
            raise MemoryError("cholmod_l_analyze_p failed")
        lib.cholmod_l_free_factor(ctypes.byref(factor), common)
        return float(struct.unpack_from("<d", common, _COMMON["fl"])[0])
    finally:
        lib.cholmod_l_finish(common)


def pose_ordering(res, method: str):
    """The row permutation of posecrb's pose-level ``method`` ordering of a ``FimResult``'s matrix:
    CHOLMOD's ``method`` on the pose graph read from the matrix's pattern (the poses numbered in
    the order the rows list them), every pose's rows together in their own order."""
    import numpy as np
    import scipy.sparse as sp
    from sksparse.cholmod import analyze

    a = sp.coo_matrix(res.matrix)
    _, first, pose = np.unique(np.asarray(res.row_ids), return_index=True, return_inverse=True)
    number = np.empty(first.size, dtype=np.int64)
    number[np.argsort(first, kind="stable")] = np.arange(first.size)
    pose_of_row = number[pose.ravel()]
    n = first.size
    graph = sp.csc_matrix((np.ones(a.nnz), (pose_of_row[a.row], pose_of_row[a.col])), shape=(n, n))
    graph.sum_duplicates()
    graph = (sp.csc_matrix((np.ones(graph.nnz), graph.indices, graph.indptr), shape=(n, n))
             + sp.identity(n, format="csc")).tocsc()
    pose_order = np.asarray(analyze(graph, ordering_method=method).P(), dtype=np.int64)
    position = np.empty(n, dtype=np.int64)
    position[pose_order] = np.arange(n)
    return np.argsort(position[pose_of_row], kind="stable")


def factor_flops(res) -> float:
    """CHOLMOD's flop count of the log-det factorization of a ``FimResult`` (``posecrb.fim``) with
    the ordering it reports using: CHOLMOD's own (``amd``) or a pose-level one (``metis (pose
    graph)``, ``nesdis (pose graph)``: ``pose_ordering``)."""
    method, _, level = res.ordering["fim"].partition(" ")
    if level == "(pose graph)":
        return cholmod_flops(res.matrix, "given", pose_ordering(res, method))
    if method not in _ORDERINGS or level:
        raise NotImplementedError(f"the flop count of the {res.ordering['fim']} ordering")
    return cholmod_flops(res.matrix, method)


def dgemm_rate(n: int = 3000, seconds: float = 2.0) -> float:
    """Flop/s of ``dgemm_`` (C = A B, n x n) of the BLAS CHOLMOD calls, on every core of this process
    (threadpoolctl), the best of the runs that fit in ``seconds``.

    The library is the ``libblas.so.3`` scikit-sparse's CHOLMOD links, as loaded in this process:
    on Debian the interface of libopenblas0-pthread (``/usr/lib/x86_64-linux-gnu/openblas-pthread/``),
    whose ``dgemm_`` is OpenBLAS's, the one CHOLMOD's supernodal factorization calls.
    NotImplementedError where it cannot be found."""
    import ctypes
    import math
    import os
    import time

    import numpy as np
    from threadpoolctl import threadpool_limits

    blas = ctypes.CDLL(loaded_library("libblas.so"))
    a = np.asfortranarray(np.random.default_rng(0).standard_normal((n, n)))
    b, c = a.copy(order="F"), np.zeros((n, n), order="F")
    size, one, zero, plain = ctypes.c_int(n), ctypes.c_double(1.0), ctypes.c_double(0.0), ctypes.c_char(b"N")
    args = [ctypes.byref(plain), ctypes.byref(plain), *[ctypes.byref(size)] * 3, ctypes.byref(one),
            ctypes.c_void_p(a.ctypes.data), ctypes.byref(size), ctypes.c_void_p(b.ctypes.data), ctypes.byref(size),
            ctypes.byref(zero), ctypes.c_void_p(c.ctypes.data), ctypes.byref(size)]
    best, end = math.inf, time.perf_counter() + seconds
    with threadpool_limits(limits=len(os.sched_getaffinity(0)), user_api="blas"):
        while True:
            start = time.perf_counter()
            blas.dgemm_(*args)
            best = min(best, time.perf_counter() - start)
            if time.perf_counter() > end:
                break
    return 2.0 * n ** 3 / best
