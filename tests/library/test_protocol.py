"""The one result protocol (posecrb.core.result), over every public result type: ``to_dict`` is plain
JSON, ``from_dict`` its inverse (also through a JSON text), ``to_frame`` a DataFrame, ``save``/``load``
keep the dict and the big arrays, and a result's status survives each of them."""
from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.sparse as sp

import posecrb
from posecrb.core.result import Result

DATA = Path(__file__).resolve().parents[1] / "data" / "cli_json"
RESULT_TYPES = sorted(n for n in posecrb.__all__ if isinstance(getattr(posecrb, n), type)
                      and issubclass(getattr(posecrb, n), Result))


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> dict[str, Result]:
    """One instance of every public result type, from the library's own calls on small graphs (2D and
    3D), parts included."""
    d = tmp_path_factory.mktemp("protocol")
    for name in ("g2d.g2o", "g3d.g2o"):
        shutil.copy(DATA / name, d)
    g2, g3 = posecrb.load(d / "g2d.g2o"), posecrb.load(d / "g3d.g2o")
    sol = posecrb.solve(g2)
    bounds = posecrb.bounds(g3)
    select = posecrb.select(g2, budget=0.5, certify=True, objective="fim", estimate=sol)
    crlb3 = posecrb.crlb(g3, poses="all")
    line = posecrb.timeline(g3, estimate="vertices", every=2)
    out: dict[str, Result] = {
        "SolveResult": sol, "BoundsResult": bounds, "GraphBounds": bounds.bounds, "FimAtEstimate": bounds.fim,
        "FimResult": posecrb.fim(g3, model="sed", frame="body"), "CrlbResult": crlb3, "InverseAccuracy": crlb3.accuracy,
        "SelectResult": select, "FixedEdges": select.fixed, "SelectionCertificate": select.certificate,
        "CertificateBounds": select.certificate.bounds, "Estimate": posecrb.Estimate(sol.rot, sol.trans),
        "TimelineResult": line, "LoopClosure": line.closures[0], "Monotonicity": line.monotonicity["lb"]["raw"],
    }
    return out


def test_every_public_result_type_is_covered(results):
    assert sorted(results) == RESULT_TYPES
    assert all(type(r).__name__ == name for name, r in results.items())


@pytest.mark.parametrize("name", RESULT_TYPES)
def test_to_dict_is_json_and_from_dict_inverts_it(results, name):
    res = results[name]
    d = res.to_dict()
    text = json.dumps(d, allow_nan=False)                  # plain JSON: no NaN, no numpy values
    for back in (type(res).from_dict(d), type(res).from_dict(json.loads(text))):
        assert type(back) is type(res) and back.to_dict() == d
        assert back.status == res.status and back.statuses() == res.statuses()


@pytest.mark.parametrize("name", RESULT_TYPES)
def test_to_frame_is_a_dataframe(results, name):
    frame = results[name].to_frame()
    assert isinstance(frame, pd.DataFrame) and len(frame) >= 1


@pytest.mark.parametrize("name", RESULT_TYPES)
def test_save_and_load_keep_the_dict_and_the_arrays(results, name, tmp_path):
    res = results[name]
    written = res.save(tmp_path / name)
    assert written == str(tmp_path / name) + ".npz"
    back = type(res).load(written)
    assert back.to_dict() == res.to_dict() and back.status == res.status
    for f in dataclasses.fields(res):
        if f.metadata.get("array") and getattr(res, f.name) is not None:
            a, b = getattr(res, f.name), getattr(back, f.name)
            if sp.issparse(a):
                assert (a != b).nnz == 0
            else:
                np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    other = next(n for n in RESULT_TYPES if n != name)
    with pytest.raises(posecrb.ParseError, match=f"not a {other}"):
        getattr(posecrb, other).load(written)


def test_parts_are_inlined_and_nested_as_the_commands_print_them(results):
    """The parts' keys are the parent's (bounds, the FIM at the estimate, the certificate) or the value
    of one key (fixed edges, the certificate's bounds, the estimate)."""
    b, s = results["BoundsResult"].to_dict(), results["SelectResult"].to_dict()
    assert results["GraphBounds"].to_dict().items() <= b.items()
    assert results["FimAtEstimate"].to_dict().items() <= b.items()
    assert results["SelectionCertificate"].to_dict().items() <= s.items()
    assert s["fixed"] == results["FixedEdges"].to_dict() and s["bounds"] == results["CertificateBounds"].to_dict()
