"""Shared by the benchmark scripts: the timing protocol, the dataset list, whole-process runs.

In-process figures use ``median_time`` (posecrb.core.timing: one warm-up, then the median of k).
Whole-process figures (``run_process``, ``alternate``) follow the same protocol one level up:
one untimed warm-up run of every program (page cache, numba's on-disk cache), then k timed
rounds in which the programs alternate run by run (the order flips every round so neither
always runs on a cache the other just warmed), and the median of each program's k runs.
The wall time of a run spans fork/exec to reaping the child. Its peak memory is the measured
program's own maximum resident set, taken by GNU time (``/usr/bin/time -f %M``, a small C parent):
``ru_maxrss`` of a child forked straight from this Python process would start from this process's
own size (Linux keeps the high-water mark across fork and exec), so it is only the fallback.
"""
from __future__ import annotations

import argparse
import datetime
import logging
import math
import os
import platform
import shlex
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as `python benchmarks/x.py` from anywhere: measure this checkout
    sys.path.insert(0, str(REPO))

from posecrb.core.timing import timed  # noqa: E402 -- after the sys.path line above
from posecrb.datasets import search as datasets  # noqa: E402

# The 16 g2o files of the SE-Sync benchmark suite, 2D then 3D, each group by size.
SESYNC_SUITE = ["CSAIL", "MIT", "intel", "kitti_05", "manhattan", "kitti_02", "kitti_00", "city10000",
                "ais2klinik", "tinyGrid3D", "smallGrid3D", "parking-garage", "sphere2500",
                "sphere_bignoise_vertex3", "torus3D", "cubicle"]
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def median_time(fn, repeat: int) -> float:
    """Median wall time of ``fn`` over ``repeat`` runs after one warm-up (posecrb.core.timing)."""
    return timed(fn, max(repeat, 2))[1]


def dataset_args(description: str, repeat: int) -> tuple[argparse.Namespace, list[Path]]:
    """Parse ``[--repeat K] [NAME ...]`` and resolve the datasets (all found when none named)."""
    logging.getLogger("posecrb").setLevel(logging.ERROR)
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("names", nargs="*")
    ap.add_argument("--repeat", type=int, default=repeat)
    args = ap.parse_args()
    files = [datasets.resolve(n) for n in args.names] if args.names else datasets.dataset_files(first_per_name=True)
    return args, files


def process_parser(description: str, *, with_data_dir: bool = False, repeat: int | None = None,
                   repeat_help: str = "timed rounds (median)", threads: int = 1) -> argparse.ArgumentParser:
    """The arguments every whole-process benchmark takes: --posecrb and --threads (default
    ``threads``; 0 leaves every pool at its own default), with ``with_data_dir`` --data-dir
    (``data_dir``), with ``repeat`` --repeat K (default ``repeat``). Each script adds its own
    arguments to the parser returned."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--posecrb", default=None, help="command that runs posecrb [default: python -m posecrb "
                                                     "from this checkout]")
    ap.add_argument("--threads", type=int, default=threads,
                    help="threads of every OpenMP/BLAS/numba pool of the measured programs, 0 = each pool's "
                         f"own default (every core) [default: {threads}]")
    if with_data_dir:
        ap.add_argument("--data-dir", default=None,
                        help="directory of the g2o files [default: $POSECRB_DATA, else a datasets directory "
                             "on the search path]")
    if repeat is not None:
        ap.add_argument("--repeat", type=int, default=repeat, help=f"{repeat_help} [default: {repeat}]")
    return ap


# ---- the data directory ---------------------------------------------------------------

def data_dir(arg: str | None) -> Path | None:
    """--data-dir, else $POSECRB_DATA (first entry), else the first ``shared/datasets`` found."""
    if arg:
        return Path(arg)
    env = os.environ.get("POSECRB_DATA")
    if env:
        return Path(env.split(os.pathsep)[0])
    for d in datasets.search_path():
        if d.name == "datasets" and d.is_dir() and any(d.glob("*.g2o")):
            return d
    return None


def suite_files(directory: Path | None, names: Sequence[str] = ()) -> list[Path]:
    """The named g2o files, else every g2o file in ``directory`` (SE-Sync suite order first)."""
    if directory is None:
        return []
    if names:
        return [directory / (n if n.endswith(".g2o") else f"{n}.g2o") for n in names]
    found = {p.stem: p for p in sorted(directory.glob("*.g2o"))}
    ordered = [found.pop(n) for n in SESYNC_SUITE if n in found]
    return ordered + list(found.values())


# ---- whole-process runs -----------------------------------------------------------------

def posecrb_command(spec: str | None = None) -> list[str]:
    """argv prefix that runs posecrb: ``spec`` split like a shell would, else this checkout's
    package under the current interpreter (``python -m posecrb`` with PYTHONPATH = the checkout,
    see ``child_env``). A pyenv/virtualenv shim in front of a console script adds its own start-up,
    which is not posecrb's, so the default goes straight to the interpreter."""
    return shlex.split(spec) if spec else [sys.executable, "-m", "posecrb"]


def child_env(threads: int | None = 1, extra: dict | None = None) -> dict:
    """Environment of the measured programs: this checkout first on PYTHONPATH; with ``threads``
    every OpenMP/BLAS/numba pool of BOTH programs capped at that many threads. PYTHONDONTWRITEBYTECODE
    is dropped: an installed package has its compiled bytecode, and without it every run would
    compile posecrb's sources again (a cost no user pays)."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    if threads:
        for var in THREAD_VARS:
            env[var] = str(threads)
    env.update(extra or {})
    return env


@dataclass
class ProcRun:
    argv: list[str]
    wall: float                  # seconds, fork/exec to reaping
    max_rss: int                 # bytes, the child's own peak resident set
    returncode: int
    stdout: str
    stderr: str
    status: str                  # "ok" | "exit N" | "timeout" | "memory"
    cpu: float = 0.0             # user + system seconds of the child

    @property
    def ok(self) -> bool:
        return self.status == "ok"


GNU_TIME = "/usr/bin/time" if os.path.isfile("/usr/bin/time") and os.access("/usr/bin/time", os.X_OK) else None


def _vm_rss(pid: int) -> int:
    """Resident set of ``pid`` and all its descendants, bytes (0 once gone)."""
    total = 0
    try:
        with open(f"/proc/{pid}/status") as fh:
            total = next((int(line.split()[1]) * 1024 for line in fh if line.startswith("VmRSS:")), 0)
        with open(f"/proc/{pid}/task/{pid}/children") as fh:
            kids = [int(k) for k in fh.read().split()]
    except (OSError, ValueError):
        return total
    return total + sum(_vm_rss(k) for k in kids)


def run_process(argv: Sequence[str], env: dict | None = None, timeout: float | None = None,
                max_rss: float | None = None, cwd: str | os.PathLike | None = None) -> ProcRun:
    """Run ``argv`` once; wall time, peak RSS and output. A watcher kills the process group when
    it runs longer than ``timeout`` seconds or its RSS exceeds ``max_rss`` bytes (status
    "timeout" / "memory"), so a scaling run cannot take the machine down."""
    argv = [str(a) for a in argv]
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err, \
            tempfile.NamedTemporaryFile(prefix="posecrb-bench-time-", suffix=".txt") as rss_file:
        full = [GNU_TIME, "-q", "-f", "%M", "-o", rss_file.name, *argv] if GNU_TIME else argv
        t0 = time.perf_counter()
        proc = subprocess.Popen(full, stdout=out, stderr=err, env=env, cwd=cwd, start_new_session=True)
        killed: list[str] = []
        done = threading.Event()

        def watch() -> None:
            while not done.wait(0.05):
                reason = None
                if timeout is not None and time.perf_counter() - t0 > timeout:
                    reason = "timeout"
                elif max_rss is not None and _vm_rss(proc.pid) > max_rss:
                    reason = "memory"
                if reason:
                    killed.append(reason)
                    try:
                        os.killpg(proc.pid, 9)
                    except ProcessLookupError:
                        pass
                    return

        watcher = threading.Thread(target=watch, daemon=True)
        if timeout is not None or max_rss is not None:
            watcher.start()
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        done.set()
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        stdout = out.read().decode(errors="replace")
        stderr = err.read().decode(errors="replace")
        peak = int(usage.ru_maxrss) * 1024
        if GNU_TIME:
            try:
                peak = int(Path(rss_file.name).read_text().split()[-1]) * 1024
            except (OSError, ValueError, IndexError):
                peak = 0   # killed before GNU time could write
    rc = proc.returncode
    state = killed[0] if killed else ("ok" if rc == 0 else f"exit {rc}")
    return ProcRun(argv, wall, peak, rc, stdout, stderr, state, usage.ru_utime + usage.ru_stime)


def alternate(programs: dict[str, Callable[[], ProcRun]], rounds: int, warmup: bool = True
              ) -> dict[str, list[ProcRun]]:
    """One untimed warm-up of each program, then ``rounds`` rounds running each once, the
    order reversed every other round (A B, B A, A B, ...). Returns the timed runs per program."""
    names = list(programs)
    if warmup:
        for name in names:
            programs[name]()
    runs: dict[str, list[ProcRun]] = {name: [] for name in names}
    for k in range(rounds):
        for name in (names if k % 2 == 0 else names[::-1]):
            runs[name].append(programs[name]())
    return runs


def median_run(runs: Sequence[ProcRun]) -> ProcRun:
    """The run of median wall time (the lower middle for an even count), so its output and
    memory belong to the time printed."""
    ordered = sorted(runs, key=lambda r: r.wall)
    return ordered[(len(ordered) - 1) // 2]


def median_wall(runs: Sequence[ProcRun]) -> float:
    return statistics.median(r.wall for r in runs)


def fit_exponent(sizes: Sequence[float], values: Sequence[float]) -> float:
    """Least-squares slope of log(value) against log(size): value ~ size^slope."""
    pts = [(math.log(s), math.log(v)) for s, v in zip(sizes, values) if s > 0 and v > 0]
    if len(pts) < 2:
        return float("nan")
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx if sxx > 0 else float("nan")


# ---- what produced the figures --------------------------------------------------------------

def _pkg_versions(names: Sequence[str]) -> dict[str, str]:
    out = {}
    for name in names:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            pass
    return out


def machine_lines(threads: int | None = None) -> list[str]:
    """Date, CPU model and cores, load, Python and the packages that change a timing."""
    cpu = platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    mem = ""
    try:
        with open("/proc/meminfo") as fh:
            kb = int(next(ln.split()[1] for ln in fh if ln.startswith("MemTotal")))
        mem = f", {kb / 2**20:.1f} GiB RAM"
    except (OSError, StopIteration, ValueError):
        pass
    load = (", load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())) if hasattr(os, "getloadavg") else ""
    vers = _pkg_versions(["posecrb", "numpy", "scipy", "scikit-sparse", "numba", "click", "rich", "pandas"])
    blas = _blas_description()
    lines = [
        f"date: {datetime.datetime.now().astimezone().isoformat(timespec='seconds')}",
        f"machine: {cpu}, {os.cpu_count()} cores{mem}{load}; {platform.platform()}",
        f"python {platform.python_version()} ({sys.executable}); " + ", ".join(f"{k} {v}" for k, v in vers.items()),
        f"posecrb checkout: {REPO}" + (f" @ {_git_head()}" if _git_head() else ""),
    ]
    if blas:
        lines.append(f"BLAS/LAPACK: {blas}")
    if threads:
        lines.append(f"threads: {'/'.join(THREAD_VARS)}={threads} for every measured program")
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):
        lines.append("PYTHONDONTWRITEBYTECODE is set here and dropped for the measured programs (bytecode cached)")
    return lines


def _git_head() -> str:
    try:
        return subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, timeout=5, check=False).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def _blas_description() -> str:
    try:
        import numpy  # noqa: F401  (loads the BLAS numpy links)
        import sksparse.cholmod  # noqa: F401  (loads CHOLMOD's BLAS)
        from threadpoolctl import threadpool_info
    except ImportError:
        return ""
    seen = []
    for info in threadpool_info():
        item = f"{info.get('internal_api')} {info.get('version') or ''} ({Path(info.get('filepath', '')).name})"
        if item not in seen:
            seen.append(item)
    return "; ".join(seen)


def print_header(title: str, threads: int | None = None, extra: Sequence[str] = ()) -> None:
    print(f"# {title}")
    for line in [*machine_lines(threads), *extra]:
        print(f"# {line}")
    print(flush=True)


def fmt_bytes(n: float) -> str:
    return "-" if not n or math.isnan(n) else (f"{n / 2**30:.2f} GB" if n >= 2**30 else f"{n / 2**20:.0f} MB")


def fmt_s(t: float | None, digits: int = 3) -> str:
    return "-" if t is None or math.isnan(t) else f"{t:.{digits}f}"
