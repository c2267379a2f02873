"""Regression of metric values against ``datasets/expected.json``.

For each dataset the file stores the input's sha256 and ``lb, ub, ub_lambda``
(graph-only: relative tolerance 1e-9) and ``fim_logdet, objective, trace_crlb``
(at the certified optimum: relative tolerance 1e-6, since they depend on the
solver's stopping point; for ``trace_crlb`` at least ten times the estimated relative error of
the inverse, ``condition x eps`` of the CRLB's accuracy estimate, so that an ill-conditioned FIM
such as w10000's, cond ~1e10, is held to what double precision can deliver), with
``fim_variant``, the FIM they were computed from (the model's
Fisher information, ``"consistent"``, the default of ``posecrb.models.paper.fim.paper_fim``; the same matrix
as eq. 64 in 2D). A changed input file or FIM variant is reported, not compared.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

from ..core.errors import InternalError, ParseError, PosecrbError
from ..core.inputs import read_input
from ..core.outputs import write_text
from ..datasets import search as datasets
from ..io import load
from ..io.lines import decode_utf8
from ..models.paper.crlb import crlb_from_fim
from .evaluate import EvaluationSettings, evaluate

GRAPH_ONLY = ("lb", "ub", "ub_lambda")
ESTIMATE_DEPENDENT = ("fim_logdet", "objective", "trace_crlb")
FIM_DERIVED = ("fim_logdet", "trace_crlb")
INVERSE_MARGIN = 10.0   # trace_crlb: tolerance >= this x the inverse's estimated relative error
TOLERANCES = {**dict.fromkeys(GRAPH_ONLY, 1e-09), **dict.fromkeys(ESTIMATE_DEPENDENT, 1e-06)}


def default_expected_path() -> Path:
    """``datasets/expected.json`` of the repository (a symlink to the package-data copy)."""
    package = Path(__file__).resolve().parents[1]
    repo = package.parent / "datasets" / "expected.json"
    return repo if repo.exists() else package / "data" / "expected.json"


def _in_site_packages(path: Path) -> bool:
    return any(part in ("site-packages", "dist-packages") for part in path.parts)


def checkout_expected_path() -> Path | None:
    """The expected file ``regress --update`` may rewrite without ``--expected``: the checkout's
    ``datasets/expected.json`` (a symlink into the package data of that checkout), or None when
    posecrb runs from an installed package (whose files an update must never change)."""
    root = Path(__file__).resolve().parents[2]
    repo = root / "datasets" / "expected.json"
    if (root / "pyproject.toml").is_file() and os.path.lexists(repo) and not _in_site_packages(root):
        return repo
    return None


def _line_of(text: str, needle: str) -> int | None:
    k = text.find(needle)
    return None if k < 0 else text.count("\n", 0, k) + 1


_NUMBERS = (*TOLERANCES, "trace_crlb_error_bound")


def parse_expected(text: str, path: str = "<expected>") -> dict:
    """An expected file's content, checked: ParseError (file, line where one exists, reason) for
    invalid JSON or anything ``compare`` could not use (a value that is not a finite number, a
    checksum or variant that is not text, a dataset entry that is not an object)."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ParseError(path, exc.lineno, f"invalid JSON ({exc.msg})") from None
    except RecursionError:
        raise ParseError(path, None, "invalid JSON (nested too deeply)") from None
    if not isinstance(data, dict) or not isinstance(data.get("datasets"), dict):
        raise ParseError(path, None, "expected an object with a 'datasets' mapping (dataset name -> values)")
    for name, values in data["datasets"].items():
        where = _line_of(text, json.dumps(name))
        if not isinstance(values, dict):
            raise ParseError(path, where, f"dataset {name!r}: expected an object of values, got "
                                          f"{type(values).__name__}")
        for key in _NUMBERS:
            v = values.get(key)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)):
                raise ParseError(path, where, f"dataset {name!r}: {key} must be a finite number or null, got {v!r}")
        for key in ("sha256", "fim_variant"):
            v = values.get(key)
            if v is not None and not isinstance(v, str):
                raise ParseError(path, where, f"dataset {name!r}: {key} must be text, got {v!r}")
    return data


def load_expected(path: str | os.PathLike | None = None) -> dict:
    """The expected file (default ``default_expected_path()``), read through the input layer
    (regular file, size, gzip) and checked by ``parse_expected``; a missing file is empty."""
    p = Path(path) if path else default_expected_path()
    if not os.path.lexists(p):
        return {"version": 1, "datasets": {}}
    inp = read_input(p)   # a directory, FIFO or device is an error, not a hang
    return parse_expected(decode_utf8(inp.data, str(p)), str(p))


def save_expected(data: dict, path: str | os.PathLike | None = None) -> Path:
    p = Path(path) if path else default_expected_path()
    write_text(p.resolve(), json.dumps(data, indent=2, sort_keys=True) + "\n")   # atomic, through a symlink
    return p


def compute_metrics(name: str, data_dir: str | None = None, variant: str = "consistent") -> dict:
    """The regressed quantities of one dataset, at its certified optimum (FIM ``variant``)."""

    path = datasets.resolve(name, data_dir)
    graph = load(path)
    m = evaluate(graph, EvaluationSettings(fim_variant=variant))
    b, est, fim = m.result.bounds, m.estimate, m.fim
    if est is None or fim is None or m.result.fim is None:
        raise InternalError("evaluate() returned no FIM and no error")
    if not est.certified:
        raise PosecrbError(f"{name}: the solver did not certify its estimate")
    crlb = crlb_from_fim(fim, graph)   # the same FIM, built once
    return {"sha256": graph.sha256, "fim_variant": fim.variant, "lb": b.lb, "ub": b.ub, "ub_lambda": b.ub_lambda,
            "fim_logdet": m.result.fim.logdet, "objective": est.objective,
            "trace_crlb": crlb.trace_crlb,
            "trace_crlb_error_bound": crlb.accuracy.error_bound if crlb.accuracy is not None else 0.0}


@dataclass(frozen=True)
class Diff:
    dataset: str
    quantity: str
    expected: float | str | None
    got: float | str | None
    rel_diff: float | None
    tolerance: float | None
    ok: bool
    fim_variant: str | None = None      # for the FIM-derived quantities (fim_logdet, trace_crlb)


def compare(name: str, expected: dict, got: dict) -> list[Diff]:
    if expected.get("sha256") and got.get("sha256") != expected["sha256"]:
        return [Diff(name, "sha256", expected["sha256"], got.get("sha256"), None, None, False)]
    variant = got.get("fim_variant")
    if expected.get("fim_variant") and expected["fim_variant"] != variant:
        return [Diff(name, "fim_variant", expected["fim_variant"], variant, None, None, False, variant)]
    out = []
    for q, tol in TOLERANCES.items():
        e, g = expected.get(q), got.get(q)
        if q == "trace_crlb":
            tol = max(tol, INVERSE_MARGIN * float(got.get("trace_crlb_error_bound") or 0.0))
        if e is None:
            continue
        rel = abs(g - e) / max(abs(e), 1e-300) if g is not None else None
        out.append(Diff(name, q, e, g, rel, tol, rel is not None and rel <= tol,
                        variant if q in FIM_DERIVED else None))
    return out
