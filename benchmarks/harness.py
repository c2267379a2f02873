"""The harness of the whole-process comparisons: hyperfine runs, peer programs, result files.

Every whole-process figure is hyperfine's (https://github.com/sharkdp/hyperfine, Debian's
``hyperfine``): ``--warmup`` untimed runs, then ``--runs`` timed runs of each command, the
commands one after the other, exported with ``--export-json``. Before it, each command runs once
through ``/usr/bin/time`` (when present): that check run gives its output (objectives, stage
times, certificates, what the comparison checks) and its peak resident memory, and a command
that fails there is recorded as failed instead of timed.

A script of this harness writes one file per group of comparisons, ``OUT/GROUP.json``:
``environment`` (date, commit, machine, load, versions: once) and ``comparisons``, each with a
``label``, hyperfine's export (``hyperfine``: its ``results``, verbatim) and what the script
checked (``checks``). ``benchmarks/report.py`` turns them into tables.

Peers are programs outside this repository, found through environment variables and skipped,
with the reason, when absent:

  SESYNC_BIN          SE-Sync's C++ example executable (C++/build/bin/SE-Sync), which reads a
                      g2o file and prints its results with 6 significant digits;
  POSECRB_MAC_PYTHON  a Python interpreter that can ``import mac`` (Doherty et al.'s MAC,
                      installed from its repository into an environment of its own);
  GTSAM               the ``gtsam`` package in this interpreter (``pip install '.[gtsam]'``).
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent
REPO = BENCHMARKS.parent
sys.path.insert(0, str(BENCHMARKS))

from suite import inputs  # noqa: E402 -- the inputs of the in-process suite, after the path above

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
GNU_TIME = "/usr/bin/time"


@dataclass(frozen=True)
class Command:
    """One program to time: a label (hyperfine's ``-n``), its argv and extra environment variables."""

    label: str
    argv: tuple[str, ...]
    env: tuple[tuple[str, str], ...] = ()

    def shell_words(self) -> str:
        """The command line hyperfine runs (no shell: ``-N``), environment variables through env(1)."""
        prefix = ["/usr/bin/env", *(f"{k}={v}" for k, v in self.env)] if self.env else []
        return shlex.join([*prefix, *self.argv])


@dataclass
class CheckRun:
    """The untimed run of a command: its output, exit status and peak resident set (bytes)."""

    returncode: int
    stdout: str
    stderr: str
    peak_rss: int | None

    @property
    def ok(self) -> bool:
        return self.returncode == 0

    def reason(self) -> str:
        last = (self.stderr.strip().splitlines() or [""])[-1]
        return f"exit {self.returncode}: {last}"[:300]

    def json(self) -> dict:
        """The run's stdout as JSON (``{}`` when it is not)."""
        try:
            value = json.loads(self.stdout)
        except json.JSONDecodeError:
            return {}
        return value if isinstance(value, dict) else {}


@dataclass
class Group:
    """The comparisons of one script, written to ``OUT/NAME.json`` by ``save``."""

    name: str
    options: argparse.Namespace
    comparisons: list[dict] = field(default_factory=list)

    def compare(self, label: str, commands: list[Command], checks: dict | None = None, *,
                alternate: bool | None = None) -> dict | None:
        """Check-run every command, then time them with hyperfine; record and return the comparison
        (None, and a failure recorded, when a check run fails). ``alternate`` (default: the option
        ``--alternate``) times them side by side in alternating rounds (``alternating``)."""
        runs = {c.label: check_run(c) for c in commands}
        entry: dict = {"label": label, "commands": {c.label: c.shell_words() for c in commands},
                       "peak_rss": {k: r.peak_rss for k, r in runs.items()}, "checks": dict(checks or {})}
        failed = {k: r.reason() for k, r in runs.items() if not r.ok}
        if failed:
            entry["failed"] = failed
            self.comparisons.append(entry)
            print(f"{self.name} {label}: failed: {failed}", file=sys.stderr)
            return None
        try:
            side_by_side = getattr(self.options, "alternate", False) if alternate is None else alternate
            entry["hyperfine"] = alternating(commands, self.options) if side_by_side else \
                hyperfine(commands, self.options)
        except subprocess.CalledProcessError as exc:   # a timed run failed where the check run did not
            entry["failed"] = {"hyperfine": f"exit {exc.returncode}"}
            self.comparisons.append(entry)
            print(f"{self.name} {label}: failed in hyperfine's runs (exit {exc.returncode})", file=sys.stderr)
            return None
        entry["outputs"] = runs
        self.comparisons.append(entry)
        return entry

    def save(self) -> Path:
        out = Path(self.options.out)
        out.mkdir(parents=True, exist_ok=True)
        comparisons = [{k: v for k, v in c.items() if k != "outputs"} for c in self.comparisons]
        target = out / f"{self.name}.json"
        write_json(target, {"group": self.name, "environment": environment(self.options),
                            "comparisons": comparisons})
        print(f"wrote {target}", file=sys.stderr)
        return target


def parser(description: str) -> argparse.ArgumentParser:
    """The options every script of the harness takes."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--quick", action="store_true",
                    help="small inputs, one timed run, no warm-up: does every comparison still run?")
    ap.add_argument("--runs", type=int, default=None, help="timed runs per command [default: 3; --quick: 1]")
    ap.add_argument("--warmup", type=int, default=None, help="untimed runs first [default: 1; --quick: 0]")
    ap.add_argument("--threads", type=int, default=0,
                    help="threads of every OpenMP/BLAS/numba pool of the programs; 0 leaves each pool its "
                         "default [default: 0]")
    ap.add_argument("--alternate", action="store_true",
                    help="one timed run of each command per hyperfine call, the calls in alternating order, "
                         "--runs rounds (side by side under the same load) instead of all runs of one command "
                         "then the next")
    ap.add_argument("--out", default=str(REPO / ".bench" / "hyperfine"),
                    help="directory of the result files [default: .bench/hyperfine]")
    return ap


def parse(ap: argparse.ArgumentParser, argv: list[str] | None) -> argparse.Namespace:
    args = ap.parse_args(argv)
    args.runs = args.runs if args.runs is not None else (1 if args.quick else 3)
    args.warmup = args.warmup if args.warmup is not None else (0 if args.quick else 1)
    if args.threads:
        os.environ.update({var: str(args.threads) for var in THREAD_VARS})
    return args


def hyperfine_binary() -> str | None:
    return shutil.which("hyperfine")


def alternating(commands: list[Command], options: argparse.Namespace) -> dict:
    """hyperfine's export of ``commands`` timed side by side: ``options.runs`` rounds, each one
    hyperfine call of one run per command, the commands' order reversed every other round (the
    first round after ``options.warmup`` untimed runs), their times merged into one export."""
    merged: dict[str, dict] = {}
    for k in range(options.runs):
        order = commands if k % 2 == 0 else commands[::-1]
        one = argparse.Namespace(**{**vars(options), "runs": 1, "warmup": options.warmup if k == 0 else 0})
        for result in hyperfine(order, one)["results"]:
            slot = merged.setdefault(result["command"], {**result, "times": []})
            slot["times"].extend(result["times"])
    results = []
    for c in commands:
        r = merged[c.label]
        times = sorted(r["times"])
        r.update(mean=sum(times) / len(times), median=times[len(times) // 2] if len(times) % 2 else
                 (times[len(times) // 2 - 1] + times[len(times) // 2]) / 2, min=times[0], max=times[-1])
        results.append(r)
    return {"results": results, "alternated": options.runs}


def hyperfine(commands: list[Command], options: argparse.Namespace) -> dict:
    """hyperfine's export of ``commands`` (``results``: one entry per command, ``command`` = label)."""
    binary = hyperfine_binary()
    if binary is None:
        raise RuntimeError("hyperfine is not installed (Debian: apt-get install hyperfine)")
    with tempfile.TemporaryDirectory(prefix="posecrb-hyperfine-") as tmp:
        export = Path(tmp) / "export.json"
        argv = [binary, "-N", "--style", "none", "--warmup", str(options.warmup), "--runs", str(options.runs),
                "--export-json", str(export)]
        for c in commands:
            argv += ["-n", c.label, c.shell_words()]
        subprocess.run(argv, check=True, env=child_env(), stdout=subprocess.DEVNULL)
        return json.loads(export.read_text())


def check_run(command: Command, timeout: float | None = None) -> CheckRun:
    """Run ``command`` once, untimed (GNU time measures its peak resident set when installed)."""
    env = {**child_env(), **dict(command.env)}
    with tempfile.NamedTemporaryFile(prefix="posecrb-rss-", suffix=".txt") as rss:
        timed = os.access(GNU_TIME, os.X_OK)
        argv = [GNU_TIME, "-q", "-f", "%M", "-o", rss.name, *command.argv] if timed else list(command.argv)
        proc = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=timeout, check=False)
        try:
            peak = int(Path(rss.name).read_text().split()[-1]) * 1024 if timed else None
        except (ValueError, IndexError):
            peak = None
    return CheckRun(proc.returncode, proc.stdout, proc.stderr, peak)


def child_env() -> dict[str, str]:
    """The measured programs' environment: this checkout's posecrb first on PYTHONPATH (asv's
    suite measures the same one), bytecode writing allowed (an installed package has it)."""
    env = inputs.posecrb_env()
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    # ``python -m`` puts the working directory ahead of PYTHONPATH: run from a checkout, a program
    # given another checkout's PYTHONPATH (the baseline) would import this one.
    env["PYTHONSAFEPATH"] = "1"
    return env


def imported_posecrb(extra_env: dict[str, str]) -> Path:
    """The package directory a measured ``posecrb`` command imports with ``extra_env`` over the
    measured programs' environment (from the checkout as working directory, as they run)."""
    code = "import posecrb, pathlib; print(pathlib.Path(posecrb.__file__).resolve().parent)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO,
                         env={**child_env(), **extra_env}).stdout
    return Path(out.strip())


def posecrb_cli(*args: str) -> tuple[str, ...]:
    """argv of a posecrb command run by this interpreter."""
    return (*inputs.posecrb_argv(), *args)


def write_json(path: Path, value: object) -> None:
    """Write ``value`` as JSON atomically (a temporary file renamed over ``path``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile("w", dir=path.parent, prefix=f".{path.name}.", delete=False) as fh:
        json.dump(value, fh, indent=1, default=str)
    os.replace(fh.name, path)


def start(name: str, options: argparse.Namespace, missing: str = "") -> Group | None:
    """The group of a script's comparisons; None, after saying why on stderr, when ``missing`` names
    what is absent (a peer) or hyperfine is not installed: an absent program is not an error."""
    if not missing and hyperfine_binary() is None:
        missing = "hyperfine is not installed (Debian: apt-get install hyperfine)"
    if missing:
        print(f"{name}: skipped: {missing}", file=sys.stderr)
        return None
    return Group(name, options)


def found(group: str, names: list[str]) -> Iterator[tuple[str, Path]]:
    """(name, file) of each input that is here; an absent dataset is said on stderr and left out."""
    for name in names:
        try:
            yield name, inputs.path(name)
        except NotImplementedError as exc:
            print(f"{group}: {exc}", file=sys.stderr)


# ---- peers ------------------------------------------------------------------------------------

def sesync_binary() -> tuple[str | None, str]:
    """($SESYNC_BIN, "") when it names an executable, else (None, why not)."""
    spec = os.environ.get("SESYNC_BIN")
    if not spec:
        return None, "SESYNC_BIN is not set (the path of SE-Sync's C++ example executable)"
    if not (os.path.isfile(spec) and os.access(spec, os.X_OK)):
        return None, f"SESYNC_BIN={spec} is not an executable file"
    return spec, ""


def mac_python() -> tuple[str | None, str]:
    """($POSECRB_MAC_PYTHON, "") when it is an interpreter that imports MAC, else (None, why not)."""
    spec = os.environ.get("POSECRB_MAC_PYTHON")
    if not spec:
        return None, "POSECRB_MAC_PYTHON is not set (a Python interpreter that can `import mac`)"
    run = check_run(Command("mac", (spec, "-c", "import mac.solvers")), timeout=120) \
        if os.path.isfile(spec) and os.access(spec, os.X_OK) else None
    if run is None:
        return None, f"POSECRB_MAC_PYTHON={spec} is not an executable file"
    if not run.ok:
        return None, f"POSECRB_MAC_PYTHON={spec} cannot import mac.solvers: {run.reason()}"
    return spec, ""


# ---- what produced the figures ------------------------------------------------------------------

def environment(options: argparse.Namespace | None = None) -> dict:
    """Date, commit, machine, load and the versions that change a timing: stated once per file."""
    cpu = platform.machine()
    memory = None
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(line.split(":", 1)[1].strip() for line in fh if line.startswith("model name"))
        with open("/proc/meminfo") as fh:
            memory = int(next(line.split()[1] for line in fh if line.startswith("MemTotal"))) * 1024
    except (OSError, StopIteration, ValueError):
        pass
    versions = {}
    for name in ("posecrb", "numpy", "scipy", "scikit-sparse", "numba", "gtsam"):
        try:
            versions[name] = version(name)
        except PackageNotFoundError:
            pass
    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True,
                            check=False).stdout.strip()
    hyperfine_version = subprocess.run([hyperfine_binary(), "--version"], capture_output=True, text=True,
                                       check=False).stdout.strip() if hyperfine_binary() else None
    return {
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "commit": commit, "cpu": cpu, "cores": os.cpu_count(), "memory": memory,
        "load_average": list(os.getloadavg()), "platform": platform.platform(),
        "python": platform.python_version(), "versions": versions, "hyperfine": hyperfine_version,
        "threads": getattr(options, "threads", 0), "runs": getattr(options, "runs", None),
        "warmup": getattr(options, "warmup", None), "quick": getattr(options, "quick", False),
        "alternate": getattr(options, "alternate", False), "baseline_commit": _baseline_commit(),
    }


def _baseline_commit() -> str | None:
    """The commit of the earlier checkout ``POSECRB_BASELINE`` names (the baseline group's)."""
    base = os.environ.get("POSECRB_BASELINE")
    if not base:
        return None
    out = subprocess.run(["git", "-C", base, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                         check=False).stdout.strip()
    return out or base
