"""`posecrb datasets`: the manifest, the search path, downloads and our synthetic generators."""
from __future__ import annotations

import logging

import click

from ...core.choices import SYNTH_KINDS
from ...core.errors import PosecrbError
from ...core.noise import precisions_from_sigma
from ...core.resources import check_memory
from ...datasets import search as ds
from ...datasets import verify as dsv
from ...datasets.fetch import PROBE_TIMEOUT, fetch, fetch_many
from ...datasets.manifest import load_manifest
from ...io import write_g2o
from ...report.render import print_rows
from ..options import SEED_RANGE, FiniteFloat, PlainInt, data_dir_option, format_option
from ..paths import GRAPH_EXTENSIONS, DatasetArg, Group, OutputDir, OutputFile
from ..progress import progress_display

log = logging.getLogger("posecrb")

LIST_COLUMNS = ["name", "dim", "poses", "edges", "table", "paper_name", "status", "path"]


@click.group("datasets", cls=Group)
def command() -> None:
    """Dataset manifest, lookup, download (verified) and synthetic graphs.

    The manifest lists every g2o/TORO dataset of the paper's tables (and a few more)
    with the expected counts, the pinned download URL and the checksum. Bare names
    are looked up in --data-dir, $POSECRB_DATA, ./datasets and the user cache
    ~/.cache/posecrb (where `fetch` downloads to).
    """


@command.command("list")
@data_dir_option
@format_option()
@click.option("--no-check", is_flag=True, help="Do not hash the files (status is only found/missing).")
def list_cmd(data_dir: str | None, fmt: str, no_check: bool) -> None:
    """Every manifest dataset: dim, counts, paper table, status (found / missing / checksum mismatch), path."""
    rows = [s.row() for s in dsv.list_datasets(data_dir, check=not no_check)]
    print_rows(rows, fmt, columns=LIST_COLUMNS, single_json=False, title="posecrb datasets",
               headers={"paper_name": "paper"})


@command.command("path")
@click.argument("name", type=DatasetArg())
@data_dir_option
def path_cmd(name: str, data_dir: str | None) -> None:
    """Print the file NAME resolves to (exit 1 with a fetch hint if it is not found)."""
    click.echo(str(ds.resolve(name, data_dir).resolve()))


@command.command("fetch")
@click.argument("names", nargs=-1)
@click.option("--all", "all_", is_flag=True, help="Every dataset of the manifest.")
@click.option("--dest", type=OutputDir(), default=None,
              help="Download directory, created if missing (its parent must exist; default: the user cache "
                   "~/.cache/posecrb).")
@click.option("--url", default=None, help="Download from this URL instead of the manifest's (one NAME only).")
@click.option("--timeout", type=FiniteFloat(min=0, min_open=True, max=1e6), default=60.0, show_default=True,
              help="Network timeout in seconds (connection and each read).")
@click.option("--deadline", type=FiniteFloat(min=0, min_open=True, max=1e7), default=600.0, show_default=True,
              help="Overall time limit of each download in seconds (a server that trickles bytes "
                   "never trips --timeout).")
@click.option("--offline-ok", is_flag=True,
              help="No network is not an error: say so once and exit 0 (a failed or bad download still exits 1).")
@data_dir_option
@format_option()
def fetch_cmd(names: tuple[str, ...], all_: bool, dest: str | None, url: str | None, timeout: float,
              deadline: float, offline_ok: bool, data_dir: str | None, fmt: str) -> None:
    """Download NAME(s) over HTTPS, verify the checksum, then move into place atomically.

    A file that already verifies (at the destination, or without --dest anywhere on
    the search path) is never downloaded again or overwritten. A bad checksum or an
    interrupted download leaves no file and exits 1. A response larger than the
    manifest's size of the file is aborted as soon as it exceeds it. Before downloading, the
    server is probed for a few seconds; when it does not answer, the datasets are rows `offline`
    and nothing is attempted (exit 1, or 0 with --offline-ok).
    """

    if all_ == bool(names):
        raise click.UsageError("give dataset NAME(s) or --all (not both)")
    if url and (all_ or len(names) != 1):
        raise click.UsageError("--url needs exactly one NAME")
    manifest = load_manifest()
    entries = list(manifest) if all_ else [manifest.get(n) for n in names]
    quiet = log.getEffectiveLevel() >= logging.ERROR
    # download bars on a terminal; elsewhere (logs, CI) none: each download is logged instead (-v)
    bar = None if quiet else progress_display(transfer=True)

    def factory(entry):
        if bar is None:
            return None
        task = bar.add_task(entry.name, total=None, visible=False)

        def update(done: int, total: int | None) -> None:
            bar.update(task, completed=done, total=total, visible=True)
        return update

    if url:

        def run():
            return [fetch(entries[0], dest=dest, url=url, manifest=manifest, timeout=timeout,
                          deadline=deadline, data_dir=data_dir, progress=factory(entries[0]))]
    else:
        def run():
            return fetch_many(entries, dest=dest, manifest=manifest, progress_factory=factory,
                              timeout=timeout, deadline=deadline, data_dir=data_dir,
                              probe_timeout=min(PROBE_TIMEOUT, timeout))
    if bar is not None:
        with bar:
            results = run()
    else:
        results = run()
    failed = [r for r in results if r.status == "failed"]
    offline = [r for r in results if r.status == "offline"]
    if len(entries) == 1 and (failed or offline):
        if offline and offline_ok:
            log.warning("no network (%s): %s not downloaded", offline[0].error, offline[0].name)
            return
        raise PosecrbError(failed[0].error if failed else
                           f"{offline[0].name}: not downloaded, no network ({offline[0].error})")
    print_rows([r.row() for r in results], fmt, columns=["name", "status", "bytes", "path"],
               single_json=False, title="posecrb datasets fetch")
    if offline:
        reasons = "; ".join(dict.fromkeys(r.error for r in offline))
        skipped = [r.name for r in offline]
        log.warning("no network (%s): %d dataset(s) not downloaded: %s", reasons, len(offline),
                    ", ".join(skipped) if len(skipped) <= 6
                    else ", ".join(skipped[:4]) + f", ... and {len(skipped) - 4} more")
    for r in failed:
        log.warning("%s", r.error)
    if failed or (offline and not offline_ok):
        bad = failed + offline
        raise PosecrbError(f"{len(bad)} of {len(results)} download(s) failed: " + ", ".join(r.name for r in bad))


@command.command("verify")
@data_dir_option
@click.option("--parse", is_flag=True, help="Also parse each file and compare the pose/edge counts.")
@format_option()
def verify_cmd(data_dir: str | None, parse: bool, fmt: str) -> None:
    """Check every dataset file on the search path against the manifest (exit 1 on a mismatch).

    Files the manifest does not know are listed as `unknown` and do not fail.
    """

    checks = dsv.verify_files(data_dir, parse=parse)
    cols = ["name", "file", "status", "algorithm"] + (["poses", "edges"] if parse else []) + ["path"]
    print_rows([c.row() for c in checks], fmt, columns=cols, single_json=False, title="posecrb datasets verify")
    found = {c.entry.name for c in checks if c.entry is not None}
    missing = [e.name for e in load_manifest() if e.name not in found]
    ok = sum(c.status == "ok" for c in checks)
    log.info("%d file(s) verified, %d unknown; not on the search path: %s", ok,
             sum(c.entry is None for c in checks), ", ".join(missing) or "none")
    bad = [c for c in checks if c.failed]
    if bad:
        raise PosecrbError(f"{len(bad)} file(s) do not match the manifest: "
                           + "; ".join(f"{c.path} ({c.status}: {c.algorithm} expected {c.expected}, got {c.actual})"
                                       if c.status != "count mismatch" or c.entry is None else
                                       f"{c.path} (count mismatch: {c.poses} poses / {c.edges} edges, expected "
                                       f"{c.entry.poses} / {c.entry.edges})" for c in bad))


# Peak memory of generating and writing a graph, per edge (measured: 3D grid of 200000 poses,
# 600000 edges, 0.96 GB peak, i.e. 1.6 kB per edge; 2 kB leaves a margin), and edges per pose.
SYNTH_BYTES_PER_EDGE = 2048
SYNTH_EDGES_PER_POSE = {"grid2d": 2, "grid3d": 3, "sphere": 2, "torus": 2, "octagon": 4, "demo": 2}
SYNTH_BASE_BYTES = 200 * 1024 ** 2       # the interpreter, numpy and scipy


def synth_memory(kind: str, poses: int) -> float:
    """Estimated peak memory of ``datasets synth KIND --poses N`` in bytes."""
    return SYNTH_BASE_BYTES + float(poses) * SYNTH_EDGES_PER_POSE.get(kind, 3) * SYNTH_BYTES_PER_EDGE


@command.command("synth")
@click.argument("kind", type=click.Choice(SYNTH_KINDS))
@click.option("--poses", type=PlainInt(2), default=None,
              help="Number of poses (grid2d 100, grid3d 125, sphere 2500, torus 5000; octagon is always 8).")
@click.option("--noise", "sigma", type=FiniteFloat(min=1e-6, max=1e6), default=None,
              help="Noisy measurements with translation std SIGMA and rotation angle std SIGMA [rad]: "
                   "tau = 1/SIGMA^2, kappa = 1/(2 SIGMA^2).")
@click.option("--tau", type=FiniteFloat(min=1e-12, max=1e12), default=None,
              help="Translation precision 1/delta^2 (implies noise unless --noise-free).")
@click.option("--kappa", type=FiniteFloat(min=1e-12, max=1e12), default=None,
              help="Langevin rotation concentration (implies noise unless --noise-free).")
@click.option("--noise-free", is_flag=True, help="Exact measurements even with --tau/--kappa (information only).")
@click.option("--seed", type=SEED_RANGE, default=0, show_default=True, help="Seed of the noise (numpy PCG64).")
@click.option("--extra", "extra_edges", type=PlainInt(0, 21), default=0, show_default=True,
              help="octagon: number of additional measurements, drawn with --seed without repetition "
                   "from the 21 pairs of poses 1..7 (paper Fig. 3-5).")
@click.option("--out", "out", type=OutputFile(GRAPH_EXTENSIONS), required=True,
              help="Output g2o file (its directory must exist).")
@format_option()
def synth_cmd(kind: str, poses: int | None, sigma: float | None, tau: float | None, kappa: float | None,
              noise_free: bool, seed: int, extra_edges: int, out: str, fmt: str) -> None:
    """Write one of our synthetic pose graphs as g2o (vertices = ground truth).

    Noise-free by default; --noise SIGMA or --tau/--kappa draw measurement noise by the
    paper's model (eq. 80): Gaussian translation noise of precision tau and isotropic
    Langevin rotation noise of concentration kappa. The information matrices always
    encode (tau, kappa) in SE-Sync's convention. `demo` is the fixed graph `make run`
    falls back on (noisy 10x10 2D grid, fixed seed).
    """

    if sigma is not None and (tau is not None or kappa is not None):
        raise click.UsageError("--noise sets tau and kappa; do not combine it with --tau/--kappa")
    if sigma is not None:
        tau, kappa = precisions_from_sigma(sigma)
    noisy = (sigma is not None or tau is not None or kappa is not None) and not noise_free
    if kind == "demo" and (poses or sigma or tau or kappa or noise_free):
        raise click.UsageError("`demo` is fixed: no --poses/--noise/--tau/--kappa/--noise-free")
    if poses is not None:
        check_memory(synth_memory(kind, poses), f"--poses {poses}", "ask for fewer poses")
    from ...sim.generators import generate  # noqa: PLC0415 -- lazy: start-up time (scipy.special)

    graph = generate(kind, poses, tau=tau, kappa=kappa, noise=noisy, seed=seed, extra_edges=extra_edges)
    write_g2o(graph, out)
    noisy = noisy or kind == "demo"
    row = {"kind": kind, "poses": graph.n, "edges": graph.m, "dim": graph.dim,
           "tau": float(graph.tau[0]), "kappa": float(graph.kappa[0]),
           "noise": "yes" if noisy else "no", "seed": (seed if kind != "demo" else "fixed") if noisy else None,
           "out": out}
    print_rows([row], fmt, title="posecrb datasets synth")
