"""Other programs run side by side with posecrb: SE-Sync's C++ command-line example, and MAC.

Neither is installable from a package registry; each is built or installed separately (never
part of this repository) and found through environment variables:

  SESYNC_BIN         path of SE-Sync's example executable (C++/build/bin/SE-Sync), which reads a
                     g2o file and prints its results with 6 significant digits;
  SESYNC_BUILD       one line saying how it was built (commit, build type, OpenMP, Eigen, BLAS), or
  SESYNC_BUILD_INFO  a file holding that description (its "Summary:" line is printed); without
                     either, a file SE-Sync-BUILD.md in a parent directory of the binary is used.
  POSECRB_MAC_PYTHON a Python interpreter that can ``import mac`` (Doherty et al.'s MAC, installed
                     from its repository into its own virtual environment, e.g.
                     ``python -m venv --system-site-packages mac-venv; mac-venv/bin/pip install -e
                     ./mac scikit-sparse``: an editable install, because MAC's setup.py misses its
                     subpackages without ``__init__.py``); benchmarks/mac_compare.py runs it.
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

from _common import ProcRun, run_process

# What mac_build_info asks MAC's interpreter: its version and where the package lives.
_MAC_WHERE = ("import json, os; from importlib import metadata; import mac; "
              "print(json.dumps([metadata.version('mac'), os.path.dirname(list(mac.__path__)[0])]))")


def sesync_binary() -> tuple[Path | None, str]:
    """(path, "") when $SESYNC_BIN names an executable, else (None, why not)."""
    spec = os.environ.get("SESYNC_BIN")
    if not spec:
        return None, "SESYNC_BIN is not set (path of SE-Sync's C++ example executable)"
    p = Path(spec)
    if not (p.is_file() and os.access(p, os.X_OK)):
        return None, f"SESYNC_BIN={spec} is not an executable file"
    return p, ""


def sesync_build_info(binary: Path | None) -> str:
    if os.environ.get("SESYNC_BUILD"):
        return os.environ["SESYNC_BUILD"]
    candidates = []
    if os.environ.get("SESYNC_BUILD_INFO"):
        candidates.append(Path(os.environ["SESYNC_BUILD_INFO"]))
    if binary is not None:
        candidates += [parent / "SE-Sync-BUILD.md" for parent in binary.resolve().parents]
    for c in candidates:
        if c.is_file():
            text = c.read_text(errors="replace")
            m = re.search(r"^\s*(?:\*\*)?Summary:?(?:\*\*)?:?\s*(.+)$", text, re.MULTILINE)
            return f"{m.group(1).strip() if m else text.strip().splitlines()[0]} (from {c})"
    return "unknown (set SESYNC_BUILD or SESYNC_BUILD_INFO)"


@dataclass
class SESyncOutput:
    objective: float          # F(x) of the rounded estimate, as printed (6 significant digits)
    sdp_value: float          # F(Y) of the relaxation
    certified: bool           # "Found global optimum!"
    status: str
    poses: int
    measurements: int
    reported_total: float     # SE-Sync's own "Total elapsed computation time" (excludes reading the file)
    init_time: float


def _last_float(pattern: str, text: str) -> float:
    found = re.findall(pattern, text)
    return float(found[-1]) if found else float("nan")


def parse_sesync(stdout: str) -> SESyncOutput:
    m = re.search(r"Loaded (\d+) measurements between (\d+) poses", stdout)
    certified = "Found global optimum!" in stdout
    status = "global optimum" if certified else next(
        (s for s in ("saddle point", "EigImprecision", "maximum rank", "exhausted") if s.lower() in stdout.lower()),
        "unknown")
    num = r"([-+0-9.eEinfa]+)"
    return SESyncOutput(
        objective=_last_float(r"Value of rounded pose estimates F\(x\):\s*" + num, stdout),
        sdp_value=_last_float(r"Value of dual SDP solution F\(Y\):\s*" + num, stdout),
        certified=certified, status=status,
        poses=int(m.group(2)) if m else -1, measurements=int(m.group(1)) if m else -1,
        reported_total=_last_float(r"Total elapsed computation time:\s*" + num + r" seconds", stdout),
        init_time=_last_float(r"SE-Sync initialization finished; elapsed time:\s*" + num, stdout),
    )


def printed_tolerance(value: float, digits: int = 6) -> float:
    """Half a unit in the last place of ``value`` printed with ``digits`` significant digits
    (std::cout's default), i.e. how far the true value may be from the printed one."""
    if not math.isfinite(value) or value == 0:
        return 0.0
    return 0.5 * 10 ** (math.floor(math.log10(abs(value))) - digits + 1)


def objectives_agree(ours: float, theirs_printed: float, rel_solver_tol: float = 2e-6) -> bool:
    """Agreement of a full-precision objective with SE-Sync's 6-digit print: within the print's
    rounding plus ``rel_solver_tol`` relative (both solvers stop on a relative decrease of ~1e-6,
    so two certified optima of the same data can differ by about that much)."""
    if not (math.isfinite(ours) and math.isfinite(theirs_printed)):
        return False
    return abs(ours - theirs_printed) <= printed_tolerance(theirs_printed) + rel_solver_tol * abs(theirs_printed)


def run_sesync(binary: Path, g2o: Path, env: dict, timeout: float | None = None,
               max_rss: float | None = None, cwd: str | os.PathLike | None = None) -> ProcRun:
    """One whole-process run (SE-Sync writes nothing but stdout with its defaults)."""
    return run_process([str(binary), str(g2o)], env=env, timeout=timeout, max_rss=max_rss, cwd=cwd)


def mac_python() -> tuple[str | None, str]:
    """(interpreter, "") when $POSECRB_MAC_PYTHON names one that imports MAC, else (None, why not)."""
    spec = os.environ.get("POSECRB_MAC_PYTHON")
    if not spec:
        return None, "POSECRB_MAC_PYTHON is not set (a Python interpreter that can `import mac`)"
    if not (Path(spec).is_file() and os.access(spec, os.X_OK)):
        return None, f"POSECRB_MAC_PYTHON={spec} is not an executable file"
    run = run_process([spec, "-c", "import mac.solvers"], timeout=120)
    if not run.ok:
        return None, f"POSECRB_MAC_PYTHON={spec} cannot import mac.solvers: {run.stderr.strip().splitlines()[-1:]}"
    return spec, ""


def mac_build_info(python: str) -> str:
    """MAC's version, source directory and git commit (when the source is a git checkout)."""
    run = run_process([python, "-c", _MAC_WHERE], timeout=120)
    try:
        ver, where = json.loads(run.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        return f"{python} (version unknown)"
    commit = run_process(["git", "-C", where, "log", "-1", "--format=%h %cs"], timeout=30)
    return f"mac {ver} from {where}" + (f" @ {commit.stdout.strip()}" if commit.ok and commit.stdout.strip() else "") \
        + f", run by {python}"

