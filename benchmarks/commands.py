"""posecrb's commands against each other, whole process, through the harness (hyperfine).

Groups (each written to OUT/GROUP.json; ``--groups`` picks some):

  startup   the interpreter alone, the imports ``solve`` cannot avoid (numpy, scipy.sparse,
            sksparse.cholmod: its floor), ``posecrb --help``, ``posecrb --version``, ``posecrb info``
            and ``posecrb solve --format json`` of a small file (intel; the 400-pose 2D grid without
            data). Goals: ``--help`` at most 0.25 s, ``info`` of a small file at most 0.35 s.
  goals     ``posecrb solve`` of the 2D grid of 100,489 poses and of the 3D grid of 21,952 (each at
            most 15 s, certified), ``posecrb bounds --estimate vertices --format json`` of the 3D grid
            (wall at most 1.5x the work of the stages it reports + 1.5 s: each stage's time times its
            runs, since the default timing protocol repeats the short stages).
  timeline  ``posecrb timeline FILE --estimate none`` against one ``posecrb bounds FILE --estimate
            none --repeat 1`` on city10000, sphere2500, the 2D grid of 10^5 poses
            and the 2D chain of 2,000,000 poses (the longest sums the drift check compares; goal on the
            chain: at most 3x).
  verify    ``posecrb verify FILE --estimate OPT`` (OPT: solve's optimum, written once untimed) against
            ``posecrb solve FILE`` and ``posecrb crlb FILE --estimate OPT`` (goal: verify at most their sum),
            and ``verify --no-solve`` (goal: its certificate stage at most twice solve's own certificate
            check, the ``verify`` stage of solve's times) on the SE-Sync datasets.
  baseline  this checkout against an earlier one (``POSECRB_BASELINE``: the directory of another posecrb
            source tree, e.g. a git worktree of an older commit; skipped without it), side by side:
            ``bounds`` (default) and this checkout's ``solve`` of every SE-Sync dataset and the 3D grid of
            21,952 poses (goal: bounds at most the larger of solve + 0.3 s and 1.3x solve); ``select
            --budget 20%`` of the 2D grids of 10^4, 3*10^4 and 10^5 poses, intel and city10000 (goals: an
            exponent in the candidates of at most 1.2, at most 15 s at 10^5 poses, a certified ratio at
            least the earlier one's minus 0.01); ``bounds --estimate none`` and ``info`` of the 2D grid
            of 10^5 poses (goal: its parse at least 4x faster; the parse stage's median over the check
            run and --runs more runs of each, alternating). Always in alternating rounds.
  threads   ``posecrb solve`` of the 2D grid of 10^5 poses and ``posecrb fim --estimate vertices`` of
            the 3D grid of 2*10^4 poses as posecrb runs them (its own thread policy) against every
            BLAS/OpenMP pool held at one thread (OPENBLAS_NUM_THREADS=1 and the like).

``--quick`` runs every group once on small inputs. Usage: python benchmarks/commands.py [--quick]
[--groups startup,goals,timeline,verify,baseline,threads] [--alternate] [--runs K] [--warmup K]
[--threads T] [--out DIR]
"""
from __future__ import annotations

import os
import statistics
import sys
from pathlib import Path

import harness
from harness import Command, posecrb_cli
from suite import inputs

GROUPS = ("startup", "goals", "timeline", "verify", "baseline", "threads")
IMPORT_FLOOR = "import numpy, scipy.sparse, sksparse.cholmod"
ONE_THREAD = tuple((var, "1") for var in harness.THREAD_VARS)


def small_file() -> str:
    try:
        return str(inputs.path("intel"))
    except NotImplementedError:
        return str(inputs.path(inputs.GRID_2D_SMALL))


def startup(group: harness.Group) -> None:
    py = sys.executable
    small = small_file()
    group.compare("startup", [
        Command("python -c pass", (py, "-c", "pass")),
        Command("import floor", (py, "-c", IMPORT_FLOOR)),
        Command("posecrb --help", posecrb_cli("--help")),
        Command("posecrb --version", posecrb_cli("--version")),
        Command("posecrb info", posecrb_cli("info", small)),
        Command("posecrb solve", posecrb_cli("solve", small, "--format", "json")),
    ], {"file": small})


def goals(group: harness.Group) -> None:
    grid2, grid3 = ("grid2d-400", "grid3d-125") if group.options.quick else ("grid2d-100000", "grid3d-20000")
    for name in (grid2, grid3):
        solve = Command("solve", posecrb_cli("solve", str(inputs.path(name)), "--format", "json"))
        entry = group.compare(f"solve {name}", [solve])
        if entry:
            out = entry["outputs"]["solve"].json()
            entry["checks"].update(poses=out.get("poses"), certified=out.get("certified"), times=out.get("times"))
    entry = group.compare(f"bounds-vertices {grid3}", [
        Command("bounds", posecrb_cli("bounds", str(inputs.path(grid3)), "--estimate", "vertices",
                                      "--format", "json"))])
    if entry:
        out = entry["outputs"]["bounds"].json()
        entry["checks"].update(poses=out.get("poses"), times=out.get("times"), runs=out.get("runs"))


def timeline(group: harness.Group) -> None:
    names = ("grid2d-400", "chain2d-2000") if group.options.quick else \
        ("city10000", "sphere2500", "grid2d-100000", "chain2d-2000000")
    for name, path in harness.found("timeline", names):
        file = str(path)
        group.compare(name, [
            Command("timeline", posecrb_cli("timeline", file, "--estimate", "none")),
            Command("bounds", posecrb_cli("bounds", file, "--estimate", "none", "--repeat", "1")),
        ])


def verify(group: harness.Group) -> None:
    names = ["intel"] if group.options.quick else list(inputs.SESYNC_DATASETS)
    for name, path in harness.found("verify", names):
        file = str(path)
        optimum = inputs.cache_dir() / f"{name}_optimum.g2o"
        if not optimum.is_file():
            optimum.parent.mkdir(parents=True, exist_ok=True)
            made = harness.check_run(Command("solve --out", posecrb_cli("-q", "solve", file, "--out", str(optimum))))
            if not made.ok:
                print(f"verify {name}: solve --out failed: {made.reason()}", file=sys.stderr)
                continue
        entry = group.compare(name, [
            Command("verify", posecrb_cli("verify", file, "--estimate", str(optimum), "--format", "json")),
            Command("verify --no-solve", posecrb_cli("verify", file, "--estimate", str(optimum), "--no-solve",
                                                     "--format", "json")),
            Command("solve", posecrb_cli("solve", file, "--format", "json")),
            Command("crlb", posecrb_cli("crlb", file, "--estimate", str(optimum), "--format", "json")),
        ])
        if entry:
            outputs = entry["outputs"]
            entry["checks"].update(verdict=outputs["verify"].json().get("verdict"),
                                   certificate=outputs["verify --no-solve"].json().get("times", {}).get("certificate"),
                                   solve_certificate=outputs["solve"].json().get("times", {}).get("verify"))


def baseline(group: harness.Group) -> None:
    base = os.environ.get("POSECRB_BASELINE")
    if not base or not os.path.isfile(os.path.join(base, "posecrb", "__init__.py")):
        print("baseline: skipped: POSECRB_BASELINE is not set to another posecrb source tree", file=sys.stderr)
        return
    before = (("PYTHONPATH", base),)
    imported = harness.imported_posecrb(dict(before))
    if imported != Path(base).resolve() / "posecrb":
        raise RuntimeError(f"baseline: the earlier checkout's command imports {imported}, not {base}/posecrb: "
                           "its comparison would time this checkout twice")
    quick = group.options.quick
    bounds_inputs = ["intel"] if quick else [*inputs.SESYNC_DATASETS, "grid3d-20000"]
    for name, path in harness.found("baseline", bounds_inputs):
        args = ("bounds", str(path), "--repeat", "1", "--format", "json")
        group.compare(f"bounds {name}", [Command("bounds", posecrb_cli(*args)),
                                         Command("bounds before", posecrb_cli(*args), before),
                                         Command("solve", posecrb_cli("solve", str(path), "--format", "json"))],
                      alternate=True)
    select_inputs = ["grid2d-400"] if quick else ["grid2d-10000", "grid2d-30000", "grid2d-100000", "intel",
                                                  "city10000"]
    for name, path in harness.found("baseline", select_inputs):
        args = ("select", str(path), "--budget", "20%", "--format", "json")
        entry = group.compare(f"select {name}", [Command("select", posecrb_cli(*args)),
                                                 Command("select before", posecrb_cli(*args), before)],
                              alternate=True)
        if entry:
            out = {k: entry["outputs"][k].json() for k in ("select", "select before")}
            entry["checks"].update(candidates=out["select"].get("candidates"),
                                   ratio=out["select"].get("certified_ratio"),
                                   ratio_before=out["select before"].get("certified_ratio"),
                                   value=out["select"].get("value"), value_before=out["select before"].get("value"),
                                   method=(out["select"].get("stats") or {}).get("strategy"))
    for name, path in harness.found("baseline", ["grid2d-400"] if quick else ["grid2d-100000"]):
        args = ("bounds", str(path), "--estimate", "none", "--repeat", "1", "--format", "json")
        commands = [Command("bounds --estimate none", posecrb_cli(*args)),
                    Command("bounds --estimate none before", posecrb_cli(*args), before),
                    Command("info", posecrb_cli("info", str(path))),
                    Command("info before", posecrb_cli("info", str(path)), before)]
        entry = group.compare(f"parse {name}", commands, alternate=True)
        if entry:
            samples = stage_samples(entry, [cmd for cmd in commands if cmd.label.startswith("bounds")], "parse",
                                    group.options.runs)
            entry["checks"].update(parse=median_or_none(samples["bounds --estimate none"]),
                                   parse_before=median_or_none(samples["bounds --estimate none before"]),
                                   parse_runs=len(samples["bounds --estimate none"]))


def stage_samples(entry: dict, commands: list[Command], stage: str, rounds: int) -> dict[str, list[float]]:
    """The ``stage`` time each command's JSON reports (``times``), from its check run and from
    ``rounds`` more untimed runs, alternating the commands (their order reversed every other round)
    so that a stage of a fraction of a second, which one cold run measures loosely, is the median
    of runs taken under the same load for each command. A failed run contributes nothing."""
    samples = {cmd.label: [] for cmd in commands}
    for cmd in commands:
        samples[cmd.label].append(entry["outputs"][cmd.label].json().get("times", {}).get(stage))
    for k in range(rounds):
        for cmd in commands if k % 2 == 0 else commands[::-1]:
            run = harness.check_run(cmd)
            samples[cmd.label].append(run.json().get("times", {}).get(stage) if run.ok else None)
    return {label: [x for x in xs if isinstance(x, (int, float))] for label, xs in samples.items()}


def median_or_none(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def threads(group: harness.Group) -> None:
    grid2, grid3 = ("grid2d-400", "grid3d-125") if group.options.quick else ("grid2d-100000", "grid3d-20000")
    for label, args in ((f"solve {grid2}", ("solve", str(inputs.path(grid2)), "--format", "json")),
                        (f"fim {grid3}", ("fim", str(inputs.path(grid3)), "--estimate", "vertices",
                                          "--format", "json"))):
        group.compare(label, [Command("posecrb's policy", posecrb_cli(*args)),
                              Command("one thread", posecrb_cli(*args), ONE_THREAD)])


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__.splitlines()[0])
    ap.add_argument("--groups", default=",".join(GROUPS), help=f"comma-separated, of {', '.join(GROUPS)}")
    args = harness.parse(ap, argv)
    chosen = [g for g in args.groups.split(",") if g]
    unknown = sorted(set(chosen) - set(GROUPS))
    if unknown:
        ap.error(f"unknown groups {unknown}; choose from {list(GROUPS)}")
    run = {"startup": startup, "goals": goals, "timeline": timeline, "verify": verify, "baseline": baseline,
           "threads": threads}
    for name in chosen:
        group = harness.start(name, args)
        if group is None:
            break
        run[name](group)
        group.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
