"""The project files and the package metadata, and a wheel that works outside the checkout."""
from __future__ import annotations

import email
import json
import re
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

import posecrb

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
PROJECT = PYPROJECT["project"]


def test_project_files() -> None:
    license_text = (ROOT / "LICENSE").read_text()
    assert license_text.startswith("MIT License")
    assert "Permission is hereby granted, free of charge" in license_text
    holder = PROJECT["authors"][0]["name"]
    assert re.search(rf"Copyright \(c\) \d{{4}} {re.escape(holder)}", license_text)
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert "## [Unreleased]" in changelog
    assert f"## [{posecrb.__version__}]" in changelog
    assert (ROOT / "CONTRIBUTING.md").is_file()
    assert (ROOT / "posecrb" / "py.typed").is_file()


def test_metadata() -> None:
    assert PROJECT["license"] == "MIT"                       # an SPDX expression, not a table
    assert PROJECT["license-files"] == ["LICENSE"]
    assert PROJECT["authors"] and PROJECT["urls"]
    assert "Typing :: Typed" in PROJECT["classifiers"]
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["posecrb"]
    assert any(r.startswith("setuptools>=77") for r in PYPROJECT["build-system"]["requires"])
    assert PROJECT["version"] == posecrb.__version__


def test_citation_names_posecrb_the_paper_and_the_thesis() -> None:
    text = (ROOT / "CITATION.cff").read_text()
    assert re.search(r"^cff-version: 1\.2\.0$", text, re.M)
    assert re.search(rf"^version: {re.escape(posecrb.__version__)}$", text, re.M)
    assert re.search(r"^license: MIT$", text, re.M)
    assert "title: \"Cramér-Rao bounds and optimal design metrics for pose-graph SLAM\"" in text
    assert "On Intrinsic Cramér–Rao Bounds on the Lie Group SE(d)^n" in text
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load(text)
    assert {r["type"] for r in cff["references"]} >= {"article", "thesis"}
    assert [a["family-names"] for a in cff["references"][0]["authors"]] == [
        "Chen", "Khosoussi", "Huang", "Zhao", "Dissanayake"]


def test_readme_is_a_front_page_that_renders_on_the_package_index() -> None:
    """At most 300 lines; no relative link or image, which the package index cannot resolve; the
    version it cites is this one."""
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 300
    targets = re.findall(r"\]\(([^)\s]+)", readme) + re.findall(r"^\[[^\]]+\]:\s*(\S+)", readme, re.M)
    relative = [t for t in targets if not re.match(r"(https?://|mailto:|#)", t)]
    assert not relative, f"relative links in README.md: {relative}"
    assert f"version = {{{posecrb.__version__}}}" in readme


def _base_interpreter() -> str:
    return getattr(sys, "_base_executable", sys.executable)


@pytest.mark.slow
def test_wheel_installs_in_a_clean_venv_and_runs_outside_the_checkout(tmp_path: Path) -> None:
    """Build the wheel, install it (and its dependencies, from the package index) into a new virtual
    environment without the system's packages, and run `posecrb bounds` from a directory outside
    the checkout."""
    wheels = tmp_path / "wheels"
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(ROOT)],
                           capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr
    (wheel,) = wheels.glob("posecrb-*.whl")
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        meta = email.message_from_bytes(z.read(f"posecrb-{posecrb.__version__}.dist-info/METADATA"))
    assert {"posecrb/py.typed", "posecrb/data/manifest.toml", "posecrb/data/expected.json",
            f"posecrb-{posecrb.__version__}.dist-info/licenses/LICENSE"} <= names
    assert not [n for n in names if n.startswith(("tests/", "benchmarks/", "examples/", "docs/"))]
    assert meta["License-Expression"] == "MIT"
    assert "Typing :: Typed" in meta.get_all("Classifier")

    venv = tmp_path / "venv"
    subprocess.run([_base_interpreter(), "-m", "venv", str(venv)], check=True, timeout=300)
    python, exe = venv / "bin" / "python", venv / "bin" / "posecrb"
    install = subprocess.run([str(python), "-m", "pip", "install", "-q", str(wheel)], cwd=tmp_path,
                             capture_output=True, text=True, timeout=1800)
    assert install.returncode == 0, install.stdout + install.stderr

    work = tmp_path / "work"
    work.mkdir()

    def run(*args: str) -> str:
        proc = subprocess.run([str(exe), *args], cwd=work, capture_output=True, text=True, timeout=600,
                              env={"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "MPLBACKEND": "Agg"})
        assert proc.returncode == 0, f"posecrb {' '.join(args)}: {proc.stdout}{proc.stderr}"
        return proc.stdout

    version = run("--version")
    assert str(venv) in version and str(ROOT) not in version
    run("datasets", "synth", "grid2d", "--poses", "25", "--noise", "0.01", "--seed", "1", "--out", "g.g2o")
    row = json.loads(run("bounds", "g.g2o", "--format", "json"))
    assert row["poses"] == 25 and row["estimate"]["certified"] is True
    assert row["lb"] <= row["fim_logdet"] <= row["ub"]
