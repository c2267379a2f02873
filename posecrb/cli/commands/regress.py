"""`posecrb regress`: recompute metric values and compare them with datasets/expected.json."""
from __future__ import annotations

import logging
import os
import shlex
from dataclasses import asdict, fields

import click

from ...core.errors import DatasetNotFound, PosecrbError, UsageError
from ...core.outputs import check_output_file
from ...evaluation.regress import Diff, checkout_expected_path, compare, compute_metrics, load_expected, save_expected
from ...report.render import print_rows
from ..options import data_dir_option, format_option, repeatable_datasets
from ..paths import Command, DatasetArg, OutputFile

log = logging.getLogger("posecrb")


@click.command("regress", cls=Command)
@click.option("--datasets", "names", type=DatasetArg(), multiple=True,
              help="A dataset name (repeatable; default: every dataset in the expected file).")
@click.option("--update", is_flag=True, help="Write the recomputed values into the expected file.")
@click.option("--expected", "expected_path", type=OutputFile((".json",), only_with="update", rewrites_input=True),
              default=None,
              help="Expected-values file (default: datasets/expected.json of the checkout, or the installed "
                   "package's copy, which --update never changes).")
@click.option("--allow-missing", is_flag=True,
              help="A dataset of the expected file that is not found is skipped with a warning instead of "
                   "failing the run.")
@click.option("--all-rows", is_flag=True, help="Show every compared value, not only drifts.")
@data_dir_option
@format_option()
def command(names, update, expected_path, allow_missing, all_rows, data_dir, fmt):
    """Recompute lb, ub, ub_lambda (tolerance 1e-9 relative) and fim_logdet, objective, trace_crlb
    at the certified optimum (1e-6; from the model's Fisher information, fim_variant=consistent,
    recorded in the file) and compare them with the expected file.

    Exits 1 on any drift, changed FIM variant or changed input checksum, when nothing was compared
    (a regression run that checked nothing must not pass), and when a dataset is not found: named
    with --datasets always, one of the expected file unless --allow-missing."""
    if update and expected_path is None:
        target = checkout_expected_path()
        if target is None:
            raise UsageError("--update without --expected rewrites a checkout's datasets/expected.json; this "
                             "posecrb is an installed package, whose files are never changed: pass "
                             "--expected FILE (a copy of the expected file to update)")
        # the file is rewritten at the end (atomically): check that it can be, before the work
        check_output_file(target.resolve(), option="--expected", extensions=(".json",))
        expected_path = str(target)
    if expected_path is not None and not update and not os.path.lexists(expected_path):
        raise UsageError(f"--expected {expected_path}: no such file (give an existing expected file, or "
                         "--update to create it)")
    data = load_expected(expected_path)
    stored = data["datasets"]
    requested = repeatable_datasets(names, data_dir) or None
    todo = requested or sorted(stored)
    if not todo:
        raise PosecrbError("nothing to compare: the expected file has no dataset; name datasets with "
                           "--datasets NAME and use --update to record them")
    diffs: list[Diff] = []
    missing: list[str] = []
    skipped: list[str] = []
    computed = 0
    for name in todo:
        try:
            got = compute_metrics(name, data_dir)
        except DatasetNotFound as exc:
            (skipped if allow_missing and not requested else missing).append(name)
            log.warning("%s", exc)
            continue
        computed += 1
        if update:
            stored[name] = got
            continue
        if name not in stored:
            raise PosecrbError(f"{name}: no expected values; run "
                               f"`posecrb regress --update --datasets {shlex.quote(name)}`")
        diffs += compare(name, stored[name], got)
    if update:
        if computed:
            click.echo(f"updated {save_expected(data, expected_path)} ({computed} dataset(s))")
    else:
        bad = [d for d in diffs if not d.ok]
        rows = [asdict(d) for d in (diffs if all_rows else bad)]
        if rows or fmt != "table":
            # machine-readable output even when nothing drifted: [] in JSON, the header in CSV/Markdown
            print_rows(rows, fmt, columns=None if fmt in ("json", "table") else [f.name for f in fields(Diff)],
                       title="regression: recomputed vs expected", single_json=False)
        click.echo(f"{len(diffs) - len(bad)} of {len(diffs)} values within tolerance "
                   f"({len({d.dataset for d in diffs})} dataset(s))", err=True)
        if bad:
            raise PosecrbError(f"{len(bad)} value(s) drifted: " +
                               ", ".join(f"{d.dataset}.{d.quantity}" for d in bad[:8]))
    if skipped:
        log.warning("--allow-missing: %d dataset(s) of the expected file not found, not compared: %s",
                    len(skipped), ", ".join(skipped))
    if missing:
        hint = "" if requested else " (--allow-missing skips datasets of the expected file that are not found)"
        raise PosecrbError(f"not found: {', '.join(missing)}{hint}")
    if not computed:
        raise PosecrbError(f"nothing was {'updated' if update else 'compared'}: none of the datasets was found on "
                           "the search path; a regression run that checked nothing does not pass (set --data-dir "
                           "or $POSECRB_DATA)")
