"""The package layering of docs/design.md#module-map: no module imports from a package listed below it,
nor the package root (which imports the library on first use); no import cycles; file sizes."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import posecrb

# Bottom to top. ``_version`` is the ground floor (it imports nothing); the package root
# (``posecrb/__init__.py``) is above everything: it imports the public names from ``api`` and the
# result modules, so a module that imports it (``from .. import __version__``) imports upwards.
ORDER = ["_version", "core", "lie", "io", "datasets", "linalg", "solver", "models", "sim", "selection", "incremental",
         "verification", "experiments", "evaluation", "report", "api", "cli"]
PACKAGE_ROOT = "posecrb (the package root)"
ROOT = Path(posecrb.__file__).resolve().parent


def _imports(path: Path) -> list[tuple[str, int]]:
    """(layer imported, line) for every posecrb import statement in ``path``: the subpackage or
    ``_version`` it reaches, or ``PACKAGE_ROOT`` for the root package itself (``import posecrb``,
    ``from posecrb import load``, ``from .. import __version__``)."""
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
        out += [(n[1] if len(n) > 1 and n[1] in ORDER else PACKAGE_ROOT, node.lineno)
                for n in names if n[0] == "posecrb"]
    return out


def _modules(layer: str) -> list[Path]:
    return [ROOT / f"{layer}.py"] if (ROOT / f"{layer}.py").is_file() else sorted((ROOT / layer).rglob("*.py"))


def test_no_module_imports_from_a_package_below_it():
    bad = []
    for layer in ORDER:
        for path in _modules(layer):
            for target, line in _imports(path):
                if target == PACKAGE_ROOT or ORDER.index(target) > ORDER.index(layer):
                    bad.append(f"{path.relative_to(ROOT.parent)}:{line} imports {target}")
    assert bad == []


def test_the_layer_check_sees_imports_of_the_package_root(tmp_path, monkeypatch):
    """Not vacuous: ``from .. import __version__``, ``import posecrb`` and ``from posecrb import x`` in a
    lower layer are each an import of the package root; ``from .. import io`` is an import of io."""
    core = tmp_path / "posecrb" / "core"
    core.mkdir(parents=True)
    (tmp_path / "posecrb" / "__init__.py").write_text("")
    (core / "m.py").write_text("from .. import __version__\nimport posecrb\nfrom posecrb import load\n"
                               "from .. import io\nfrom .._version import __version__ as v\n")
    monkeypatch.setattr(__import__(__name__, fromlist=["ROOT"]), "ROOT", tmp_path / "posecrb")
    assert _imports(core / "m.py") == [(PACKAGE_ROOT, 1), (PACKAGE_ROOT, 2), (PACKAGE_ROOT, 3), ("io", 4),
                                       ("_version", 5)]
    with pytest.raises(AssertionError):
        test_no_module_imports_from_a_package_below_it()


def test_every_package_is_in_the_order():
    packages = {p.name for p in ROOT.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    modules = {p.stem for p in ROOT.glob("*.py")} - {"__init__", "__main__"}
    assert packages | modules == set(ORDER)


def _module_graph() -> dict[str, set[str]]:
    """Every posecrb module -> the posecrb modules it imports, at module level or inside functions
    (an import inside a function still runs before the function's work: a cycle through it is a cycle).
    ``from package import name`` points at the submodule ``package.name`` when there is one, else at the
    package's ``__init__``."""
    files = {}
    for path in ROOT.rglob("*.py"):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        is_package = path.name == "__init__.py"
        package = name.split(".") if is_package else name.split(".")[:-1]
        targets: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = (package[: len(package) - node.level + 1] + (node.module.split(".") if node.module else [])
                        if node.level else (node.module or "").split("."))
                mod = ".".join(base)
                for a in node.names:
                    sub = f"{mod}.{a.name}"
                    targets.add(sub if sub in files else mod)
            elif isinstance(node, ast.Import):
                targets.update(a.name for a in node.names)
        graph[name] = {t for t in targets if t in files and t != name}
    return graph


def test_no_import_cycle():
    """No chain of imports leads from a posecrb module back to itself (Tarjan's strongly connected
    components of the module graph: every component must be a single module)."""
    graph = _module_graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert cycles == [], f"import cycles: {cycles}"


def test_the_cycle_check_sees_function_level_imports(tmp_path, monkeypatch):
    """The check is not vacuous: two modules importing each other, one of them inside a function, form a cycle."""
    pkg = tmp_path / "posecrb" / "demo"
    pkg.mkdir(parents=True)
    (tmp_path / "posecrb" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import g\n")
    (pkg / "b.py").write_text("def g():\n    from .a import x  # noqa\n")
    monkeypatch.setattr(__import__(__name__, fromlist=["ROOT"]), "ROOT", tmp_path / "posecrb")
    graph = _module_graph()
    assert graph["posecrb.demo.a"] == {"posecrb.demo.b"} and graph["posecrb.demo.b"] == {"posecrb.demo.a"}
    with pytest.raises(AssertionError):
        test_no_import_cycle()


# ---------------------------------------------------------------- file sizes
LINE_LIMIT = 450
MAX_LONG_FILES = 2
# Files above the limit that other lines of work are splitting at the time of writing. The list only
# shrinks: once a file is back under the limit its entry must go (the test below says so), and a
# file not listed here counts towards MAX_LONG_FILES.
BEING_SPLIT: set[str] = set()


def _long_files() -> dict[str, int]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        n = len(path.read_text().splitlines())
        if n > LINE_LIMIT:
            out[path.relative_to(ROOT).as_posix()] = n
    return out


def test_at_most_two_files_above_the_line_limit_each_saying_why():
    """docs/design.md#module-map: at most two files under posecrb/ above 450 lines, each saying why in
    its first docstring line (the words "450 lines")."""
    long = _long_files()
    exceptions = {name: n for name, n in long.items() if name not in BEING_SPLIT}
    assert len(exceptions) <= MAX_LONG_FILES, exceptions
    unexplained = [name for name in exceptions
                   if "450 lines" not in ((ast.get_docstring(ast.parse((ROOT / name).read_text())) or "")
                                          .splitlines() or [""])[0]]
    assert unexplained == []
    assert sorted(BEING_SPLIT - set(long)) == [], "split already: remove from BEING_SPLIT"


# The test folders that cross every package, named by what they protect (docs/design.md#testing).
CROSS_CUTTING = {"library", "cli", "files", "hostile", "docs", "package", "benchmarks"}
TESTS = Path(__file__).resolve().parents[1]


def _test_folders() -> list[Path]:
    return sorted(p for p in TESTS.iterdir() if p.is_dir() and p.name not in ("data", "__pycache__"))


def test_tests_mirror_the_packages():
    """Every test module sits in a folder named after a package of posecrb or a cross-cutting promise,
    each folder a package (so module names may repeat across folders)."""
    packages = {p.name for p in ROOT.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    assert not sorted(p.name for p in TESTS.glob("test_*.py")), "test modules belong in a folder"
    for folder in _test_folders():
        assert folder.name in packages | CROSS_CUTTING, f"tests/{folder.name}/ mirrors no package"
        assert (folder / "__init__.py").is_file(), f"tests/{folder.name}/ has no __init__.py"


def test_test_modules_do_not_import_each_other():
    """Shared references live in tests/helpers.py, tests/numerics.py or a folder's references.py,
    never in a test module another one imports."""
    bad = []
    for path in sorted(TESTS.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ""] + ([a.name for a in node.names] if node.level else [])
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            if any(n.rsplit(".", 1)[-1].startswith("test_") for n in names):
                bad.append(f"{path.relative_to(TESTS.parent)}:{node.lineno}")
    assert not bad, bad
