"""`posecrb info FILE`: what a dataset is made of."""
from __future__ import annotations

import click
import numpy as np

from ...core.graph import PoseGraph
from ...report.render import print_rows
from ..options import data_dir_option, format_option, load_dataset
from ..paths import Command, DatasetArg


def graph_info(graph: PoseGraph) -> dict:
    """Summary of a pose graph as a flat-ish dict (JSON-ready)."""
    deg = graph.degree
    pairs = np.sort(np.stack([graph.src, graph.dst], 1), axis=1)
    unique_pairs = np.unique(pairs, axis=0).shape[0]
    return {
        "dataset": graph.name,
        "path": graph.path,
        "sha256": graph.sha256,
        "format": graph.format,
        "dim": graph.dim,
        "poses": graph.n,
        "edges": graph.m,
        "parallel_edges": int(graph.m - unique_pairs),
        "components": graph.n_components,
        "component_sizes": [c.size for c in graph.component_summaries()][:10],
        "has_vertices": graph.has_vertices,
        "id_min": int(graph.ids[0]),
        "id_max": int(graph.ids[-1]),
        "degree_min": int(deg.min()),
        "degree_mean": float(deg.mean()),
        "degree_max": int(deg.max()),
        "tau_min": float(graph.tau.min()),
        "tau_max": float(graph.tau.max()),
        "kappa_min": float(graph.kappa.min()),
        "kappa_max": float(graph.kappa.max()),
        "skipped_lines": dict(graph.skipped),
    }


@click.command("info", cls=Command)
@click.argument("files", nargs=-1, required=True, type=DatasetArg())
@data_dir_option
@format_option()
def command(files: tuple[str, ...], data_dir: str | None, fmt: str) -> None:
    """Describe pose-graph FILE(s): format, dimension, sizes, connectivity, degrees, noise ranges.

    tau is the isotropic translation precision and kappa the Langevin rotation
    concentration derived from each edge's information matrix (SE-Sync's rule).
    """
    rows = [graph_info(load_dataset(f, data_dir)[0]) for f in files]
    if fmt == "table":
        for row in rows:
            kv = [{"field": k, "value": ", ".join(f"{n} {t}" for t, n in v.items()) or "none"
                   if isinstance(v, dict) else v} for k, v in row.items()]
            print_rows(kv, "table", title=row["dataset"])
    else:
        print_rows(rows, fmt)
