"""`posecrb regress`: recompute metric values and compare them with datasets/expected.json."""
from __future__ import annotations

import logging
from dataclasses import asdict

import click

from ...core.errors import DatasetNotFound, PosecrbError
from ...evaluation.regress import Diff, compare, compute_metrics, default_expected_path, load_expected, save_expected
from ...io import check_output_file
from ...report.render import print_rows
from ..options import data_dir_option, format_option

log = logging.getLogger("posecrb")


@click.command("regress")
@click.option("--datasets", "names", default=None,
              help="Comma-separated dataset names (default: every dataset in the expected file).")
@click.option("--update", is_flag=True, help="Write the recomputed values into the expected file.")
@click.option("--expected", "expected_path", type=click.Path(dir_okay=False), default=None,
              help="Expected-values file (default: datasets/expected.json).")
@click.option("--all-rows", is_flag=True, help="Show every compared value, not only drifts.")
@data_dir_option
@format_option()
def command(names, update, expected_path, all_rows, data_dir, fmt):
    """Recompute lb, ub, ub_lambda (tolerance 1e-9 relative) and fim_logdet, objective, trace_crlb
    at the certified optimum (1e-6; from the model's Fisher information, fim_variant=consistent,
    recorded in the file) and compare them with the expected file. Exits 1 on any drift, changed
    FIM variant or changed input checksum. A dataset not found is skipped with a warning unless it
    was named with --datasets."""
    if update:   # the file is rewritten at the end (atomically): check that it can be, first

        check_output_file(expected_path or default_expected_path().resolve(), option="--expected")
    data = load_expected(expected_path)
    stored = data["datasets"]
    requested = [n.strip() for n in names.split(",") if n.strip()] if names else None
    todo = requested or sorted(stored)
    if not todo:
        raise click.UsageError("nothing to compare: the expected file is empty; name datasets and use --update")
    diffs: list[Diff] = []
    missing: list[str] = []
    for name in todo:
        try:
            got = compute_metrics(name, data_dir)
        except DatasetNotFound as exc:
            (missing if requested else []).append(name)
            log.warning("%s", exc)
            continue
        if update:
            stored[name] = got
            continue
        if name not in stored:
            raise PosecrbError(f"{name}: no expected values; run `posecrb regress --update --datasets {name}`")
        diffs += compare(name, stored[name], got)
    if update:
        click.echo(f"updated {save_expected(data, expected_path)} ({len(todo) - len(missing)} dataset(s))")
    else:
        bad = [d for d in diffs if not d.ok]
        rows = [asdict(d) for d in (diffs if all_rows else bad)]
        if rows:
            print_rows(rows, fmt, title="regression: recomputed vs expected", single_json=False)
        click.echo(f"{len(diffs) - len(bad)} of {len(diffs)} values within tolerance "
                   f"({len({d.dataset for d in diffs})} dataset(s))", err=True)
        if bad:
            raise PosecrbError(f"{len(bad)} value(s) drifted: " +
                               ", ".join(f"{d.dataset}.{d.quantity}" for d in bad[:8]))
    if missing:
        raise PosecrbError(f"not found: {', '.join(missing)}")
