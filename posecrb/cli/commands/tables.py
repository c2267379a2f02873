"""`posecrb tables`: the paper's Tables I-IV on every available dataset."""
from __future__ import annotations

import logging
import sys
from collections.abc import Sequence

import click

from ...core.choices import EXECUTORS, TABLE_FORMATS
from ...core.errors import PosecrbError
from ...core.folders import output_folder
from ...core.outputs import scratch_dir, write_text
from ...core.provenance import write_run_record
from ...evaluation.tables import (
    HEADERS,
    TITLES,
    TableSettings,
    build_rows,
    dataset_names,
    dataset_row,
    failed,
    footnote,
    published_settings,
    table_rows,
    tables_run_record,
)
from ...io import write_g2o
from ...report.latex import to_latex
from ...report.render import to_csv, to_json, to_markdown, to_rich_table
from ...sim.generators import builtin_demo
from ..options import (
    PlainInt,
    data_dir_option,
    format_option,
    make_rotation_weight_option,
    ordering_option,
    repeat_option,
    repeatable_datasets,
)
from ..paths import FIGURE_EXTENSIONS, Command, DatasetArg, OutputDir, OutputFile
from ..progress import progress

log = logging.getLogger("posecrb")
ROMAN = {1: "I", 2: "II", 3: "III", 4: "IV"}
OUT_FILES = [f"table{t}.{ext}" for t in ROMAN for ext in ("md", "csv", "json", "tex")] + \
    ["rows.csv", "rows.json", "run.json"]


def _shown(rows: list[dict], tables: Sequence[int], compare: bool, settings: TableSettings,
           explicit: bool) -> list[tuple[int, list[dict], list[str], str | None]]:
    """(table, rows, columns, note) of every table that has rows; each distinct note only once.

    A table without rows (Tables II/IV when every dataset is 2D) is not printed: said on
    stderr, as a warning when it was asked for with --table."""
    out: list[tuple[int, list[dict], list[str], str | None]] = []
    seen = set()
    for t in tables:
        trs, cols = table_rows(rows, t, compare)
        if not trs:
            (log.warning if explicit else log.info)("%s: no %dD dataset, not printed", TITLES[t].split(":")[0],
                                                     2 if t in (1, 3) else 3)
            continue
        note = footnote(t, settings.rotation_weight, settings.fim_variant)
        out.append((t, trs, cols, note if note not in seen else None))
        seen.add(note)
    return out


def _render(rows: list[dict], tables: Sequence[int], fmt: str, compare: bool, settings: TableSettings,
            explicit: bool = False) -> str:
    parts = []
    if fmt == "json":
        return to_json({"rows": rows, "tables": {ROMAN[t]: table_rows(rows, t, compare)[0] for t in tables}})
    if fmt == "csv":
        return to_csv(rows)
    for t, trs, cols, note in _shown(rows, tables, compare, settings, explicit):
        if fmt == "markdown":
            parts.append(f"### {TITLES[t]}\n\n" + to_markdown(trs, cols, HEADERS) + (f"\n{note}\n" if note else ""))
        elif fmt == "latex":
            parts.append(to_latex(trs, cols, TITLES[t] + (f". {note}" if note else ""), HEADERS))
    return "\n".join(parts)


@click.command("tables", cls=Command)
@click.option("--all", "all_", is_flag=True, help="Every dataset of the manifest and search path (the default).")
@click.option("--table", "tables", type=PlainInt(1, 4), multiple=True,
              help="Which table(s) to print: 1 (2D metrics), 2 (3D metrics), 3/4 (construction times). "
                   "Repeatable; default all four.")
@click.option("--datasets", "names", type=DatasetArg(), multiple=True,
              help="A dataset name or path (repeatable: --datasets intel --datasets CSAIL.g2o); default: "
                   "every dataset of the manifest and search path.")
@repeat_option
@click.option("--jobs", type=PlainInt(1, 64), default=1, show_default=True,
              help="Datasets computed in parallel processes (timings then include core contention).")
@format_option(TABLE_FORMATS)
@click.option("--out", "out_dir", type=OutputDir(OUT_FILES), default=None,
              help="Also write every format and run.json (versions, CPU, sha256, settings) to DIR.")
@click.option("--compare-paper", is_flag=True, help="Add the paper's printed values and relative differences.")
@make_rotation_weight_option(default=None)   # None: not given (--as-published picks table2)
@click.option("--as-published", is_flag=True,
              help="Reproduce the printed Table II: eq. (64) exactly as printed (fim_variant=eq64) with the "
                   "empirical rotation weight table2. Without it the 3D rows are the model's quantities "
                   "(eq. 59, the model's Fisher information). 2D rows are the same either way.")
@click.option("--plot", "plot_path", type=OutputFile(FIGURE_EXTENSIONS), default=None,
              help="Also draw one figure (PNG, SVG or PDF, by the extension): FIM log-det and ub relative to lb per "
                   "dataset, and every time against the paper's printed one.")
@ordering_option
@click.option("--executor", type=click.Choice(EXECUTORS), default="local", show_default=True,
              help="local: in this process (--jobs 1) or a process pool; dask: one dataset per task on "
                   "dask.distributed (pip install 'posecrb[dask]'), each task single-threaded (BLAS/OpenMP "
                   "1 thread), so its timings are single-threaded ones (rows say timing).")
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Dask scheduler address (tcp://host:8786) of an existing cluster (its workers need posecrb "
                   "and the datasets at the same paths); without it a LocalCluster of --jobs workers is started.")
@data_dir_option
def command(all_, tables, names, repeat, jobs, fmt, out_dir, compare_paper, rotation_weight, as_published,
            plot_path, ordering, executor, scheduler, data_dir):
    """Rebuild the paper's Tables I-IV: FIM log-det at the certified optimum, ub and lb with their
    times (I/II) and the construction time of the whole FIM vs the weighted Laplacians (III/IV).

    Beyond the paper: ub_lambda, the relative gaps (ub-lb)/lb and (FIM-lb)/lb, the certified
    objective and the solve time. The 3D rows are the model's quantities (eq. 59 rotation weight,
    the model's Fisher information) and differ from the printed Table II by design;
    --as-published reproduces its FIM and lb columns (eq. 64 as printed, weight 0.5515*kappa^2).
    A dataset that is not found is a row with status `not found` (fetch it with
    `posecrb datasets fetch NAME`); a failed factorization or an uncertified solve is a row
    with that status and makes the command exit 1 after printing everything.
    """
    if all_ and names:
        raise click.UsageError("--all and --datasets are exclusive")
    # --out and --plot were checked before the work, against the inputs (posecrb.cli.paths)
    requested = repeatable_datasets(names, data_dir) or None
    explicit = bool(tables)
    tables = sorted(set(tables)) or [1, 2, 3, 4]
    if as_published:
        if rotation_weight not in (None, "table2"):
            raise click.UsageError("--as-published uses --rotation-weight table2 (the fit to the printed Table II)")
        settings = published_settings(repeat=repeat, data_dir=data_dir, ordering=ordering)
    else:
        settings = TableSettings(repeat=repeat, rotation_weight=rotation_weight or "eq59", data_dir=data_dir,
                                 ordering=ordering)
    if scheduler and executor != "dask":
        raise click.UsageError("--scheduler needs --executor dask")
    todo = dataset_names(requested, data_dir)

    with progress(len(todo), "tables") as advance:

        def on_step(name, step):
            advance(0, description=f"{name}: {step}")

        def on_done(name, row):
            advance(1)

        rows = build_rows(todo, settings, jobs, on_done=on_done, on_step=on_step, executor=executor,
                          scheduler=scheduler)
    if executor == "dask":
        click.echo("note: --executor dask: every time was measured in a single-threaded task (BLAS/OpenMP 1 "
                   "thread); rows carry timing", err=True)

    if not requested and all(r["status"] == "not found" for r in rows):

        demo = builtin_demo()
        tmp = scratch_dir() / "builtin_demo.g2o"
        write_g2o(demo, tmp)
        log.warning("no dataset found on the search path; running on the built-in synthetic graph "
                    "(posecrb.sim.generators.builtin_demo, written to %s)", tmp)
        rows = [dataset_row(str(tmp), settings)]

    if fmt == "table":
        from rich.console import Console  # noqa: PLC0415 -- rich only for table output (start-up time)

        console = Console(width=None if sys.stdout.isatty() else 250)
        for t, trs, cols, note in _shown(rows, tables, compare_paper, settings, explicit):
            console.print(to_rich_table(trs, cols, TITLES[t], HEADERS, caption=note))
    else:
        click.echo(_render(rows, tables, fmt, compare_paper, settings, explicit), nl=False)

    if out_dir:
        with output_folder(out_dir) as out:   # swapped in whole: all of this run or all of the last
            for t in tables:
                trs, cols = table_rows(rows, t, compare_paper)
                stem = out / f"table{t}"
                write_text(stem.with_suffix(".md"), to_markdown(trs, cols, HEADERS))
                write_text(stem.with_suffix(".csv"), to_csv(trs, cols))
                write_text(stem.with_suffix(".json"), to_json(trs))
                write_text(stem.with_suffix(".tex"), to_latex(trs, cols, TITLES[t], HEADERS))
            write_text(out / "rows.csv", to_csv(rows))
            write_text(out / "rows.json", to_json(rows))
            write_run_record(out, tables_run_record(settings, rows, sys.argv))

    if plot_path:
        from ...report.plots import plot_tables  # noqa: PLC0415 -- matplotlib, only for --plot

        try:
            note = f"3D rotation weight: {settings.rotation_weight}, FIM: {settings.fim_variant}"
            log.info("wrote %s", plot_tables(rows, plot_path, note=note))
        except ValueError as exc:
            log.warning("no figure written: %s", exc)

    bad = failed(rows, requested)
    if bad:
        raise PosecrbError(f"{len(bad)} dataset(s) failed: "
                           + ", ".join(f"{r['dataset']} ({r['status']})" for r in bad))
