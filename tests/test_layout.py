"""The package layering of docs/design.md#module-map: no module imports from a package listed below it."""
from __future__ import annotations

import ast
from pathlib import Path

import posecrb

ORDER = ["core", "lie", "io", "datasets", "linalg", "models", "solver", "sim", "selection", "incremental",
         "experiments", "metrics", "report", "cli"]
ROOT = Path(posecrb.__file__).resolve().parent


def _imports(path: Path) -> list[tuple[str, int]]:
    """(package under posecrb imported, line) for every import statement in ``path``."""
    module = path.relative_to(ROOT.parent).with_suffix("").parts
    package = list(module[:-1])
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = (package[: len(package) - node.level + 1] + (node.module.split(".") if node.module else [])
                    if node.level else (node.module or "").split("."))
            names = [base] if len(base) > 1 else [base + [a.name] for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name.split(".") for a in node.names]
        else:
            continue
        out += [(n[1], node.lineno) for n in names if n[0] == "posecrb" and len(n) > 1]
    return out


def test_no_module_imports_from_a_package_below_it():
    bad = []
    for package in ORDER:
        for path in sorted((ROOT / package).rglob("*.py")):
            for target, line in _imports(path):
                if target in ORDER and ORDER.index(target) > ORDER.index(package):
                    bad.append(f"{path.relative_to(ROOT.parent)}:{line} imports posecrb.{target}")
    assert bad == []


def test_every_package_is_in_the_order():
    packages = {p.name for p in ROOT.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert packages == set(ORDER) | {"experiments"}
