"""Tables I-IV of the paper on every available dataset (docs/design.md#tables).

One ``dataset_row`` per dataset computes everything (parse, bounds, certified
solve, FIM at the optimum and its log-det, construction times); the four tables
are column views of those rows. Timing protocol (``posecrb.core.timing.measure``):
``time.perf_counter`` around exactly the measured work, run as ``repeat`` says (1: once, the
library's default; k: warm-up, then the median of k; "auto": adaptive, the command line's
default); ``runs`` of a row says how many runs each time is the median of:

* ``lb_time`` / ``ub_time`` / ``ub_lambda_time``: see ``posecrb.models.paper.bounds.compute_bounds``;
* ``fim_time``: ordering + numeric Cholesky + log-det of the anchored FIM (Table I/II "Time");
* ``fim_build_time`` / ``laplacians_build_time``: construction of the whole FIM from the
  estimate and edge data, vs the two weighted reduced Laplacians (Table III/IV);
* ``solve_time``: one run of the certified solver (not repeated).
"""
from __future__ import annotations

import logging
import os
import shlex
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field, fields
from functools import partial
from typing import Any

import numpy as np

from ..core import provenance
from ..core.choices import EXECUTORS
from ..core.errors import ArgumentError, DatasetNotFound, InternalError, PosecrbError, UsageError, status_of
from ..core.status import log_status, put
from ..core.timing import Repeat, timed
from ..datasets import search as datasets
from ..datasets.manifest import load_manifest
from ..io import load
from ..sim.montecarlo import Task, run_dask, task_chunks
from .evaluate import EvaluationSettings, evaluate
from .published import TABLE_II_FIT_FOOTNOTE, TABLE_II_FOOTNOTE, TABLE_II_PUBLISHED_FOOTNOTE, paper_row

log = logging.getLogger("posecrb")

# Failed computations make the command exit 1; "not found" rows of datasets that were not
# asked for by name (e.g. grid3D/rim, which only a user with internet can fetch) do not.
FAILED_STATUSES = ("parse error", "not positive definite", "uncertified", "disconnected", "error")


@dataclass(frozen=True)
class TableSettings:
    """``rotation_weight`` / ``fim_variant``: the model's quantities by default (eq. 59, the model's
    Fisher information); ``published()`` gives the settings that reproduce the printed Table II."""

    repeat: Repeat = 1
    rotation_weight: str = "eq59"
    data_dir: str | None = None
    solver: dict = field(default_factory=dict)
    fim_variant: str = "consistent"
    ordering: str = "auto"          # fill-reducing ordering (posecrb.linalg.ordering; cost only)

    @property
    def as_published(self) -> bool:
        return self.rotation_weight == "table2" and self.fim_variant == "eq64"

    @classmethod
    def from_record(cls, settings: Mapping[str, Any]) -> TableSettings:
        """The settings of a ``tables --out`` run record (``run.json``'s ``settings``).

        Records written before 0.3 name the rotation weight ``rotation_model``: it is read as
        ``rotation_weight``, with a ``DeprecationWarning``. Unknown keys are an ``ArgumentError``."""
        if not isinstance(settings, Mapping):
            raise ArgumentError("settings", type(settings).__name__, "is not a mapping (run.json's settings)", sep=": ")
        values = dict(settings)
        if "rotation_model" in values:
            warnings.warn("run.json: the setting 'rotation_model' is now 'rotation_weight' (read as such); "
                          "records written by posecrb 0.3 and later use the new key", DeprecationWarning, stacklevel=2)
            old = values.pop("rotation_model")
            values.setdefault("rotation_weight", old)
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ArgumentError("settings", f"{{... {len(values)} keys}}", f"has unknown keys {unknown}", sep=": ")
        return cls(**values)


def published_settings(**kwargs: Any) -> TableSettings:
    """Eq. (64) as printed with the empirical Table II rotation weight (``posecrb tables --as-published``)."""
    return TableSettings(rotation_weight="table2", fim_variant="eq64", **kwargs)


def dataset_names(names: Sequence[str] | None = None, data_dir: str | None = None) -> list[str]:
    """The paper's datasets first (Table I then II, in the paper's order), then every other
    manifest entry, then any other dataset file found on the search path."""
    if names:
        return list(names)

    man = load_manifest()
    order = [e.name for e in man.paper()] + [e.name for e in man if e.table is None]
    known = {n.lower() for n in order} | {e.file.lower() for e in man}
    extra = [p.stem for p in datasets.dataset_files(data_dir, first_per_name=True)
             if p.stem.lower() not in known and p.name.lower() not in known]
    return order + extra


def dataset_row(name: str, settings: TableSettings,
                progress: Callable[[str], None] | None = None) -> dict:
    """Every Table I-IV quantity for one dataset; failures become a status, never an exception."""
    step = progress or (lambda s: None)
    row: dict = {"dataset": name, "status": "ok"}
    try:
        path = datasets.resolve(name, settings.data_dir)
    except DatasetNotFound as exc:
        row.update(status="not found", hint=f"posecrb datasets fetch {shlex.quote(name)}", error=str(exc))
        return row
    except PosecrbError as exc:   # e.g. a directory or a device given as the dataset
        row.update(status=status_of(exc), error=str(exc))
        log.error("%s", exc)
        return row
    try:
        step("parse")
        graph, t_parse = timed(lambda: load(path), 1)
        if os.sep in name:  # a path: name the row after the file
            row["dataset"] = graph.name
        row.update(path=str(path), sha256=graph.sha256, dim=graph.dim,
                   poses=graph.n, edges=graph.m)
        m = evaluate(graph, EvaluationSettings(rotation_weight=settings.rotation_weight,
                                               fim_variant=settings.fim_variant, repeat=settings.repeat,
                                               solver=settings.solver, ordering=settings.ordering),
                     step=step, errors="keep")
        res = m.result
        b = res.bounds
        row.update(lb=b.lb)
        put(row, "ub", b.ub, b.ub_status)
        row.update(ub_lambda=b.ub_lambda, lb_time=b.times["lb"], ub_time=b.times["ub"],
                   ub_lambda_time=b.times["ub_lambda"], laplacians_build_time=b.times["laplacians"])
        runs = {"parse_time": 1, "lb_time": b.runs["lb"], "ub_time": b.runs["ub"],
                "ub_lambda_time": b.runs["ub_lambda"], "laplacians_build_time": b.runs["laplacians"]}
        est = m.estimate
        if est is not None:
            # a certified estimate of an inexact relaxation: the objective's status says so
            put(row, "objective", est.objective, est.objective_status)
            log_status(log, f"{name}: estimate duality gap", est.objective_status)
            row.update(certified=est.certified, solve_time=est.solve_time)
            runs["solve_time"] = 1
        row["runs"] = runs
        if m.error is not None:
            raise m.error       # reported below, with what was computed before it
        fim = res.fim
        if est is None or fim is None:
            raise InternalError("evaluate() returned no FIM and no error")
        ld = fim.logdet
        put(row, "fim_logdet", ld, fim.logdet_status)
        if not fim.logdet_status.ok:
            log.warning("%s: %s", name, fim.logdet_status.message("FIM log-det"))
        row.update(fim_variant=fim.variant, rotation_weight=settings.rotation_weight,
                   fim_time=res.times["fim_logdet"], fim_build_time=res.times["fim_build"])
        row.update(gap_ub_rel=None if b.ub is None else (b.ub - b.lb) / b.lb,
                   gap_fim_rel=(ld - b.lb) / b.lb if ld is not None and fim.logdet_status.available else None,
                   parse_time=t_parse, ordering={k: v for k, v in res.ordering.items() if k != "requested"})
        runs.update(fim_time=res.runs["fim_logdet"], fim_build_time=res.runs["fim_build"])
        if not est.certified:
            row["status"] = "uncertified"
    except PosecrbError as exc:
        row.update(status=status_of(exc), error=str(exc))
        log.error("%s: %s", name, exc)
    return row


def _run_one(args):  # top level: picklable for the process pool
    name, settings = args
    return dataset_row(name, settings)


def _dataset_task(context: tuple[str, TableSettings], task: object) -> dict:
    """One dataset as a Monte Carlo engine task (posecrb.sim.montecarlo; run single-threaded there)."""
    name, settings = context
    row = dataset_row(name, settings)
    row["timing"] = "single-threaded task"
    return row




def build_rows(names: Sequence[str], settings: TableSettings, jobs: int = 1,
               on_done: Callable[[str, dict], None] | None = None,
               on_step: Callable[[str, str], None] | None = None, *, executor: str = "local",
               scheduler: str | None = None, client: Any = None) -> list[dict]:
    """Rows in the order of ``names``; with jobs > 1 datasets run in a process pool whose workers
    run every BLAS/OpenMP pool at one thread (timings then include contention for the machine's
    cores: use --jobs 1 for timing).

    ``executor="dask"``: one dataset per task on a Dask cluster through the Monte Carlo engine
    (posecrb.sim.montecarlo): the cluster at ``scheduler`` (or the given ``client``), otherwise a
    LocalCluster of ``jobs`` worker processes. Each task runs with BLAS/OpenMP limited to one
    thread, so its timings are single-threaded (rows carry ``timing``); the workers need posecrb
    and the datasets at the same paths (give ``data_dir`` / paths valid on the workers)."""
    if executor not in EXECUTORS:
        raise UsageError(f"executor must be one of {EXECUTORS}, got {executor!r}")
    if scheduler and executor != "dask":
        raise UsageError("--scheduler needs --executor dask")
    if executor == "dask":
        tasks = [Task(k, 0, np.random.SeedSequence(0)) for k in range(len(names))]
        dask_rows: list = [None] * len(names)

        def collect(done: Iterable[tuple[int, dict]]) -> None:
            for pos, row in done:
                dask_rows[pos] = row
                if on_done:
                    on_done(names[pos], row)

        if names:
            run_dask(_dataset_task, [(n, settings) for n in names], task_chunks(tasks, 1), jobs, scheduler, client,
                      collect, dask_rows)
        return dask_rows
    if jobs <= 1:
        rows = []
        for n in names:
            rows.append(dataset_row(n, settings, partial(on_step, n) if on_step else None))
            if on_done:
                on_done(n, rows[-1])
        return rows

    out: dict[str, dict] = {}
    from ..linalg.threads import single_threaded_worker  # noqa: PLC0415 -- threadpoolctl only for pools

    with ProcessPoolExecutor(max_workers=jobs, initializer=single_threaded_worker) as pool:
        futures = {pool.submit(_run_one, (n, settings)): n for n in names}

        for fut in as_completed(futures):
            n = futures[fut]
            out[n] = fut.result()
            if on_done:
                on_done(n, out[n])
    return [out[n] for n in names]


# ---- views -------------------------------------------------------------------------
MAIN_COLUMNS = ["dataset", "poses", "edges", "fim_logdet", "fim_time", "ub", "ub_time", "lb", "lb_time",
                "ub_lambda", "gap_ub_rel", "gap_fim_rel", "objective", "solve_time", "fim_variant", "status"]
BUILD_COLUMNS = ["dataset", "fim_build_time", "laplacians_build_time", "build_ratio", "status"]
HEADERS = {
    "poses": "# Poses", "edges": "# Meas.", "fim_logdet": "FIM logdet", "fim_time": "FIM t [s]",
    "ub": "ub", "ub_time": "ub t [s]", "lb": "lb", "lb_time": "lb t [s]", "ub_lambda": "ub (λ∞)",
    "gap_ub_rel": "(ub-lb)/lb", "gap_fim_rel": "(FIM-lb)/lb", "objective": "objective F*",
    "solve_time": "solve t [s]", "fim_build_time": "whole FIM [s]",
    "laplacians_build_time": "weighted Laplacians [s]", "build_ratio": "FIM/Lapl.",
    "paper_name": "paper name", "fim_variant": "FIM variant",
}
for _c, _h in (("fim_logdet", "FIM"), ("ub", "ub"), ("lb", "lb"), ("fim_build_time", "whole FIM"),
               ("laplacians_build_time", "Laplacians")):
    HEADERS[f"paper_{_c}"] = f"paper {_h}"
    HEADERS[f"rel_diff_{_c}"] = f"Δrel {_h}"
TITLES = {1: "Table I: metric results, 2D datasets", 2: "Table II: metric results, 3D datasets",
          3: "Table III: matrix construction time, 2D datasets",
          4: "Table IV: matrix construction time, 3D datasets"}
COMPARED = {1: ["fim_logdet", "ub", "lb"], 2: ["fim_logdet", "ub", "lb"],
            3: ["fim_build_time", "laplacians_build_time"], 4: ["fim_build_time", "laplacians_build_time"]}


def table_rows(rows: Iterable[dict], table: int, compare_paper: bool = False) -> tuple[list[dict], list[str]]:
    """(rows, columns) of Table 1-4; 2D rows go to I/III, 3D rows to II/IV, missing ones to both."""
    dim = 2 if table in (1, 3) else 3
    cols = list(MAIN_COLUMNS if table in (1, 2) else BUILD_COLUMNS)
    out = []
    for r in rows:
        if r.get("dim", dim) != dim:
            continue
        if r.get("dim") is None and not _belongs_missing(r["dataset"], dim):
            continue
        v = {c: r.get(c) for c in cols}
        v.update({f"{c}_status": r[f"{c}_status"] for c in cols if f"{c}_status" in r})
        if table in (3, 4) and r.get("fim_build_time") and r.get("laplacians_build_time"):
            v["build_ratio"] = r["fim_build_time"] / r["laplacians_build_time"]
        if compare_paper:
            p = paper_row(r["dataset"]) or {}
            v["paper_name"] = p.get("paper_name")
            for c in COMPARED[table]:
                pv = p.get(c)
                v[f"paper_{c}"] = pv
                v[f"rel_diff_{c}"] = (r[c] - pv) / abs(pv) if pv and r.get(c) is not None else None
        out.append(v)
    if compare_paper:
        extra = ["paper_name"] + [x for c in COMPARED[table] for x in (f"paper_{c}", f"rel_diff_{c}")]
        cols = cols[:-1] + extra + cols[-1:]
    return out, cols


def _belongs_missing(name: str, dim: int) -> bool:
    try:

        entry = load_manifest().find(name)
    except Exception:
        return True
    return entry is None or entry.dim == dim


def footnote(table: int, rotation_weight: str, fim_variant: str = "consistent") -> str | None:
    """The note printed once, under Table II: how its numbers relate to the printed table."""
    if table != 2:
        return None
    if rotation_weight == "table2" and fim_variant == "eq64":
        return TABLE_II_PUBLISHED_FOOTNOTE
    if rotation_weight == "table2":
        return TABLE_II_FIT_FOOTNOTE.format(variant="model's (consistent)" if fim_variant == "consistent"
                                            else "eq. (64) as printed")
    return TABLE_II_FOOTNOTE


def failed(rows: Iterable[dict], requested: Sequence[str] | None) -> list[dict]:
    """Rows that make the command exit 1."""
    asked = {n.lower() for n in requested or []}
    return [r for r in rows if r["status"] in FAILED_STATUSES
            or (r["status"] == "not found" and r["dataset"].lower() in asked)]


# ---- reproducibility record ------------------------------------------------------------
def tables_run_record(settings: TableSettings, rows: list[dict], argv: Sequence[str] | None = None) -> dict:
    """The run record of ``tables --out`` (``posecrb.core.provenance.run_record``, one schema for
    every run.json): versions, machine, settings, the solver's seed and every dataset's sha256."""
    statuses: dict[str, int] = {}
    for r in rows:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    return provenance.run_record(
        "tables", settings=asdict(settings),
        seeds={"solver": settings.solver.get("seed", "default (deterministic)")},
        datasets={r["dataset"]: provenance.dataset_entry(r.get("path"), r.get("sha256"), r["status"]) for r in rows},
        results={"rows": len(rows), "statuses": statuses}, argv=argv)
