"""`posecrb regress`: the CI subset holds, and drift or a changed input is caught."""
import hashlib
import json

import pytest

from posecrb.cli import main
from posecrb.core.errors import PosecrbError
from posecrb.evaluation.regress import compare, default_expected_path, load_expected

# The CI subset (well under the 3-minute budget); `make regress` runs every dataset.
CI_SUBSET = ["CSAIL", "intel", "MIT", "kitti_05", "tinyGrid3D", "smallGrid3D"]


def test_expected_file_covers_the_ci_subset():
    stored = load_expected()["datasets"]
    assert set(CI_SUBSET) <= set(stored)
    for name in CI_SUBSET:
        assert {"sha256", "lb", "ub", "ub_lambda", "fim_logdet", "objective", "trace_crlb"} <= set(stored[name])
        assert stored[name]["fim_variant"] == "consistent"   # the default FIM: the model's


def test_ci_subset_has_no_drift(shared_datasets, capfd):
    assert main(["regress", *(a for name in CI_SUBSET for a in ("--datasets", name))]) == 0


@pytest.mark.parametrize("fmt", ["json", "csv", "markdown"])
def test_no_drift_still_prints_machine_readable_output(shared_datasets, capfd, fmt):
    """With nothing drifted, a pipe still gets a parseable result: [] or the header, never nothing."""
    assert main(["regress", "--datasets", "tinyGrid3D", "--format", fmt]) == 0
    out, err = capfd.readouterr()
    if fmt == "json":
        assert json.loads(out) == []
    else:
        header = out.splitlines()[0].replace("\\", "")
        assert all(col in header for col in ("dataset", "quantity", "expected", "got", "rel_diff", "ok"))
    assert "values within tolerance" in err


@pytest.mark.parametrize("quantity,factor", [("lb", 1 + 1e-8), ("objective", 1 + 1e-5)])
def test_perturbed_expected_value_is_caught(shared_datasets, capfd, tmp_path, quantity, factor):
    data = load_expected()
    data["datasets"] = {"CSAIL": dict(data["datasets"]["CSAIL"])}
    data["datasets"]["CSAIL"][quantity] *= factor
    f = tmp_path / "expected.json"
    f.write_text(json.dumps(data))
    rc = main(["regress", "--expected", str(f), "--format", "json"])
    out, err = capfd.readouterr()
    assert rc == 1
    rows = json.loads(out)
    assert [r["quantity"] for r in rows] == [quantity]
    assert f"CSAIL.{quantity}" in err


def test_changed_input_checksum_is_reported():
    diffs = compare("x", {"sha256": "aa", "lb": 1.0}, {"sha256": "bb", "lb": 1.0})
    assert len(diffs) == 1 and diffs[0].quantity == "sha256" and not diffs[0].ok


def test_tolerances():
    ok = compare("x", {"lb": 100.0, "objective": 10.0}, {"lb": 100.0 * (1 + 5e-10), "objective": 10.0 * (1 + 5e-7)})
    assert all(d.ok for d in ok)
    bad = compare("x", {"lb": 100.0}, {"lb": 100.0 * (1 + 2e-9)})
    assert not bad[0].ok


def test_expected_file_checksums_are_the_datasets(shared_datasets, monkeypatch):
    """The default expected file describes the files on the search path: each stored sha256 is the
    hash of the dataset's bytes, computed here, and each stored bound pair is ordered (eq. 75, 77)."""
    from posecrb.datasets.search import resolve

    monkeypatch.setenv("POSECRB_DATA", str(shared_datasets))
    stored = json.loads(default_expected_path().read_text())["datasets"]
    assert stored == load_expected()["datasets"]
    missing = []
    for name, values in stored.items():
        try:
            path = resolve(name)
        except PosecrbError:
            missing.append(name)
            continue
        assert values["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest(), name
        assert values["lb"] <= values["ub"] <= values["ub_lambda"], name
    assert not set(missing) & set(CI_SUBSET)


def test_changed_fim_variant_is_reported_not_compared():
    diffs = compare("x", {"fim_variant": "eq64", "fim_logdet": 1.0}, {"fim_variant": "consistent", "fim_logdet": 2.0})
    assert [(d.quantity, d.ok) for d in diffs] == [("fim_variant", False)]
    same = compare("x", {"fim_variant": "consistent", "fim_logdet": 1.0, "lb": 1.0},
                   {"fim_variant": "consistent", "fim_logdet": 1.0, "lb": 1.0})
    assert all(d.ok for d in same)
    assert {d.quantity: d.fim_variant for d in same} == {"fim_logdet": "consistent", "lb": None}


def test_save_expected_is_atomic_and_leaves_no_temporary(tmp_path):
    from posecrb.evaluation.regress import save_expected

    target = tmp_path / "expected.json"
    target.write_text("{}")
    save_expected({"version": 1, "datasets": {"a": {"lb": 1.0}}}, target)
    assert json.loads(target.read_text())["datasets"]["a"]["lb"] == 1.0
    assert [p.name for p in tmp_path.iterdir()] == ["expected.json"]


def test_trace_crlb_tolerance_follows_the_inverse_accuracy():
    """An ill-conditioned FIM cannot give trace(F^-1) to 1e-6: the tolerance is at least ten times
    the inverse's estimated relative error (cond x eps), and only for trace_crlb."""
    from posecrb.evaluation.regress import compare

    expected = {"trace_crlb": 1.0, "fim_logdet": 1.0}
    drift = 1 + 8e-6
    tight = {d.quantity: d.ok for d in compare("x", expected, {"trace_crlb": drift, "fim_logdet": drift})}
    assert tight == {"trace_crlb": False, "fim_logdet": False}
    loose = {d.quantity: d for d in compare("x", expected, {"trace_crlb": drift, "fim_logdet": drift,
                                                           "trace_crlb_error_bound": 4e-6})}
    assert loose["trace_crlb"].ok and loose["trace_crlb"].tolerance == pytest.approx(4e-5)
    assert not loose["fim_logdet"].ok
