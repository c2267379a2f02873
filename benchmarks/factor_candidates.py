"""The FIM log-det of a large 3D grid: ways to use every core, side by side, against the flop limit.

The matrix is the anchored paper FIM at the file's vertices, exactly what `posecrb bounds
--estimate vertices` factors (3D grid of 21,952 poses by default: 131,706 rows, 4.2M nonzeros),
cached as .npz next to the grid files (benchmarks/grids.py). Each candidate runs in its own
process (so its peak memory is its own) and prints its ordering + analysis time, numeric
factorization time, CHOLMOD's flop count, GF/s of the factorization, peak RSS and its log-det
against the first candidate's:

  posecrb         posecrb's own call (posecrb.models.paper.fim.fim_symbolic_choice + factor_logdet
                  through scikit-sparse): --ordering auto = nested dissection of the pose graph
  <ordering>      CHOLMOD called directly (benchmarks/_cholmod.py) with CHOLMOD's ordering of the
                  scalar matrix: nesdis, metis, amd
  pose-metis      the pose graph's nested dissection (METIS; pose-nesdis: CHOLMOD's NESDIS) expanded
                  to 6x6 blocks, CHOLMOD's default supernodal amalgamation (posecrb's `auto` on this
                  graph, without scikit-sparse); pose-nesdis-relax with 4x larger relaxed supernodes
                  (nrelax 16/64/256, zrelax 0.8/0.2/0.1)
  split           two halves of the pose graph (CHOLMOD's METIS bisection), each factored with the
                  separator ordered last, in two threads at one BLAS thread each (CHOLMOD releases
                  the GIL here), then the separator's Schur complement S = L1 L1^T + L2 L2^T - A_ss
                  assembled from the two trailing blocks (LAPACK dlauum, one thread: threaded lauum
                  collapses when another process holds a core) and factored densely (dpotrf) with
                  every BLAS thread
  mumps           another library: MUMPS's multifrontal LDL^T (sequential library, SYM=1) through
                  benchmarks/mumps_logdet.c, compiled on first use against the system's MUMPS
                  (Debian: libmumps-seq-dev; $POSECRB_MUMPS_LIBS overrides the link flags,
                  $POSECRB_MUMPS_CFLAGS the include flags) and run in a process of its own, with
                  MUMPS's automatic ordering; mumps-pose-metis with posecrb's ordering (the pose
                  graph's METIS) as MUMPS's pivot order. Skipped with the reason where no MUMPS
                  compiles. Its flops are MUMPS's own count (RINFOG(3)), never the limit's.
  pardiso         another library: Intel oneMKL's PARDISO (Cholesky, two-level factorization)
                  through ctypes (benchmarks/_pardiso.py), found through $POSECRB_MKL_RT (the
                  path of libmkl_rt.so, e.g. from `pip install mkl` in a virtual environment of
                  its own), with its own METIS ordering; pardiso-pose-metis with posecrb's ordering.
                  Its threads are MKL's (1t: MKL_NUM_THREADS=1). Skipped with the reason where
                  MKL is not given. Its flops are PARDISO's own count, never the limit's.
each with the BLAS of CHOLMOD at one thread ("1t") and at every core ("all"), where it applies,
and CHOLMOD's own OpenMP team off (posecrb.linalg.threads.cholmod_openmp_serial) as in posecrb.
The table's "process CPU / wall" is the candidate's whole process: about 1 for one thread, up to
the number of threads with more (OpenBLAS's waiting threads spin, so CPU time does not say they
worked).

The limit is the fewest flops of any candidate divided by the dgemm rate of all cores (the
system BLAS's dgemm, the one CHOLMOD calls, 3000 x 3000, best of 2 s), measured in the same run;
each candidate's total time is printed as a multiple of it. Flops are CHOLMOD's count from the
analysis (machine-independent); every time depends on the load, printed with the figures.

Usage: python benchmarks/factor_candidates.py [--grid3 20000] [--candidates a,b,...] [--rounds K]
                                              [--cache-dir DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import threading
import time
from pathlib import Path

from _common import child_env, print_header, run_process
from grids import DEFAULT_SIGMA, cache_dir, grid_file

CANDIDATES = ["posecrb/1t", "posecrb/all", "nesdis/1t", "nesdis/all", "metis/all", "amd/all",
              "pose-metis/1t", "pose-metis/all", "pose-nesdis/all", "pose-nesdis-relax/all", "split/all",
              "mumps/all", "mumps-pose-metis/1t", "mumps-pose-metis/all", "pardiso/all",
              "pardiso-pose-metis/1t", "pardiso-pose-metis/all"]
MUMPS_LIBS = "-ldmumps_seq -lmumps_common_seq -lmpiseq_seq -lpord_seq -lm"
RELAX = {"nrelax": (16, 64, 256), "zrelax": (0.8, 0.2, 0.1)}


def matrix_path(poses: int, directory: str | None) -> Path:
    g = grid_file(3, poses, directory=directory)
    out = g.with_suffix(".fim.npz")
    if not out.is_file():
        import numpy as np
        import scipy.sparse as sp

        from posecrb.io import load
        from posecrb.models.paper.fim import paper_fim, pose_of_row

        graph = load(g)
        fim = paper_fim(graph, graph.vertex_rot, graph.vertex_trans, 0, "eq59", variant="consistent")
        a = fim.matrix.tocsc()
        tmp = out.with_suffix(".tmp.npz")
        sp.save_npz(tmp, a)
        np.save(out.with_suffix(".por.npy"), pose_of_row(fim))
        os.replace(tmp, out)
    return out


def _blas_limit(limits: int | None):
    """threadpoolctl's limit on every BLAS of this process, CHOLMOD's included. threadpoolctl sets only
    the libraries loaded when the limit is entered, and CHOLMOD's BLAS (the system's libblas.so.3)
    loads with CHOLMOD, so CHOLMOD is loaded first: a limit entered before left it on every core."""
    import numpy  # noqa: F401  (numpy's own BLAS)
    import sksparse.cholmod  # noqa: F401  (CHOLMOD and its BLAS, the library _cholmod loads too)
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=limits)


def _limit_blas(threads: str):
    return _blas_limit(1 if threads == "1t" else None)


def _pose_perm(a, por, method: str):
    import numpy as np

    from posecrb.linalg.ordering import expand_permutation, pose_adjacency_of, pose_permutation

    n_poses = int(np.max(por)) + 1
    adj = pose_adjacency_of(a, por, n_poses)
    return adj, expand_permutation(pose_permutation(adj, method), por)


def run_one(name: str, path: Path) -> dict:
    """One candidate in this process; the figures as a dict."""
    import numpy as np
    import scipy.sparse as sp

    kind, threads = name.split("/")
    a = sp.load_npz(path).tocsc()
    por = np.load(path.with_suffix(".por.npy"))
    base_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    out: dict = {"candidate": name, "rows": a.shape[0], "nnz": int(a.nnz)}
    if kind.startswith("mumps"):
        out.update(_mumps(a, por, kind, threads, path))
        return out
    if kind.startswith("pardiso"):
        out.update(_pardiso_candidate(a, por, kind, threads))
        return out
    from posecrb.linalg.threads import cholmod_openmp_serial

    # CHOLMOD's own OpenMP team off for every candidate, as posecrb's factorizations keep it
    with _limit_blas(threads), cholmod_openmp_serial():
        if kind == "posecrb":
            from posecrb.linalg.ordering import ordered_symbolic

            t0 = time.perf_counter()
            sym, choice = ordered_symbolic(a, "auto", dim=3, poses=int(np.max(por)) + 2, matrix="fim",
                                           pose_of_row=por, n_poses=int(np.max(por)) + 1)
            t1 = time.perf_counter()
            _, ld = sym.factor_logdet(a, name="paper FIM")
            t2 = time.perf_counter()
            out.update(ordering=str(choice), analyse=t1 - t0, factor=t2 - t1, logdet=ld, flops=None)
        elif kind == "split":
            out.update(_split(a, por))
        else:
            import _cholmod

            kw = RELAX if kind.endswith("-relax") else {}
            t0 = time.perf_counter()
            if kind.startswith("pose-"):
                _, perm = _pose_perm(a, por, kind.split("-")[1])
                f = _cholmod.Factorization(a, perm=perm, **kw)
            else:
                f = _cholmod.Factorization(a, kind)
            t1 = time.perf_counter()
            f.factor()
            t2 = time.perf_counter()
            out.update(ordering=kind, analyse=t1 - t0, factor=t2 - t1, logdet=f.logdet(), flops=f.flops,
                       lnz=f.lnz)
    out["peak_rss"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    out["base_rss"] = base_rss
    return out


def _mumps_driver(cache: Path) -> Path:
    """benchmarks/mumps_logdet.c compiled against the system's MUMPS (cached next to the grids);
    a RuntimeError with the compiler's reason where it does not build."""
    import shlex
    import subprocess

    src = Path(__file__).resolve().with_name("mumps_logdet.c")
    exe = cache / "mumps_logdet"
    if exe.is_file() and exe.stat().st_mtime >= src.stat().st_mtime:
        return exe
    cc = os.environ.get("CC", "cc")
    tmp = exe.with_name(f"mumps_logdet.{os.getpid()}.tmp")
    cmd = [cc, "-O2", "-o", str(tmp), str(src), *shlex.split(os.environ.get("POSECRB_MUMPS_CFLAGS", "")),
           *shlex.split(os.environ.get("POSECRB_MUMPS_LIBS", MUMPS_LIBS))]
    try:
        r = subprocess.run(cmd, capture_output=True, text=True)
    except OSError as exc:
        raise RuntimeError(f"skipped: no C compiler ({exc})") from None
    if r.returncode != 0:
        reason = (r.stderr.strip().splitlines() or ["unknown"])[0]
        raise RuntimeError(f"skipped: MUMPS does not compile here ({' '.join(cmd)}: {reason})")
    os.replace(tmp, exe)
    return exe


def _mumps(a, por, kind: str, threads: str, path: Path) -> dict:
    """MUMPS's log-det in its own process (module docstring); the driver's figures, the pose
    ordering's time counted in the analysis."""
    import subprocess
    import tempfile

    import numpy as np
    import scipy.sparse as sp

    try:
        exe = _mumps_driver(path.parent)
    except RuntimeError as exc:
        return {"error": str(exc)}
    data = path.with_suffix(".mumps.bin")
    if not data.is_file():
        low = sp.tril(a).tocoo()
        tmp = data.with_name(f"{data.name}.{os.getpid()}.tmp")
        with open(tmp, "wb") as f:
            np.array([a.shape[0], low.nnz], np.int64).tofile(f)
            (low.row + 1).astype(np.int32).tofile(f)
            (low.col + 1).astype(np.int32).tofile(f)
            low.data.astype(np.float64).tofile(f)
        os.replace(tmp, data)
    env = dict(os.environ)
    if threads == "1t":
        env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    with tempfile.TemporaryDirectory(prefix="posecrb-mumps-") as tmpdir:
        t_order = 0.0
        argv = [str(exe), str(data), "7"]
        ordering = "MUMPS's automatic choice"
        if kind == "mumps-pose-metis":
            t0 = time.perf_counter()
            _, perm = _pose_perm(a, por, "metis")
            t_order = time.perf_counter() - t0
            position = np.empty_like(perm)
            position[perm] = np.arange(perm.size)
            perm_file = Path(tmpdir) / "perm.bin"
            (position + 1).astype(np.int32).tofile(perm_file)
            argv = [str(exe), str(data), "1", str(perm_file)]
            ordering = "METIS (pose graph)"
        r = subprocess.run(argv, capture_output=True, text=True, env=env)
    lines = r.stdout.strip().splitlines()
    res = json.loads(lines[-1]) if lines else {"error": f"no output, exit {r.returncode}: {r.stderr.strip()}"}
    if "error" in res:
        return res
    names = {0: "AMD", 2: "AMF", 3: "SCOTCH", 4: "PORD", 5: "METIS", 6: "QAMD"}
    if kind == "mumps":
        ordering = f"MUMPS's choice: {names.get(res['ordering_used'], res['ordering_used'])}"
    return {"ordering": f"MUMPS, {ordering}", "analyse": t_order + res["analyse"], "factor": res["factor"],
            "logdet": res["logdet"], "flops": res["flops"], "lnz": res["lnz"], "peak_rss": res["peak_rss"],
            "foreign_flops": True}


def _pardiso_candidate(a, por, kind: str, threads: str) -> dict:
    """MKL PARDISO's log-det in this candidate's process (module docstring); the pose ordering's
    time counted in the analysis."""
    import _pardiso

    if threads == "1t":
        os.environ["MKL_NUM_THREADS"] = "1"     # read when MKL loads, just below
    try:
        _pardiso.library()
    except _pardiso.Unavailable as exc:
        return {"error": str(exc)}
    perm, ordering = None, "PARDISO's METIS"
    t0 = time.perf_counter()
    if kind == "pardiso-pose-metis":
        _, perm = _pose_perm(a, por, "metis")
        ordering = "METIS (pose graph)"
    t_order = time.perf_counter() - t0
    try:
        res = _pardiso.logdet(a, perm)
    except (_pardiso.NotPositiveDefinite, RuntimeError) as exc:
        return {"error": str(exc)}
    return {"ordering": f"PARDISO, {ordering}", "analyse": t_order + res["analyse"], "factor": res["factor"],
            "logdet": res["logdet"], "flops": res["flops"], "lnz": res["lnz"],
            "peak_rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024, "foreign_flops": True}


def _split(a, por) -> dict:
    """Two halves in two threads, then the separator's dense Schur complement (module docstring)."""
    import _cholmod
    import numpy as np
    import scipy.sparse as sp
    from scipy.linalg import lapack

    from posecrb.linalg.ordering import expand_permutation, pose_adjacency_of, pose_permutation

    t0 = time.perf_counter()
    n_poses = int(np.max(por)) + 1
    adj = pose_adjacency_of(a, por, n_poses)
    part = _cholmod.bisect(adj + sp.identity(n_poses, format="csc"))
    sep_rows = np.flatnonzero(part[por] == 2)
    k = sep_rows.size
    halves = []
    for h in (0, 1):
        poses = np.flatnonzero(part == h)
        local = np.full(n_poses, -1)
        local[poses] = np.arange(poses.size)
        rows = np.flatnonzero(part[por] == h)
        sub_adj = adj[poses][:, poses]
        perm_rows = rows[expand_permutation(pose_permutation(sub_adj, "nesdis"), local[por[rows]])]
        idx = np.concatenate([perm_rows, sep_rows])        # half's rows in elimination order, separator last
        halves.append(idx)
    t_order = time.perf_counter() - t0

    results: list = [None, None]

    def work(h: int) -> None:
        idx = halves[h]
        m = a[idx][:, idx].tocsc()
        f = _cholmod.Factorization(m, "natural", postorder=False)
        ta = time.perf_counter()
        f.factor()
        tf = time.perf_counter() - ta
        d = f.diagonal()
        ld_own = float(2.0 * np.log(d[:-k]).sum())
        lss = f.trailing_block(k)
        results[h] = (ld_own, lss, f.flops, tf)
        del f

    t1 = time.perf_counter()
    with _blas_limit(1):
        threads = [threading.Thread(target=work, args=(h,)) for h in (0, 1)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
    t2 = time.perf_counter()
    # S = L1 L1^T + L2 L2^T - A_ss; L L^T = J lauum(J L J) J with J the reversal (lauum forms U U^T)
    s = -a[sep_rows][:, sep_rows].toarray(order="F")
    with _blas_limit(1):
        for _, lss, _, _ in results:
            u = np.asfortranarray(lss[::-1, ::-1])
            uut, info = lapack.dlauum(u, lower=0, overwrite_c=1)
            if info:
                raise RuntimeError(f"dlauum info {info}")
            s += np.triu(uut)[::-1, ::-1]       # lower triangle of L L^T
    c, info = lapack.dpotrf(s, lower=1, overwrite_a=1, clean=0)
    if info:
        raise RuntimeError(f"dpotrf of the Schur complement: info {info}")
    ld_s = float(2.0 * np.log(np.diag(c)).sum())
    t3 = time.perf_counter()
    flops = results[0][2] + results[1][2] + k ** 3          # two lauum (k^3/3 each) + dpotrf (k^3/3)
    return {"ordering": f"bisection + nesdis per half, separator {k} rows", "analyse": t_order,
            "factor": t3 - t1, "halves": [results[0][3], results[1][3]], "schur": t3 - t2,
            "logdet": results[0][0] + results[1][0] + ld_s, "flops": flops}


def dgemm_child() -> dict:
    import _cholmod

    with _blas_limit(1):
        one = _cholmod.dgemm_rate()
    return {"dgemm_1t": one, "dgemm_all": _cholmod.dgemm_rate(), "cores": os.cpu_count()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid3", type=int, default=20000, help="3D grid poses (lattice side rounded up)")
    ap.add_argument("--candidates", default=",".join(CANDIDATES))
    ap.add_argument("--rounds", type=int, default=1, help="rounds over all candidates, order flipped each round")
    ap.add_argument("--cache-dir", default=None)
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--matrix", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        res = dgemm_child() if args.one == "dgemm" else run_one(args.one, Path(args.matrix))
        print(json.dumps(res))
        return 0
    names = [c.strip() for c in args.candidates.split(",") if c.strip()]
    kinds = {c.split("/")[0] for c in CANDIDATES}
    unknown = [n for n in names if n.count("/") != 1 or n.split("/")[0] not in kinds
               or n.split("/")[1] not in ("1t", "all")]
    if unknown or not names:
        ap.error(f"unknown candidate(s) {', '.join(unknown) or '(none given)'}: KIND/1t or KIND/all with KIND one "
                 f"of {', '.join(sorted(kinds))}")
    if all(n.startswith(("posecrb/", "mumps", "pardiso")) for n in names):
        # posecrb's own path goes through scikit-sparse, which does not report CHOLMOD's flop count,
        # and MUMPS and PARDISO count their own way.
        ap.error("the flop limit needs CHOLMOD's flop count: add a candidate that calls CHOLMOD directly "
                 "(e.g. metis/all)")
    print_header("FIM log-det candidates (benchmarks/factor_candidates.py)")
    path = matrix_path(args.grid3, args.cache_dir)
    print(f"matrix: {path} (sigma {DEFAULT_SIGMA}); cache {cache_dir(args.cache_dir)}")
    env = child_env(threads=None)

    def child(name: str) -> dict:
        r = run_process([sys.executable, __file__, "--one", name, "--matrix", str(path)], env=env)
        if not r.ok:
            return {"candidate": name, "error": (r.stderr.strip().splitlines() or [r.status])[-1]}
        d = json.loads(r.stdout.strip().splitlines()[-1])
        d["wall"] = r.wall
        d["cpu"] = r.cpu
        return d

    rows: dict[str, list[dict]] = {n: [] for n in names}
    rates = []
    for k in range(args.rounds):
        rates.append(child("dgemm"))
        for n in (names if k % 2 == 0 else names[::-1]):
            rows[n].append(child(n))
            print(f"  {n}: {json.dumps(rows[n][-1])}", file=sys.stderr, flush=True)
    rates.append(child("dgemm"))
    all_rate = max(r["dgemm_all"] for r in rates)
    one_rate = max(r["dgemm_1t"] for r in rates)
    best = [min(rs, key=lambda r: r.get("factor", 1e300) + r.get("analyse", 0)) for rs in rows.values()]
    fl = min(r["flops"] for r in best if r.get("flops") and not r.get("foreign_flops"))
    limit = fl / (all_rate * 1e9)
    ref = next((r["logdet"] for r in best if "logdet" in r), None)
    print(f"dgemm (system BLAS, CHOLMOD's): {one_rate:.1f} GF/s on one core, {all_rate:.1f} GF/s on all "
          f"{rates[0]['cores']}; limit = {fl / 1e9:.0f} Gflop / {all_rate:.1f} GF/s = {limit:.2f} s; "
          f"best of {args.rounds} round(s); load average {os.getloadavg()[0]:.1f} at the end")
    print()
    print("| candidate | ordering | Gflop | analysis s | factor s | total s | GF/s | x limit | peak RSS | "
          "process CPU / wall | logdet - first |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in best:
        if "error" in r:
            print(f"| {r['candidate']} | failed: {r['error']} ||||||||||")
            continue
        total = r["analyse"] + r["factor"]
        flops = r.get("flops")
        gfs = f"{flops / r['factor'] / 1e9:.1f}" if flops else ""
        print(f"| {r['candidate']} | {r['ordering']} | {flops / 1e9:.0f} | " if flops else
              f"| {r['candidate']} | {r['ordering']} | | ", end="")
        print(f"{r['analyse']:.2f} | {r['factor']:.2f} | {total:.2f} | {gfs} | {total / limit:.2f} | "
              f"{r['peak_rss'] / 2**30:.2f} GB | {r['cpu']:.1f} / {r['wall']:.1f} s | {r['logdet'] - ref:+.2e} |")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
