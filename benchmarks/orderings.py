"""Fill-reducing orderings for the lb and FIM log-det factorizations (in-process, CHOLMOD).

For every dataset (the SE-Sync g2o files, or the NAMEs given) and noisy 3D grids (2*10^3 and
2*10^4 poses, 10^5 with --huge; --grids2 adds 2D grids), factors
  lb   the reduced Laplacians L_tau and L_w (posecrb.models.paper.bounds.weighted_laplacians): one symbolic
       analysis and two numeric factorizations with log-dets, as compute_bounds' lb does;
  FIM  the anchored paper FIM (posecrb.models.paper.fim.paper_fim, pose-major layout) at the file's vertices
       (an odometry estimate for edge-only files: the pattern, hence the ordering's cost, does not
       depend on the estimate): one analysis, one factorization, the log-det;
  Mred the solver's sparse matrix M_red(s) = [[L_red, V_red], [V_red^T, C + s I]] (posecrb.solver.problem:
       its factor is the trust-region preconditioner, refactored with -Lambda at every accepted
       iterate, and the certificate test), at the base shift s = gershgorin / 1e6: one analysis, one
       factorization (a solve runs one analysis and about 8-10 factorizations of this pattern);
with each CHOLMOD ordering scikit-sparse's ``analyze(ordering_method=...)`` accepts here:
  natural, amd, colamd, metis, nesdis, default (CHOLMOD's choice: AMD, METIS when AMD's fill is
  poor), best (CHOLMOD tries several and keeps the least fill);
and for the FIM and Mred also pose-level orderings expanded to each pose's rows (amd/poses,
metis/poses, nesdis/poses: the pose graph's reduced Laplacian is ordered, which is the pattern the
lb step already analyses, and the matrix is permuted with it and factored with the natural ordering).
Note: CHOLMOD applies COLAMD only to unsymmetric input; for a symmetric matrix its "colamd"
ordering is AMD (the nnz(L) columns show it).

Per (matrix, ordering): analysis time, factorization time, their total (median of --repeat after
a warm-up; a single run when the first takes longer than --slow seconds), nnz(L) and the fill
ratio nnz(L) / nnz(tril(A)). Then, per matrix, the fastest ordering, and the summed time of each
fixed choice over all matrices against the per-matrix best (the data for `--ordering auto`).
The natural ordering is skipped above --natural-max rows (its fill is quadratic in the bandwidth)
and for Mred (translations first, then rotations: its natural order fills almost completely).

--options measures instead posecrb's own ``--ordering`` choices (auto, amd, colamd, metis, nesdis)
exactly as the library runs them (posecrb.linalg.ordering): per dataset and choice,
  lb   ordering of L_tau + factorizations of L_tau and L_w with log-dets (compute_bounds' lb);
  ub   ordering of L_w (x) I_dr + blkdiag(Psi) (pose graph: L_w) + its factorization;
  FIM  ordering of the anchored paper FIM ("blocks" layout, as bounds/tables) + factorization + log-det;
with the ordering actually used, the time (median of --repeat after a warm-up), nnz(L), and the spread
of the log-dets over the choices (they must agree to rounding). This is the Orderings table of docs/performance.md.

Usage: python benchmarks/orderings.py [--repeat K] [--huge] [--grids3 N,N] [--grids2 N,N]
                                      [--no-real] [--data-dir DIR] [--slow S] [--options [--markdown]]
                                      [NAME ...]
"""
from __future__ import annotations

import argparse
import logging
import statistics
import sys
import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from _common import data_dir, print_header, suite_files
from grids import grid_file

CHOLMOD_ORDERINGS = ["natural", "amd", "colamd", "metis", "nesdis", "default", "best"]
POSE_ORDERINGS = ["amd/poses", "metis/poses", "nesdis/poses"]


@dataclass
class Timing:
    analyze: float
    factor: float
    nnz_l: int
    flops: float
    logdet: float

    @property
    def total(self) -> float:
        return self.analyze + self.factor


def _fill(f) -> tuple[int, float]:
    """nnz(L) and the factorization's flop count sum_j c_j^2 (c_j = nnz of column j of L): the
    machine-independent cost of an ordering, steady where the timings of a shared machine are not."""
    L = f.L()
    c = np.diff(L.indptr).astype(float)
    return int(L.nnz), float(np.dot(c, c))


def _measure(run, repeat: int, slow: float) -> list[tuple[float, float, object]]:
    first = run()
    if first[0] + first[1] > slow or repeat <= 1:
        return [first]
    return [run() for _ in range(repeat)]


def time_lb(lap, ordering: str, repeat: int, slow: float) -> Timing:
    """One analysis of L_tau's pattern, factorizations of L_tau and L_w (Algorithm 1)."""
    from sksparse.cholmod import analyze

    def run():
        t0 = time.perf_counter()
        sym = analyze(lap.l_tau, ordering_method=ordering)
        t1 = time.perf_counter()
        f_tau = sym.cholesky(lap.l_tau)
        ld = f_tau.logdet()
        f_w = sym.cholesky(lap.l_w)
        ld += f_w.logdet()
        t2 = time.perf_counter()
        return t1 - t0, t2 - t1, (f_w, ld)

    runs = _measure(run, repeat, slow)
    f_w, ld = runs[-1][2]
    return Timing(statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs),
                  *_fill(f_w), float(ld))


def _expanded(perm: np.ndarray, q: int) -> np.ndarray:
    return (perm[:, None] * q + np.arange(q)[None, :]).ravel()


def _mred_expanded(p: np.ndarray, n: int, d: int) -> np.ndarray:
    """M_red's rows pose by pose in the order of the reduced poses ``p`` (pose k + 1 for entry k),
    the anchor (pose 0: rotation rows only) last. Row layout: n - 1 translation rows (poses
    1..n-1), then d rotation rows per pose 0..n-1."""
    poses = np.concatenate([p + 1, [0]])
    rows = np.full((n, 1 + d), -1, dtype=np.int64)
    rows[:, 0] = np.where(poses > 0, poses - 1, -1)
    rows[:, 1:] = (n - 1) + poses[:, None] * d + np.arange(d)[None, :]
    flat = rows.ravel()
    return flat[flat >= 0]


def _pose_order(pose_pattern, ordering: str, q: int | None, expand=None) -> np.ndarray:
    """The matrix's rows in the order of the pose ordering ``ordering`` (``X/poses``: CHOLMOD's X
    of ``pose_pattern``), expanded to each pose's ``q`` rows, or by ``expand``."""
    from sksparse.cholmod import analyze

    p = analyze(pose_pattern, ordering_method=ordering.split("/")[0]).P()
    return _expanded(p, q) if expand is None else expand(p)


def time_fim(fim, pose_pattern, ordering: str, repeat: int, slow: float, expand=None) -> Timing:
    """One analysis + factorization of the FIM (pose-major layout), or of the matrix ``fim`` with
    the pose-order expansion ``expand``, with ``ordering``."""
    from sksparse.cholmod import analyze

    a = fim.matrix
    q = getattr(fim, "q", None)

    def run():
        t0 = time.perf_counter()
        if ordering.endswith("/poses"):
            perm = _pose_order(pose_pattern, ordering, q, expand)
            ap = a[perm][:, perm].tocsc()
            sym = analyze(ap, ordering_method="natural")
        else:
            ap = a
            sym = analyze(a, ordering_method=ordering)
        t1 = time.perf_counter()
        f = sym.cholesky(ap)
        ld = f.logdet()
        t2 = time.perf_counter()
        return t1 - t0, t2 - t1, (f, ld)

    runs = _measure(run, repeat, slow)
    f, ld = runs[-1][2]
    return Timing(statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs),
                  *_fill(f), float(ld))


def analysis_counts(a, pose_pattern, ordering: str, q: int | None, expand=None) -> tuple[float, float]:
    """CHOLMOD's own counts from the symbolic analysis of ``a`` with ``ordering`` (no numeric
    factorization): (flops, nnz(L)) before relaxed amalgamation adds explicit zeros, as
    ``cholmod_analyze`` reports them (``Common->fl``, ``Common->lnz``). Pose orderings (``X/poses``)
    order ``pose_pattern`` and expand it to the matrix's rows, as ``time_fim`` does."""
    import _cholmod

    if ordering.endswith("/poses"):
        f = _cholmod.Factorization(a, perm=_pose_order(pose_pattern, ordering, q, expand))
    else:
        f = _cholmod.Factorization(a, ordering)
    return f.flops, f.lnz


def estimate_for(graph):
    if graph.has_vertices:
        return graph.vertex_rot, graph.vertex_trans
    from fim import odometry_estimate  # benchmarks/fim.py

    return odometry_estimate(graph)


def _time_choice(run, repeat: int, slow: float):
    first = run()
    t = [first[0]]
    if first[0] <= slow and repeat > 1:
        t = []
        for _ in range(repeat):
            r = run()
            t.append(r[0])
            first = r
    return statistics.median(t), first[1], first[2], first[3]


def _nnz(k: int) -> str:
    return f"{k / 1e6:.2f}M" if k >= 1e6 else f"{k / 1e3:.1f}k"


def markdown_tables(results: list[dict], orderings: list[str]) -> None:
    """The Orderings tables of docs/performance.md: per matrix, time (s) and nnz(L) per explicit choice, and
    what auto used."""
    shown = [o for o in orderings if o != "auto"]
    for matrix in ("lb", "ub", "FIM"):
        sel = [r for r in results if r["matrix"] == matrix]
        if not sel:
            continue
        print()
        print(f"{matrix}: time in s / nnz(L)")
        print()
        print("| dataset | dim | poses | " + " | ".join(shown) + " | auto uses |")
        print("|---|---|---|" + "---|" * (len(shown) + 1))
        for r in sel:
            cells = [f"{r['res'][o][0]:.3g} / {_nnz(r['res'][o][2])}" if o in r["res"] else "-" for o in shown]
            auto = r["res"]["auto"][1] if "auto" in r["res"] else "-"
            print(f"| {r['name']} | {r['dim']} | {r['poses']} | " + " | ".join(cells) + f" | {auto} |")


def options_table(items, orderings: list[str], matrices: str, repeat: int, slow: float,
                  markdown: bool = False) -> None:
    """posecrb's --ordering choices as the library runs them (module docstring, --options)."""
    from posecrb import load
    from posecrb.linalg.laplacian import kron_identity
    from posecrb.linalg.ordering import ordered_symbolic
    from posecrb.models.paper.bounds import block_diagonal, source_terms, weighted_laplacians
    from posecrb.models.paper.fim import fim_symbolic_choice, paper_fim

    print(f"{'dataset':24s} {'dim':>3s} {'poses':>6s} {'matrix':6s} {'rows':>7s} {'--ordering':10s} "
          f"{'used':20s} {'time s':>8s} {'nnz(L)':>10s} {'vs amd':>6s}")
    summary: dict[tuple[str, str], float] = {}
    results: list[dict] = []
    for name, path in items:
        g = load(path)
        if g.n_components != 1:
            print(f"{name:24s} disconnected, skipped")
            continue
        lap = weighted_laplacians(g)
        d, dr, n_p = g.dim, g.rot_dim, g.n - 1
        runs = {}
        if "lb" in matrices:
            def lb(o):
                t0 = time.perf_counter()
                sym, c = ordered_symbolic(lap.l_tau, o, dim=d, poses=g.n, matrix="lb")
                _, l1 = sym.factor_logdet(lap.l_tau)
                f, l2 = sym.factor_logdet(lap.l_w)
                return time.perf_counter() - t0, str(c), f, d * l1 + dr * l2
            runs["lb"] = (lb, lap.l_tau.shape[0])
        if "ub" in matrices:
            psi, _ = source_terms(g, lap.tau, 0)
            m = (kron_identity(lap.l_w, dr) + block_diagonal(psi)).tocsc()

            def ub(o, m=m):
                t0 = time.perf_counter()
                sym, c = ordered_symbolic(m, o, dim=d, poses=g.n, matrix="ub",
                                          pose_of_row=np.repeat(np.arange(n_p), dr), n_poses=n_p,
                                          pose_adjacency=lap.l_w)
                f, ld = sym.factor_logdet(m)
                return time.perf_counter() - t0, str(c), f, ld
            runs["ub"] = (ub, m.shape[0])
        if "FIM" in matrices:
            rot, trans = estimate_for(g)
            fim = paper_fim(g, rot, trans)

            def fimrun(o, fim=fim):
                t0 = time.perf_counter()
                sym, c = fim_symbolic_choice(fim, o)
                f, ld = sym.factor_logdet(fim.matrix)
                return time.perf_counter() - t0, str(c), f, ld
            runs["FIM"] = (fimrun, fim.size)
        for matrix, (run, rows) in runs.items():
            res = {}
            for o in orderings:
                t, used, f, ld = _time_choice(lambda o=o: run(o), repeat, slow)
                res[o] = (t, used, int(f.L().nnz), ld)
                del f
            ref = res.get("amd")
            lds = [r[3] for r in res.values()]
            for o, (t, used, nnz, _) in res.items():
                summary[(matrix, o)] = summary.get((matrix, o), 0.0) + t
                print(f"{name:24s} {d:3d} {g.n:6d} {matrix:6s} {rows:7d} {o:10s} {used:20s} {t:8.4f} {nnz:10d} "
                      f"{t / ref[0] if ref else float('nan'):6.2f}", flush=True)
            spread = (max(lds) - min(lds)) / max(1.0, abs(statistics.median(lds)))
            print(f"{'':24s} -> log-dets agree to {spread:.1e} relative", flush=True)
            results.append({"name": name, "dim": d, "poses": g.n, "matrix": matrix, "res": res})
    print()
    print("summed time per choice over the datasets above:")
    for (matrix, o), t in summary.items():
        print(f"  {matrix:4s} {o:10s} {t:9.3f} s")
    if markdown:
        markdown_tables(results, orderings)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*")
    ap.add_argument("--data-dir", default=None)
    ap.add_argument("--no-real", action="store_true", help="grids only")
    ap.add_argument("--grids3", default="2000,20000", help="3D grid pose counts ('' for none)")
    ap.add_argument("--grids2", default="", help="2D grid pose counts, e.g. 10000,100000")
    ap.add_argument("--huge", action="store_true", help="add a 10^5-pose 3D grid")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--slow", type=float, default=2.0, help="seconds; slower configurations run once")
    ap.add_argument("--natural-max", type=int, default=20000, help="skip natural above this many rows")
    ap.add_argument("--orderings", default=",".join(CHOLMOD_ORDERINGS + POSE_ORDERINGS))
    ap.add_argument("--matrices", default="lb,FIM,Mred")
    ap.add_argument("--options", action="store_true",
                    help="measure posecrb's --ordering choices as the library runs them (lb, ub, FIM)")
    ap.add_argument("--markdown", action="store_true", help="with --options: also print the tables as markdown")
    ap.add_argument("--counts", action="store_true",
                    help="print CHOLMOD's flop and nnz(L) counts of each analysis instead of timing "
                         "factorizations (machine-independent; no numeric factorization)")
    args = ap.parse_args(argv)
    logging.getLogger("posecrb").setLevel(logging.ERROR)
    if args.options:
        from threadpoolctl import threadpool_limits

        orderings = [o for o in args.orderings.split(",") if o] if args.orderings != ap.get_default("orderings") \
            else ["auto", "amd", "colamd", "metis", "nesdis"]
        items = [] if args.no_real else [(p.stem, p) for p in suite_files(data_dir(args.data_dir), args.names)]
        g3 = [int(x) for x in args.grids3.split(",") if x] + ([100_000] if args.huge else [])
        g2 = [int(x) for x in args.grids2.split(",") if x]
        items += [(f"grid3D-{n}", grid_file(3, n)) for n in g3] + [(f"grid2D-{n}", grid_file(2, n)) for n in g2]
        print_header("posecrb --ordering: lb, ub and FIM log-det (in-process, as the library runs them)", 1, [
            f"median of {args.repeat} after a warm-up (one run above {args.slow:g} s); BLAS single-threaded; "
            "time = ordering + analysis + factorizations + log-det"])
        matrices = args.matrices if args.matrices != ap.get_default("matrices") else "lb,ub,FIM"
        with threadpool_limits(1):
            options_table([(n, p) for n, p in items if p.is_file()], orderings, matrices, args.repeat, args.slow,
                          args.markdown)
        return 0

    from threadpoolctl import threadpool_limits

    from posecrb import load
    from posecrb.models.paper.bounds import weighted_laplacians
    from posecrb.models.paper.fim import paper_fim
    from posecrb.solver.problem import Problem

    orderings = [o for o in args.orderings.split(",") if o]
    items = [] if args.no_real else [(p.stem, p) for p in suite_files(data_dir(args.data_dir), args.names)]
    g3 = [int(x) for x in args.grids3.split(",") if x] + ([100_000] if args.huge else [])
    g2 = [int(x) for x in args.grids2.split(",") if x]
    items += [(f"grid3D-{n}", None, 3, n) for n in g3] + [(f"grid2D-{n}", None, 2, n) for n in g2]
    print_header("fill-reducing orderings: lb and FIM log-det factorizations (in-process, CHOLMOD)", None, [
        "symbolic analyses only: CHOLMOD's counts, no timing" if args.counts else
        (f"median of {args.repeat} after a warm-up (one run above {args.slow:g} s); BLAS single-threaded; "
         "times in seconds; fill = nnz(L) / nnz(tril(A))")])
    table: list[dict] = []
    if args.counts:
        print("CHOLMOD's analysis counts, Gflop / nnz(L) (before relaxed amalgamation):")
        print("| dataset | matrix | rows | " + " | ".join(orderings) + " |")
        print("|---|---|---|" + "---|" * len(orderings))
    else:
        print(f"{'dataset':24s} {'dim':>3s} {'poses':>6s} {'matrix':6s} {'rows':>7s} {'nnz(trilA)':>10s} "
              f"{'ordering':13s} {'analyze':>8s} {'factor':>8s} {'total':>8s} {'nnz(L)':>10s} {'fill':>6s} "
              f"{'Mflop':>9s} {'vs amd':>6s}")
    with threadpool_limits(1):
        for item in items:
            if item[1] is None:
                name, _, dim, n = item
                path = grid_file(dim, n)
            else:
                name, path = item
                if not path.is_file():
                    print(f"{name:24s} missing: {path}")
                    continue
            g = load(path)
            if g.n_components != 1:
                print(f"{name:24s} disconnected, skipped")
                continue
            lap = weighted_laplacians(g)
            mats = []
            if "lb" in args.matrices:
                mats.append(("lb", lap.l_tau, None))
            if "FIM" in args.matrices:
                rot, trans = estimate_for(g)
                fim = paper_fim(g, rot, trans).to_layout("poses")
                mats.append(("FIM", fim.matrix, fim))
            if "Mred" in args.matrices:
                prob = Problem.from_graph(g)
                mred = SimpleNamespace(matrix=prob.full_matrix(None, prob.gershgorin_max() / 1e6))
                mats.append(("Mred", mred.matrix, mred))
                del prob
            if args.counts:
                for matrix, a, obj in mats:
                    expand = (lambda p, n=g.n, d=g.dim: _mred_expanded(p, n, d)) if matrix == "Mred" else None
                    cells = []
                    for o in orderings:
                        if o == "natural" or (o.endswith("/poses") and matrix == "lb"):
                            cells.append("")
                            continue
                        fl, lnz = analysis_counts(a, lap.l_tau, o, getattr(obj, "q", None), expand)
                        cells.append(f"{fl / 1e9:.3g} G / {lnz / 1e6:.3g}M")
                    print(f"| {name} | {matrix} | {a.shape[0]} | " + " | ".join(cells) + " |", flush=True)
                continue
            for matrix, a, obj in mats:
                nnz_tril = int((a.nnz + a.shape[0]) // 2)
                rows: dict[str, Timing] = {}
                for o in orderings:
                    if o.endswith("/poses") and matrix == "lb":
                        continue
                    if o == "natural" and (a.shape[0] > args.natural_max or matrix == "Mred"):
                        continue  # Mred's rows are not pose-major: its natural order is a full band
                    if matrix == "lb":
                        rows[o] = time_lb(lap, o, args.repeat, args.slow)
                    else:
                        expand = (lambda p, n=g.n, d=g.dim: _mred_expanded(p, n, d)) if matrix == "Mred" else None
                        rows[o] = time_fim(obj, lap.l_tau, o, args.repeat, args.slow, expand)
                ref = rows.get("amd")
                lds = [t.logdet for t in rows.values()]
                spread = (max(lds) - min(lds)) / max(1.0, abs(statistics.median(lds)))
                for o, t in rows.items():
                    print(f"{name:24s} {g.dim:3d} {g.n:6d} {matrix:6s} {a.shape[0]:7d} {nnz_tril:10d} {o:13s} "
                          f"{t.analyze:8.4f} {t.factor:8.4f} {t.total:8.4f} {t.nnz_l:10d} "
                          f"{t.nnz_l / nnz_tril:6.2f} {t.flops / 1e6:9.1f} "
                          f"{t.total / ref.total if ref else float('nan'):6.2f}",
                          flush=True)
                best = min(rows, key=lambda o: rows[o].total)
                least = min(rows, key=lambda o: rows[o].flops)
                print(f"{'':24s} -> fastest: {best}; fewest flops: {least}; log-dets agree to {spread:.1e} "
                      "relative", flush=True)
                table.append({"name": name, "dim": g.dim, "n": g.n, "matrix": matrix, "rows": a.shape[0],
                              "times": {o: t.total for o, t in rows.items()},
                              "flops": {o: t.flops for o, t in rows.items()}, "best": best})
    if not table:
        return 0
    print()
    print("summed time of each fixed choice over the matrices where it ran, against the per-matrix best "
          "(the oracle) over the same matrices:")
    for matrix in ("lb", "FIM", "Mred"):
        sel = [r for r in table if r["matrix"] == matrix]
        for o in orderings:
            have = [r for r in sel if o in r["times"]]
            if not have:
                continue
            tot = sum(r["times"][o] for r in have)
            oracle = sum(r["times"][r["best"]] for r in have)
            wins = sum(r["best"] == o for r in have)
            print(f"  {matrix:4s} {o:13s} {tot:9.3f} s over {len(have):2d} matrices (oracle {oracle:9.3f} s, "
                  f"x{tot / oracle:5.2f}); fastest on {wins}")
    print()
    keys = [o for o in orderings if o not in ("natural", "colamd", "best")]
    for what in ("times", "flops"):
        print(f"per matrix, {'time' if what == 'times' else 'flop count'} relative to amd (by matrix size; "
              "the crossing point is the rule for auto):")
        print(f"  {'dataset':24s} {'dim':>3s} {'matrix':6s} {'rows':>7s} " + " ".join(f"{o:>12s}" for o in keys))
        for r in sorted(table, key=lambda r: (r["matrix"], r["dim"], r["rows"])):
            amd = r[what].get("amd")
            cells = [f"{r[what][o] / amd:12.2f}" if o in r[what] and amd else f"{'-':>12s}" for o in keys]
            print(f"  {r['name']:24s} {r['dim']:3d} {r['matrix']:6s} {r['rows']:7d} " + " ".join(cells))
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
