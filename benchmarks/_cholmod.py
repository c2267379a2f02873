"""CHOLMOD called directly through ctypes, for the factorization benchmarks only.

scikit-sparse (what posecrb uses) exposes neither CHOLMOD's supernodal amalgamation settings nor
its flop count, and holds the GIL while it factors, so two factorizations cannot run at once in
one process. This binding reaches them for ``benchmarks/factor_candidates.py``: ctypes releases
the GIL around every foreign call. It knows the struct layout of CHOLMOD 3.0 (SuiteSparse 5.x,
Debian 12), checks the version and the defaults ``cholmod_l_start`` writes before it trusts any
offset, and raises ``Unavailable`` otherwise (the benchmark then skips those candidates).
Offsets were read with ``offsetof`` from Debian's cholmod.h (SuiteSparse 5.12, CHOLMOD 3.0.14).
"""
from __future__ import annotations

import ctypes
import ctypes.util
import math
import struct

import numpy as np
import scipy.sparse as sp


class Unavailable(RuntimeError):
    pass


# cholmod_common (CHOLMOD 3.0.x, LP64): offsets in bytes
_COMMON_SIZE = 2664
_C = {"supernodal_switch": 40, "supernodal": 48, "final_asis": 52, "zrelax": 80, "nrelax": 104, "print": 144,
      "nmethods": 168, "method": 184, "postorder": 1864, "itype": 1960, "status": 1972, "fl": 1976, "lnz": 1984}
_METHOD_SIZE, _METHOD_ORDERING = 168, 132
# cholmod_factor
_F = {"n": 0, "minor": 8, "Perm": 16, "ColCount": 24, "nsuper": 104, "xsize": 120, "super": 144, "pi": 152,
      "px": 160, "x": 64, "is_ll": 180, "is_super": 184}
ORDERING = {"natural": 0, "given": 1, "amd": 2, "metis": 3, "nesdis": 4}
SIMPLICIAL, AUTO, SUPERNODAL = 0, 1, 2
NOT_POSDEF = 1


class _Sparse(ctypes.Structure):
    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("p", ctypes.c_void_p), ("i", ctypes.c_void_p), ("nz", ctypes.c_void_p), ("x", ctypes.c_void_p),
                ("z", ctypes.c_void_p), ("stype", ctypes.c_int), ("itype", ctypes.c_int), ("xtype", ctypes.c_int),
                ("dtype", ctypes.c_int), ("sorted", ctypes.c_int), ("packed", ctypes.c_int)]


_LIB = None


def library() -> ctypes.CDLL:
    global _LIB
    if _LIB is None:
        name = ctypes.util.find_library("cholmod") or "libcholmod.so.3"
        try:
            lib = ctypes.CDLL(name)
        except OSError as exc:
            raise Unavailable(f"CHOLMOD not loadable: {exc}") from None
        version = (ctypes.c_int * 3)()
        lib.cholmod_l_version(version)
        if version[0] != 3 or version[1] != 0:
            raise Unavailable(f"CHOLMOD {tuple(version)}: this binding knows the struct layout of 3.0.x only")
        vp = ctypes.c_void_p
        lib.cholmod_l_start.argtypes = [vp]
        lib.cholmod_l_finish.argtypes = [vp]
        lib.cholmod_l_analyze_p.argtypes = [vp, vp, vp, ctypes.c_size_t, vp]
        lib.cholmod_l_analyze_p.restype = vp
        lib.cholmod_l_factorize_p.argtypes = [vp, vp, vp, ctypes.c_size_t, vp, vp]
        lib.cholmod_l_factorize_p.restype = ctypes.c_int
        lib.cholmod_l_free_factor.argtypes = [ctypes.POINTER(vp), vp]
        lib.cholmod_l_bisect.argtypes = [vp, vp, ctypes.c_size_t, ctypes.c_int, vp, vp]
        lib.cholmod_l_bisect.restype = ctypes.c_int64
        _LIB = lib
    return _LIB


class Common:
    """One cholmod_common (a workspace per thread: CHOLMOD is thread-safe across Commons)."""

    def __init__(self) -> None:
        self.lib = library()
        self.buf = ctypes.create_string_buffer(_COMMON_SIZE + 1024)
        self.lib.cholmod_l_start(self.buf)
        got = (self.get("d", "supernodal_switch"), self.get("i", "supernodal"), self.get("3d", "zrelax"),
               self.get("3q", "nrelax"), self.get("i", "itype"))
        if got != (40.0, AUTO, (0.8, 0.1, 0.05), (4, 16, 48), 2):
            raise Unavailable(f"cholmod_common's layout differs from CHOLMOD 3.0's (defaults read {got})")
        self.set("i", "print", 0)

    def get(self, fmt: str, name: str):
        v = struct.unpack_from("<" + fmt, self.buf, _C[name])
        return v if len(v) > 1 else v[0]

    def set(self, fmt: str, name: str, *values) -> None:
        struct.pack_into("<" + fmt, self.buf, _C[name], *values)

    def set_ordering(self, method: str) -> None:
        self.set("i", "nmethods", 1)
        struct.pack_into("<i", self.buf, _C["method"] + _METHOD_ORDERING, ORDERING[method])

    def __del__(self) -> None:
        try:
            self.lib.cholmod_l_finish(self.buf)
        except Exception:
            pass


def _view(a: sp.csc_matrix) -> tuple[_Sparse, tuple]:
    """A cholmod_sparse of the upper triangle of the symmetric ``a`` (no copy of the values
    beyond scipy's triu), and the arrays it points into (keep them alive)."""
    u = sp.triu(a, format="csc")
    u.sort_indices()
    indptr, indices = u.indptr.astype(np.int64), u.indices.astype(np.int64)
    data = np.ascontiguousarray(u.data, dtype=np.float64)
    s = _Sparse(nrow=a.shape[0], ncol=a.shape[1], nzmax=data.size, p=indptr.ctypes.data, i=indices.ctypes.data,
                nz=None, x=data.ctypes.data, z=None, stype=1, itype=2, xtype=1, dtype=0, sorted=1, packed=1)
    return s, (indptr, indices, data)


def _array(addr: int, n: int, dtype) -> np.ndarray:
    if n == 0:
        return np.empty(0, dtype)
    ctype = ctypes.c_int64 if dtype == np.int64 else ctypes.c_double
    return np.ctypeslib.as_array((ctype * n).from_address(addr))


class Factorization:
    """Analysis (ordering ``method`` or a given ``perm``) and numeric factorizations of one pattern.

    ``flops`` and ``lnz`` are CHOLMOD's own counts from the analysis (before relaxed amalgamation
    adds explicit zeros); ``nrelax`` / ``zrelax`` are its amalgamation settings (None: defaults)."""

    def __init__(self, a: sp.spmatrix, method: str = "amd", perm: np.ndarray | None = None, *,
                 supernodal: int = SUPERNODAL, nrelax: tuple[int, int, int] | None = None,
                 zrelax: tuple[float, float, float] | None = None, postorder: bool = True) -> None:
        self.c = Common()
        self.c.set("i", "supernodal", supernodal)
        if nrelax:
            self.c.set("3q", "nrelax", *nrelax)
        if zrelax:
            self.c.set("3d", "zrelax", *zrelax)
        self.c.set("i", "postorder", int(postorder))
        self.n = a.shape[0]
        self.a, self.keep = _view(sp.csc_matrix(a))
        if perm is not None:
            self.perm = np.ascontiguousarray(perm, dtype=np.int64)
            self.c.set_ordering("given")
            pptr = self.perm.ctypes.data
        else:
            self.c.set_ordering(method)
            pptr = None
        self.L = ctypes.c_void_p(self.c.lib.cholmod_l_analyze_p(ctypes.byref(self.a), pptr, None, 0, self.c.buf))
        if not self.L.value:
            raise MemoryError(f"cholmod_l_analyze_p failed (status {self.c.get('i', 'status')})")
        self.flops = float(self.c.get("d", "fl"))
        self.lnz = float(self.c.get("d", "lnz"))

    def _field(self, name: str, fmt: str = "q"):
        return struct.unpack_from("<" + fmt, ctypes.string_at(self.L.value + _F[name], 8))[0]

    def factor(self, a: sp.spmatrix | None = None, beta: float = 0.0) -> None:
        """Numeric factorization of ``a + beta I`` (``a``: same pattern as analysed; default the
        analysed matrix itself). Releases the GIL. Raises ValueError when not positive definite."""
        if a is not None:
            self.a, self.keep = _view(sp.csc_matrix(a))
        b = (ctypes.c_double * 2)(beta, 0.0)
        self.c.lib.cholmod_l_factorize_p(ctypes.byref(self.a), b, None, 0, self.L, self.c.buf)
        if self.c.get("i", "status") == NOT_POSDEF or self._field("minor") < self.n:
            raise ValueError(f"not positive definite (pivot {self._field('minor')})")

    def permutation(self) -> np.ndarray:
        return _array(self._field("Perm"), self.n, np.int64).copy()

    def diagonal(self) -> np.ndarray:
        """Diagonal of L (LL^T supernodal factor), in the factor's ordering."""
        if not (self._field("is_super", "i") and self._field("is_ll", "i")):
            raise Unavailable("diagonal() reads supernodal LL^T factors only")
        ns = self._field("nsuper")
        sup = _array(self._field("super"), ns + 1, np.int64)
        pi = _array(self._field("pi"), ns + 1, np.int64)
        px = _array(self._field("px"), ns + 1, np.int64)
        x = _array(self._field("x"), int(self._field("xsize")), np.float64)
        width = np.diff(sup)
        sn = np.repeat(np.arange(ns), width)
        j = np.arange(self.n) - sup[sn]
        return x[px[sn] + j * (pi[sn + 1] - pi[sn]) + j]

    def logdet(self) -> float:
        return float(2.0 * np.log(self.diagonal()).sum())

    def trailing_block(self, k: int) -> np.ndarray:
        """The dense lower-triangular last ``k`` x ``k`` block of L (columns and rows n-k..n-1
        of the factor's ordering), as an F-ordered array."""
        ns = self._field("nsuper")
        sup = _array(self._field("super"), ns + 1, np.int64)
        pi = _array(self._field("pi"), ns + 1, np.int64)
        px = _array(self._field("px"), ns + 1, np.int64)
        x = _array(self._field("x"), int(self._field("xsize")), np.float64)
        n0 = self.n - k
        out = np.zeros((k, k), order="F")
        first = int(np.searchsorted(sup, n0, side="right")) - 1
        for s in range(first, ns):
            k1, k2 = int(sup[s]), int(sup[s + 1])
            nsrow = int(pi[s + 1] - pi[s])
            block = x[px[s]:px[s] + nsrow * (k2 - k1)].reshape((nsrow, k2 - k1), order="F")
            # rows of a supernode of the trailing dense block are its own columns then later ones, in
            # order: with a dense trailing block they are exactly k1..n-1
            if nsrow != self.n - k1:
                raise Unavailable("the trailing block is not dense")
            c0 = max(k1, n0)
            out[c0 - n0:, c0 - n0:k2 - n0] = block[c0 - k1:, c0 - k1:]
        return out

    def __del__(self) -> None:
        if getattr(self, "L", None) is not None and self.L.value:
            self.c.lib.cholmod_l_free_factor(ctypes.byref(self.L), self.c.buf)


def bisect(a: sp.spmatrix) -> np.ndarray:
    """CHOLMOD's node bisection (METIS) of the graph of ``a``: 0 / 1 for the two parts, 2 for the
    separator."""
    c = Common()
    view, keep = _view(sp.csc_matrix(a))
    part = np.empty(a.shape[0], np.int64)
    c.lib.cholmod_l_bisect(ctypes.byref(view), None, 0, 1, part.ctypes.data, c.buf)
    del keep
    return part


def dgemm_rate(n: int = 3000, seconds: float = 2.0) -> float:
    """GF/s of the system BLAS's dgemm (the one CHOLMOD calls) on n x n matrices, best of the runs
    that fit in ``seconds``, with its current thread setting."""
    import time

    blas = ctypes.CDLL(ctypes.util.find_library("blas") or "libblas.so.3")
    fn = blas.dgemm_
    a = np.asfortranarray(np.random.default_rng(0).standard_normal((n, n)))
    b, c = a.copy(order="F"), np.zeros((n, n), order="F")
    nn = ctypes.c_int(n)
    one, zero = ctypes.c_double(1.0), ctypes.c_double(0.0)
    tr = ctypes.c_char(b"N")
    best, t_end = math.inf, time.perf_counter() + seconds
    while True:
        t0 = time.perf_counter()
        fn(ctypes.byref(tr), ctypes.byref(tr), ctypes.byref(nn), ctypes.byref(nn), ctypes.byref(nn), ctypes.byref(one),
           a.ctypes.data_as(ctypes.c_void_p), ctypes.byref(nn), b.ctypes.data_as(ctypes.c_void_p), ctypes.byref(nn),
           ctypes.byref(zero), c.ctypes.data_as(ctypes.c_void_p), ctypes.byref(nn))
        best = min(best, time.perf_counter() - t0)
        if time.perf_counter() > t_end:
            break
    return 2.0 * n ** 3 / best / 1e9
