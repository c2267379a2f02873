"""posecrb solve against SE-Sync C++, whole process against whole process, file by file (hyperfine).

For each g2o file of SE-Sync's suite in the data directory (the 16 files, or the NAMEs given;
``--grids`` adds the scaling grids): SE-Sync's example executable ($SESYNC_BIN) and ``posecrb solve
FILE --sesync-compat --format json`` (3D quaternions read as SE-Sync reads them: the same data,
the same objective). The check runs give both objectives (SE-Sync prints 6 significant digits),
whether they agree within that print plus 2e-6 relative (both stop on a relative decrease of about
1e-6), SE-Sync's status and posecrb's certificate. Skipped without $SESYNC_BIN.

Goals (benchmarks/report.py): the sum of the medians at most 0.8x SE-Sync's; every file where
SE-Sync needs 0.5 s or more no slower than SE-Sync, the others within SE-Sync + the import floor
(``benchmarks/commands.py --groups startup``) + 0.1 s.

Usage: SESYNC_BIN=... python benchmarks/peers/sesync_solve.py [--quick] [--grids] [--runs K] [--warmup K]
       [--threads T] [--out DIR] [NAME ...]
"""
from __future__ import annotations

import math
import re
import sys

import _peer  # noqa: F401 -- benchmarks/ on sys.path
import harness
from harness import Command, posecrb_cli
from suite import inputs

_NUMBER = r"([-+0-9.eEinfa]+)"


def parse_sesync(stdout: str) -> dict:
    """What SE-Sync's example prints: poses, measurements, F(x) of the rounded estimate, F(Y) of the
    relaxation, whether it certified the optimum (else its status)."""
    loaded = re.search(r"Loaded (\d+) measurements between (\d+) poses", stdout)

    def last(pattern: str) -> float:
        found = re.findall(pattern + _NUMBER, stdout)
        return float(found[-1]) if found else math.nan

    certified = "Found global optimum!" in stdout
    status = "global optimum" if certified else next(
        (s for s in ("saddle point", "EigImprecision", "maximum rank", "exhausted") if s.lower() in stdout.lower()),
        "unknown")
    return {"objective": last(r"Value of rounded pose estimates F\(x\):\s*"),
            "sdp_value": last(r"Value of dual SDP solution F\(Y\):\s*"), "certified": certified, "status": status,
            "poses": int(loaded.group(2)) if loaded else None,
            "measurements": int(loaded.group(1)) if loaded else None}


def printed_tolerance(value: float, digits: int = 6) -> float:
    """Half a unit in the last place of ``value`` printed with ``digits`` significant digits."""
    if not math.isfinite(value) or value == 0:
        return 0.0
    return 0.5 * 10 ** (math.floor(math.log10(abs(value))) - digits + 1)


def objectives_agree(ours: float, printed: float, rel_solver_tol: float = 2e-6) -> bool:
    """A full-precision objective against SE-Sync's 6-digit print: within the print's rounding plus
    ``rel_solver_tol`` relative (two certified optima of the same data differ by about that much)."""
    if not (math.isfinite(ours) and math.isfinite(printed)):
        return False
    return abs(ours - printed) <= printed_tolerance(printed) + rel_solver_tol * abs(printed)


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__.splitlines()[0])
    ap.add_argument("--grids", action="store_true", help="also the scaling grids of the in-process suite")
    ap.add_argument("names", nargs="*", help="datasets or grids [default: SE-Sync's 16 files]")
    args = harness.parse(ap, argv)
    binary, why = harness.sesync_binary()
    group = harness.start("sesync", args, why)
    if group is None:
        return 0
    names = args.names or (["intel", inputs.GRID_3D_SMALL] if args.quick else list(inputs.SESYNC_DATASETS))
    for name, path in harness.found("sesync", names + (list(inputs.GRIDS) if args.grids else [])):
        file = str(path)
        ours = Command("posecrb", posecrb_cli("solve", file, "--sesync-compat", "--format", "json"))
        entry = group.compare(name, [Command("SE-Sync", (str(binary), file)), ours])
        if entry is None:
            continue
        theirs = parse_sesync(entry["outputs"]["SE-Sync"].stdout)
        ours = entry["outputs"]["posecrb"].json()
        objective = float(ours.get("objective", math.nan))
        entry["checks"].update(
            dim=ours.get("dim"), poses=ours.get("poses"), edges=ours.get("edges"), sesync=theirs,
            posecrb={"objective": objective, "certified": ours.get("certified"), "times": ours.get("times")},
            agree=objectives_agree(objective, theirs["objective"]))
    group.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
