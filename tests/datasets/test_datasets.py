"""Manifest and search path: checksums and counts against the real files, aliases, list/verify/path."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from posecrb.cli import main
from posecrb.datasets import search as ds
from posecrb.datasets import verify as dsv
from posecrb.datasets.manifest import (
    ManifestError,
    default_manifest_path,
    git_blob_file,
    load_manifest,
    parse_manifest,
    sha256_file,
)
from posecrb.io import load

REPO = Path(__file__).resolve().parents[2]
SE_SYNC_COMMIT = "9b631b6b82d8aa7d32ab846412ae1c070412b7b6"

# Typed in from the paper (seeds/000, Tables I and II): name, #poses, #measurements, in table order.
PAPER_TABLE_1 = [("CSAIL", 1045, 1172), ("Intel", 1728, 2512), ("manhattan", 3500, 5453),
                 ("KITTI", 4541, 4677), ("city10000", 10000, 20687), ("ais2klinik", 15115, 16727)]
PAPER_TABLE_2 = [("tiny-grid", 9, 11), ("small-grid", 125, 297), ("garage", 1661, 6275),
                 ("sphere", 2500, 4949), ("torus", 5000, 9048), ("cubicle", 5750, 16869),
                 ("grid", 8000, 22236), ("rim", 10195, 29743)]
# Typed in from the datasets' SOURCES.md: EDGE line counts of every shared file.
SOURCES_EDGES = {
    "CSAIL.g2o": 1172, "MIT.g2o": 827, "intel.g2o": 2512, "manhattan.g2o": 5453, "kitti_00.g2o": 4677,
    "kitti_02.g2o": 4703, "kitti_05.g2o": 2826, "city10000.g2o": 20687, "ais2klinik.g2o": 16727,
    "tinyGrid3D.g2o": 11, "smallGrid3D.g2o": 297, "parking-garage.g2o": 6275, "sphere2500.g2o": 4949,
    "sphere_bignoise_vertex3.g2o": 8647, "torus3D.g2o": 9048, "cubicle.g2o": 16869,
    "w10000.graph": 64311, "sphere_smallnoise.graph": 8647, "sphere_bignoise.graph": 8647,
    "w100.graph": 300, "csail.toro": 1172,
}
SOURCES_BLOBS = {"grid3D": "0dee46a9e43e1f51b9d4466ac6119e5bb6966954",
                 "rim": "0c2f783b9d71012a612f09673f5aed87ae65f954"}


def shared_files(root: Path) -> list[Path]:
    return sorted(root.glob("*.g2o")) + sorted(p for p in (root / "toro").iterdir() if p.is_file())


# ---- the manifest against the real files --------------------------------------------

def test_every_shared_file_is_in_the_manifest_with_its_sha256(shared_datasets):
    man = load_manifest()
    files = shared_files(shared_datasets)
    assert len(files) == 21
    for f in files:
        entry = man.find(f.name)
        assert entry is not None and entry.file == f.name, f
        assert entry.sha256 == hashlib.sha256(f.read_bytes()).hexdigest(), f
        assert entry.size == f.stat().st_size
        assert entry.relpath == (f"toro/{f.name}" if f.parent.name == "toro" else f.name)


def test_git_blob_ids_match_git_hash_object(shared_datasets, tmp_path):
    if shutil.which("git") is None:
        pytest.skip("git not installed")
    man = load_manifest()
    files = shared_files(shared_datasets)
    out = subprocess.run(["git", "hash-object", "--no-filters", *map(str, files)], capture_output=True,
                         text=True, check=True).stdout.split()
    for f, blob in zip(files, out):
        assert man.find(f.name).git_blob == blob
        assert git_blob_file(f) == blob
    odd = tmp_path / "odd.bin"
    odd.write_bytes(b"\0blob 3\n\xff" * 1000)
    ref = subprocess.run(["git", "hash-object", "--no-filters", str(odd)], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert git_blob_file(odd) == ref


@pytest.mark.slow
def test_counts_match_the_parsed_files_and_sources_md(shared_datasets):
    man = load_manifest()
    for f in shared_files(shared_datasets):
        entry = man.find(f.name)
        g = load(f)
        assert (g.n, g.m, g.dim, g.format) == (entry.poses, entry.edges, entry.dim, entry.format), f
        assert entry.edges == SOURCES_EDGES[f.name]
        assert entry.has_vertices == g.has_vertices


def test_paper_tables_membership_order_and_counts():
    man = load_manifest()
    for table, expected in ((1, PAPER_TABLE_1), (2, PAPER_TABLE_2)):
        got = [(e.paper_name, e.poses, e.edges) for e in man.paper(table)]
        assert got == expected
        assert all(e.dim == table + 1 for e in man.paper(table))
    assert [e.paper_order for e in man.paper(2)] == list(range(1, 9))
    assert man.get("KITTI").file == "kitti_00.g2o" and man.get("garage").file == "parking-garage.g2o"
    assert len(man) == 23


def test_grid3d_and_rim_are_verified_by_git_blob():
    man = load_manifest()
    for name, blob in SOURCES_BLOBS.items():
        e = man.get(name)
        assert e.sha256 is None and e.git_blob == blob and e.checksum == ("git_blob", blob)
        assert e.url.endswith(f"/{SE_SYNC_COMMIT}/data/{name}.g2o")


def test_urls_are_https_at_pinned_commits():
    for e in load_manifest():
        assert e.url.startswith("https://raw.githubusercontent.com/")
        assert e.commit and f"/{e.commit}/" in e.url and e.url.endswith(e.file)
        if e.format == "g2o":
            assert e.url == f"https://raw.githubusercontent.com/david-m-rosen/SE-Sync/{SE_SYNC_COMMIT}/data/{e.file}"


def test_repo_manifest_is_the_package_manifest():
    repo_file = REPO / "datasets" / "manifest.toml"
    assert repo_file.is_symlink() and not os.path.isabs(os.readlink(repo_file))
    assert repo_file.resolve() == default_manifest_path().resolve()


@pytest.mark.parametrize("patch, message", [
    (('url = "https://', 'url = "http://'), "https"),
    (('sha256 = "', 'sha_256 = "'), "unknown field"),
    (("dim = 2", "dim = 4"), "dim"),
])
def test_malformed_manifest_is_rejected(patch, message):
    text = default_manifest_path().read_text().replace(*patch, 1)
    with pytest.raises(ManifestError, match=message):
        parse_manifest(text, "m.toml")


def test_entry_needs_a_checksum():
    text = '[[dataset]]\nname="a"\nfile="a.g2o"\nformat="g2o"\ndim=2\nposes=1\nedges=1\nurl="https://x/a.g2o"\n'
    with pytest.raises(ManifestError, match="sha256 or git_blob"):
        parse_manifest(text)


# ---- search path, aliases, status ------------------------------------------------------

def test_resolve_keeps_file_lookup_and_adds_manifest_aliases(shared_datasets, isolated_cache):
    assert ds.resolve("csail", shared_datasets).name == "CSAIL.g2o"
    assert ds.resolve("csail-toro", shared_datasets) == shared_datasets / "toro" / "csail.toro"
    assert ds.resolve("garage", shared_datasets).name == "parking-garage.g2o"
    assert ds.resolve("KITTI", shared_datasets).name == "kitti_00.g2o"
    with pytest.raises(ds.DatasetNotFound, match="datasets fetch grid3D"):
        ds.resolve("grid", shared_datasets)


def _corrupt_copy(src: Path, dst_dir: Path) -> Path:
    dst_dir.mkdir(parents=True, exist_ok=True)
    data = bytearray(src.read_bytes())
    data[-2] = ord("7") if data[-2] != ord("7") else ord("8")
    out = dst_dir / src.name
    out.write_bytes(bytes(data))
    return out


def test_list_reports_found_missing_and_mismatch(shared_datasets, tmp_path, isolated_cache):
    bad = _corrupt_copy(shared_datasets / "tinyGrid3D.g2o", tmp_path / "data")
    shutil.copy(shared_datasets / "intel.g2o", tmp_path / "data")
    status = {s.entry.name: s for s in dsv.list_datasets(tmp_path / "data")}
    assert status["tinyGrid3D"].status == "checksum mismatch" and status["tinyGrid3D"].path == bad
    assert status["intel"].status == "found"
    assert status["grid3D"].status == "missing" and status["grid3D"].path is None
    assert status["rim"].status == "missing"


def test_verify_files_flags_a_mismatch_and_unknown_files(shared_datasets, tmp_path, isolated_cache, monkeypatch):
    monkeypatch.setenv("POSECRB_DATA", str(shared_datasets))   # the real files, after --data-dir
    data = tmp_path / "data"
    _corrupt_copy(shared_datasets / "tinyGrid3D.g2o", data)
    shutil.copy(shared_datasets / "tinyGrid3D.g2o", data / "mine.g2o")
    checks = {c.path.resolve(): c for c in dsv.verify_files(data)}
    assert checks[(data / "tinyGrid3D.g2o").resolve()].status == "checksum mismatch"
    assert checks[(data / "mine.g2o").resolve()].status == "unknown"
    assert checks[(shared_datasets / "tinyGrid3D.g2o").resolve()].status == "ok"
    assert sum(c.failed for c in checks.values()) == 1


def test_verify_parse_compares_counts(shared_datasets, tmp_path):
    checks = dsv.verify_files(parse=True, files=[shared_datasets / "tinyGrid3D.g2o",
                                                shared_datasets / "toro" / "w100.graph"])
    assert [(c.status, c.poses, c.edges) for c in checks] == [("ok", 9, 11), ("ok", 100, 300)]
    # Same bytes under another entry's file name: the checksum catches it before the counts.
    shutil.copy(shared_datasets / "tinyGrid3D.g2o", tmp_path / "smallGrid3D.g2o")
    (c,) = dsv.verify_files(parse=True, files=[tmp_path / "smallGrid3D.g2o"])
    assert c.status == "checksum mismatch" and c.failed


# ---- CLI ------------------------------------------------------------------------------

def test_cli_list_json_and_csv(shared_datasets, isolated_cache, capsys):
    assert main(["datasets", "list", "--data-dir", str(shared_datasets), "--format", "json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    by = {r["name"]: r for r in rows}
    assert by["CSAIL"]["status"] == "found" and by["CSAIL"]["table"] == "I" and by["CSAIL"]["poses"] == 1045
    assert by["rim"]["status"] == "missing" and by["rim"]["path"] is None
    assert main(["datasets", "list", "--format", "csv", "--no-check"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "name,dim,poses,edges,table,paper_name,status,path" and len(lines) == 24


def test_cli_verify_exit_codes(shared_datasets, tmp_path, isolated_cache, capsys):
    assert main(["datasets", "verify", "--data-dir", str(shared_datasets), "--format", "csv"]) == 0
    _corrupt_copy(shared_datasets / "toro" / "w100.graph", tmp_path / "data")
    assert main(["datasets", "verify", "--data-dir", str(tmp_path / "data")]) == 1
    err = capsys.readouterr().err
    assert "do not match the manifest" in err and "w100.graph" in err


def test_cli_path(shared_datasets, isolated_cache, capsys):
    assert main(["datasets", "path", "sphere", "--data-dir", str(shared_datasets)]) == 0
    assert Path(capsys.readouterr().out.strip()) == (shared_datasets / "sphere2500.g2o").resolve()
    assert main(["datasets", "path", "rim", "--data-dir", str(shared_datasets)]) == 1
    assert "posecrb datasets fetch rim" in capsys.readouterr().err


def test_sha256_file_streams_large_files(tmp_path):
    f = tmp_path / "big.bin"
    data = os.urandom(3 * (1 << 20) + 17)
    f.write_bytes(data)
    assert sha256_file(f) == hashlib.sha256(data).hexdigest()
