"""The one result protocol (posecrb.core.result), over every public result type: ``to_dict`` is plain
JSON, ``from_dict`` its inverse (also through a JSON text), ``to_frame`` a DataFrame, ``save``/``load``
keep the dict and the big arrays, and a result's status survives each of them."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.sparse as sp

import posecrb

from ..helpers import PUBLIC_RESULT_TYPES as RESULT_TYPES

DATA = Path(__file__).resolve().parents[1] / "data" / "cli_json"

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
