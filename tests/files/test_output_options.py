"""The output layer keeps its promises for every path-writing option of the whole command tree.

The options are found by walking the click tree (``posecrb.cli.cli``), never listed by hand: a
new command or option is covered as soon as it exists. For each output option, each hostile
target -- the command's own input, a symbolic link to it, the empty string, a missing directory,
a read-only directory -- must exit 2 naming the option, with nothing written anywhere and the
input intact. A second test fails if any module other than the output layer (posecrb/core/outputs.py
and posecrb/core/folders.py) opens a file for writing; a third checks that a write the system
refuses (full disk, permission, read-only file system) is exit 1 with the path and the reason,
never an internal error. The last ones run every command with an output under faults: a file
name that is not UTF-8, a full disk at the first and at the last write, a signal mid-write.
"""
from __future__ import annotations

import ast
import errno
import hashlib
import io
import json
import os
import re
import signal
from pathlib import Path

import click
import pytest

import posecrb
from posecrb.cli import cli, main
from posecrb.cli.paths import INPUT_TYPES, OUTPUT_TYPES, Command, DatasetArg, InputFile, OutputDir, OutputFile

from ..hostile.corpus import INFO2

GRAPH = "\n".join([f"EDGE_SE2 0 1 1 0 0 {INFO2}", f"EDGE_SE2 1 2 1 0 1.57 {INFO2}",
                   f"EDGE_SE2 2 3 1 0 1.57 {INFO2}", f"EDGE_SE2 3 0 1 0 1.57 {INFO2}",
                   f"EDGE_SE2 0 2 1 1 1.57 {INFO2}"]) + "\n"

# Options whose name says they write, or whose type is click's own path type: each must be
# declared with an output type (or, for click.Path, an input type) of posecrb.cli.paths.
WRITING_NAME = re.compile(r"^--(out|output|save|plot|dest|write|export|dump|expected|report)\b")


def _leaves(cmd: click.Command, path: tuple[str, ...] = ()):
    if isinstance(cmd, click.Group):
        ctx = click.Context(cmd)
        for name in cmd.list_commands(ctx):
            yield from _leaves(cmd.get_command(ctx, name), (*path, name))
    else:
        yield path, cmd


LEAVES = list(_leaves(cli))
OUTPUTS = [(path, cmd, p) for path, cmd in LEAVES for p in cmd.params if isinstance(p.type, OUTPUT_TYPES)]


def _long(p: click.Parameter) -> str:
    return next((o for o in p.opts if o.startswith("--")), p.name or "")


def test_the_walk_finds_every_path_writing_option():
    """Every option named like a writer, or typed as a click path, is declared with the layer's
    types; every command with an output is a paths.Command (the checks run before it); the number
    of output options tested below is the number in the tree."""
    assert len(LEAVES) >= 17, [" ".join(p) for p, _ in LEAVES]           # the groups were descended
    suspects = [(" ".join(path), _long(p)) for path, cmd in LEAVES for p in cmd.params
                if WRITING_NAME.match(_long(p)) or isinstance(p.type, (click.Path, click.File))]
    typed = {(" ".join(path), _long(p)) for path, cmd in LEAVES for p in cmd.params
             if isinstance(p.type, OUTPUT_TYPES + INPUT_TYPES)}
    assert [s for s in suspects if s not in typed] == []
    assert [" ".join(path) for path, cmd, _ in OUTPUTS if not isinstance(cmd, Command)] == []
    found = {(" ".join(path), _long(p)) for path, _, p in OUTPUTS}
    assert len(found) == len(OUTPUTS) == len(CASES_BY_OPTION)
    # today's writers, as a floor: a walk that silently lost a group would find fewer
    assert {("solve", "--out"), ("select", "--out"), ("fim", "--save"), ("tables", "--out"), ("tables", "--plot"),
            ("regress", "--expected"), ("datasets fetch", "--dest"), ("datasets synth", "--out"),
            ("experiment crlb", "--out"), ("experiment crlb", "--plot"), ("experiment sparsify", "--plot"),
            ("experiment sparsify", "--out"), ("experiment thesis", "--plot"), ("experiment octagon", "--out")} <= found


# ---------------------------------------------------------------- the hostile targets
def _ext(t) -> str:
    return t.extensions[0] if isinstance(t, OutputFile) else ""


def _has_input(cmd: click.Command) -> bool:
    return any(isinstance(p.type, DatasetArg) for p in cmd.params)


def _argv(path: tuple[str, ...], cmd: click.Command, option: click.Parameter, value: str, graph: Path,
          fine: Path) -> list[str]:
    """The command with ``option`` = ``value`` and everything else it requires filled in: the graph
    for dataset arguments (required or not, so that it is an input of the call), the first choice
    of a choice, a fine path for other required outputs, ``1`` otherwise; --quick, --trials 2 and
    --repeat 1 where they exist (nothing long may start if a check were missing)."""
    args: list[str] = list(path)
    for p in cmd.params:
        if p is option:
            continue
        t = p.type
        if isinstance(p, click.Argument):
            args.append(str(graph) if isinstance(t, DatasetArg) else
                        (t.choices[0] if isinstance(t, click.Choice) else "1"))
        elif isinstance(t, DatasetArg):
            args += [_long(p), str(graph)]
        elif p.required:
            val = (str(fine / f"other{_ext(t)}") if isinstance(t, OUTPUT_TYPES) else
                   t.choices[0] if isinstance(t, click.Choice) else "1")
            args += [_long(p), val]
        elif _long(p) == "--quick":
            args.append("--quick")
        elif _long(p) in ("--trials", "--repeat"):
            args += [_long(p), "2" if _long(p) == "--trials" else "1"]
    if isinstance(option.type, OutputFile) and option.type.only_with:
        args.append("--" + option.type.only_with.replace("_", "-"))
    return [*args, _long(option), value]


def _targets(tmp: Path, t, graph: Path, has_input: bool) -> dict[str, tuple[str, str]]:
    """case -> (value, words the message must contain)."""
    ext = _ext(t)
    link = tmp / f"link{ext}"
    out: dict[str, tuple[str, str]] = {}
    if has_input:
        link.symlink_to(graph)
        if isinstance(t, OutputDir):
            hard_dir = tmp / "holder"
            hard_dir.mkdir()
            os.link(graph, hard_dir / t.names[0]) if t.names else None
            out["onto the input"] = (str(graph), "not a directory")
            out["symlink to the input"] = (str(link), "not a directory")
            if t.names:
                out["a name of the directory is the input"] = (str(hard_dir), "input")
        else:
            out["onto the input"] = (str(graph), "input")
            out["symlink to the input"] = (str(link), "input")
    out["empty"] = ("", "empty path")
    out["missing directory"] = (str(tmp / "missing" / f"x{ext}"), "does not exist")
    if os.geteuid() == 0:             # root writes through permissions: /proc refuses everyone
        out["read-only directory"] = (f"/proc/posecrb-test{ext}", "cannot write in /proc")
    else:
        ro = tmp / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        out["read-only directory"] = (str(ro / f"x{ext}"), "cannot write in")
    return out


CASE_NAMES = ["onto the input", "symlink to the input", "a name of the directory is the input", "empty",
              "missing directory", "read-only directory"]
CASES_BY_OPTION = [(path, cmd, p) for path, cmd, p in OUTPUTS]


def _snapshot(root: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() and not p.is_symlink() else None)
            for p in sorted(root.rglob("*"))}


@pytest.mark.timeout(600)
@pytest.mark.parametrize("path, cmd, option", CASES_BY_OPTION,
                         ids=[f"{' '.join(path)} {_long(p)}" for path, _, p in CASES_BY_OPTION])
def test_every_output_option_refuses_every_hostile_target(tmp_path, capsys, monkeypatch, path, cmd, option):
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    t = option.type
    tried = []
    for case in CASE_NAMES:
        work = tmp_path / re.sub(r"\W+", "_", case)
        work.mkdir()
        # the input carries an extension the option accepts: the extension check cannot hide the input check
        graph = work / f"input{_ext(t) or '.g2o'}"
        graph.write_text(GRAPH)
        fine = work / "fine"
        fine.mkdir()
        targets = _targets(work, t, graph, _has_input(cmd))
        if case not in targets:
            continue
        value, words = targets[case]
        before = _snapshot(work)
        monkeypatch.chdir(work)
        args = _argv(path, cmd, option, value, graph, fine)
        capsys.readouterr()
        rc = main(args)
        err = capsys.readouterr().err
        assert rc == 2, (case, args, err)
        assert _long(option) in err and words in err, (case, args, err)
        assert "Traceback" not in err and "internal error" not in err
        assert _snapshot(work) == before, (case, args)          # nothing written, the input intact
        tried.append(case)
    assert "empty" in tried and "missing directory" in tried and "read-only directory" in tried
    assert _has_input(cmd) == ("onto the input" in tried)


# ---------------------------------------------------------------- only the layer writes
LAYER = [Path(posecrb.__file__).resolve().parent / "core" / name for name in ("outputs.py", "folders.py")]
# Calls that create, replace or write files or directories.
WRITING_CALLS = {"mkstemp", "mkdtemp", "NamedTemporaryFile", "TemporaryFile", "SpooledTemporaryFile",
                 "TemporaryDirectory", "replace", "rename", "renames", "makedirs", "mkdir", "link", "symlink",
                 "symlink_to", "hardlink_to", "touch", "write_text", "write_bytes", "copy", "copy2", "copyfile",
                 "copytree", "move", "savefig", "savez", "savez_compressed", "save", "savetxt", "tofile", "to_csv",
                 "to_parquet", "to_pickle", "to_excel", "dump", "truncate", "chmod", "unlink", "remove", "rmdir",
                 "rmtree", "save_npz", "mkfifo", "mknod"}
# Functions of the layer itself, and writes into in-memory buffers, are fine.
LAYER_NAMES = {"outputs", "write_text", "write_bytes", "save_figure"}


def _buffers(tree: ast.AST) -> set[str]:
    """Names bound to in-memory buffers or to the layer's ``atomic_write`` handles."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call):
            f = node.value.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if name in ("StringIO", "BytesIO"):
                out |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        if isinstance(node, (ast.With, ast.AsyncWith)):
            for item in node.items:
                c = item.context_expr
                if isinstance(c, ast.Call) and getattr(c.func, "id", getattr(c.func, "attr", "")) == "atomic_write" \
                        and isinstance(item.optional_vars, ast.Name):
                    out.add(item.optional_vars.id)
    return out


_FILE_MODULES = ("io", "builtins", "gzip", "bz2", "lzma", "codecs", "tarfile", "zipfile")


def _writes(call: ast.Call, mode_at: int) -> bool:
    """Whether an ``open`` call's mode (positional ``mode_at`` or ``mode=``) writes."""
    mode = (call.args[mode_at] if len(call.args) > mode_at else
            next((k.value for k in call.keywords if k.arg == "mode"), None))
    return isinstance(mode, ast.Constant) and isinstance(mode.value, str) and bool(set(mode.value) & set("wax+"))


def _violations(path: Path) -> list[str]:
    tree = ast.parse(path.read_text())
    buffers = _buffers(tree)
    bad = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
        owner = f.value.id if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) else None
        where = f"{path.name}:{node.lineno}: {ast.unparse(node)[:80]}"
        if name == "open":
            if owner == "os":
                flags = ast.unparse(node.args[1]) if len(node.args) > 1 else ""
                if re.search(r"WR|CREAT|APPEND|TRUNC", flags):
                    bad.append(where)
            elif _writes(node, 1 if isinstance(f, ast.Name) or owner in _FILE_MODULES else 0):
                bad.append(where)                # open(p, "w"), gzip.open(p, "wb"), Path(p).open("w")
        elif name in WRITING_CALLS:
            if isinstance(f, ast.Name) and name in LAYER_NAMES:
                continue                         # the layer's functions, imported by name
            if owner in LAYER_NAMES:
                continue                         # outputs.write_text(...)
            target = node.args[0] if node.args else None
            if isinstance(target, ast.Name) and target.id in buffers:
                continue                         # savefig(fh) into atomic_write's handle, savetxt(buf)
            if name == "save" and owner not in ("np", "numpy"):
                continue                         # io.save (a writer going through the layer), other objects
            if name.startswith("to_") and isinstance(f, ast.Name):
                continue                         # render.to_csv(rows) returns text; DataFrame.to_csv(path) writes
            if name in ("replace", "dump", "copy", "remove", "move", "truncate") and owner not in ("os", "shutil",
                                                                                                   "json", "pickle"):
                continue                         # str.replace, dict.copy, list.remove, dataclasses.replace...
            bad.append(where)
    return bad


def test_no_module_but_the_layer_writes_files():
    root = LAYER[0].parents[1]
    bad = [v for path in sorted(root.rglob("*.py")) if path not in LAYER for v in _violations(path)]
    assert bad == []


def test_the_scan_sees_writes(tmp_path):
    """The scan is not vacuous: every way of writing it knows is found in a module written to fail."""
    probe = tmp_path / "probe.py"
    lines = ["open('x', 'w')", "open('x', mode='ab')", "os.open('x', os.O_WRONLY | os.O_CREAT)", "os.replace('a', 'b')",
             "Path('x').write_text('y')", "Path('x').open('w')", "np.savez('x.npz', a=1)", "tempfile.mkstemp()",
             "shutil.copy('a', 'b')", "fig.savefig('x.png')", "os.makedirs('d')", "gzip.open('x.gz', 'wt')"]
    probe.write_text("\n".join(lines) + "\nopen('x')\nopen('x', 'rb')\nos.open('x', os.O_RDONLY)\n"
                     "buf = io.StringIO()\nnp.savetxt(buf, a)\nwith atomic_write('x') as fh:\n    fig.savefig(fh)\n")
    assert len(_violations(probe)) == len(lines)


# ---------------------------------------------------------------- the system refuses the write
@pytest.mark.parametrize("code, where", [(errno.ENOSPC, "fsync"), (errno.EACCES, "mkstemp"),
                                         (errno.EROFS, "replace")])
def test_a_refused_write_is_exit_1_with_the_path_and_the_reason(tmp_path, capsys, monkeypatch, code, where):
    """A full disk said `internal error ... (a bug in posecrb)`: now the path and the system's reason."""
    import posecrb.core.outputs as outputs

    graph = tmp_path / "g.g2o"
    graph.write_text(GRAPH)
    out = tmp_path / "est.g2o"
    out.write_text("previous\n")

    def refuse(*a, **k):
        raise OSError(code, os.strerror(code))

    target = {"fsync": (outputs.os, "fsync"), "mkstemp": (outputs.tempfile, "mkstemp"),
              "replace": (outputs.os, "replace")}[where]
    monkeypatch.setattr(*target, refuse)
    capsys.readouterr()
    rc = main(["solve", str(graph), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 1, err
    assert f"cannot write {out}: {os.strerror(code)}" in err and "internal error" not in err
    assert out.read_text() == "previous\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["est.g2o", "g.g2o"]      # no temporary left


def test_input_types_guard_before_the_work(tmp_path, capsys):
    """--fixed and --estimate are read through the input layer's guards at once (exit 1, named)."""
    graph = tmp_path / "g.g2o"
    graph.write_text(GRAPH)
    fifo = tmp_path / "pairs"
    os.mkfifo(fifo)
    for args in (["select", str(graph), "--budget", "1", "--fixed", str(fifo)],
                 ["experiment", "sparsify", str(graph), "--quick", "--fixed", "/dev/zero"],
                 ["select", str(graph), "--budget", "1", "--objective", "fim", "--estimate", str(tmp_path)]):
        capsys.readouterr()
        assert main(args) == 1
        assert "not a regular file" in capsys.readouterr().err
    assert isinstance(next(p for p in cli.get_command(click.Context(cli), "select").params
                           if p.name == "fixed").type, InputFile)


# ---------------------------------------------------------------- every output under faults
# Each command with an output option runs on a graph whose file name is not valid UTF-8 (it must
# succeed, its text outputs valid UTF-8), then with a full disk from the first write on and from the
# last write on (exit 1 naming the path, nothing left behind); folder outputs also take a signal at
# chosen writes and in the middle of their swap (posecrb's files all old or all new, others untouched).
# Writes are counted and failed at the raw file under the output layer's buffers, as a device would.


class _Disk(io.FileIO):
    """``posecrb.core.outputs.RAW_FILE`` for one run: counts raw writes; from write ``full_at`` on each
    fails with ENOSPC; after write ``signal_at`` the process gets SIGTERM."""

    writes = 0
    full_at: int | None = None
    signal_at: int | None = None

    def write(self, b):
        cls = type(self)
        cls.writes += 1
        if cls.full_at is not None and cls.writes >= cls.full_at:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = super().write(b)
        if cls.writes == cls.signal_at:
            os.kill(os.getpid(), signal.SIGTERM)
        return n


def _disk(monkeypatch, **faults) -> type[_Disk]:
    import posecrb.core.outputs as outputs

    disk = type("Disk", (_Disk,), dict(faults))
    monkeypatch.setattr(outputs, "RAW_FILE", disk)
    return disk


@pytest.fixture(scope="module")
def sweep_graph(tmp_path_factory) -> Path:
    """A 16-pose noisy grid with 9 loop closures (sparsify's budgets need candidates)."""
    path = tmp_path_factory.mktemp("sweep") / "grid.g2o"
    assert main(["-q", "datasets", "synth", "grid2d", "--poses", "16", "--noise", "0.05", "--seed", "3",
                 "--out", str(path), "--format", "json"]) == 0
    return path


NON_UTF8 = os.fsdecode(b"caf\xe9.g2o")          # 'caf\udce9.g2o': the byte 0xe9 is not UTF-8
SWEPT = [(path, cmd, p) for path, cmd, p in OUTPUTS if path != ("datasets", "fetch")]   # fetch: its own test
FOLDERS = [(path, cmd, p) for path, cmd, p in SWEPT if isinstance(p.type, OutputDir)]


def _setup(root: Path, path, cmd, option, graph: Path) -> tuple[Path, Path, list[str]]:
    """(work directory, output target, argv) of one run on a copy of ``graph`` named NON_UTF8."""
    work = root / "work"
    work.mkdir(parents=True)
    g = work / NON_UTF8
    g.write_bytes(graph.read_bytes())
    fine = work / "fine"
    fine.mkdir()
    target = work / (f"out{_ext(option.type)}" if isinstance(option.type, OutputFile) else "outdir")
    return work, target, ["-q", *_argv(path, cmd, option, str(target), g, fine)]


def _run(args, capsys, monkeypatch, work: Path) -> tuple[int, str]:
    monkeypatch.chdir(work)
    capsys.readouterr()
    rc = main(args)
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    return rc, err


def _written(target: Path) -> list[Path]:
    return sorted(p for p in target.iterdir()) if target.is_dir() else [target]


@pytest.mark.timeout(600)
@pytest.mark.parametrize("path, cmd, option", SWEPT, ids=[f"{' '.join(p)} {_long(o)}" for p, _, o in SWEPT])
def test_every_output_survives_a_non_utf8_name_and_a_full_disk(tmp_path, capsys, monkeypatch, sweep_graph,
                                                               path, cmd, option):
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    work, target, args = _setup(tmp_path / "ok", path, cmd, option, sweep_graph)
    disk = _disk(monkeypatch)
    rc, err = _run(args, capsys, monkeypatch, work)
    assert rc == 0, (args, err)
    for f in _written(target):
        if f.suffix in (".json", ".csv", ".md", ".tex", ".g2o"):
            f.read_bytes().decode("utf-8")                     # valid UTF-8, the odd byte escaped
    writes = disk.writes
    assert writes >= 1
    for full_at in sorted({1, writes}):
        work, target, args = _setup(tmp_path / f"full{full_at}", path, cmd, option, sweep_graph)
        before = _snapshot(work)
        _disk(monkeypatch, full_at=full_at)
        rc, err = _run(args, capsys, monkeypatch, work)
        assert rc == 1, (full_at, args, err)
        shown = f"cannot write {target}" + (os.sep if isinstance(option.type, OutputDir) else "")
        assert shown in err and "No space left on device" in err, (full_at, err)
        assert _snapshot(work) == before, full_at                # nothing left: no file, no temporary


def _old_run(target: Path, names: tuple[str, ...]) -> dict[str, bytes | None]:
    """``target`` as a previous run left it: every name the option declares, with the manifest that
    says posecrb wrote them, and a file of the user's."""
    from posecrb.core.folders import MANIFEST

    target.mkdir()
    digests = {}
    for n in names:
        data = f"old {n}\n".encode()
        (target / n).write_bytes(data)
        digests[n] = hashlib.sha256(data).hexdigest()
    (target / MANIFEST).write_text(json.dumps({"schema": 1, "files": digests}))
    (target / "notes.txt").write_text("the user's\n")
    return _snapshot(target)


@pytest.mark.timeout(600)
@pytest.mark.parametrize("path, cmd, option", FOLDERS, ids=[f"{' '.join(p)} {_long(o)}" for p, _, o in FOLDERS])
def test_a_folder_output_is_all_old_or_all_new_after_a_signal(tmp_path, capsys, monkeypatch, sweep_graph,
                                                              path, cmd, option):
    """SIGTERM at the first, a middle and the last write leaves the previous run's folder as it was;
    SIGTERM in the middle of the swap is held until the swap is done (all new). Either way the
    user's file in the folder is untouched and no staging directory is left."""
    import posecrb.core.folders as folders

    monkeypatch.delenv("POSECRB_DATA", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    work, target, args = _setup(tmp_path / "fresh", path, cmd, option, sweep_graph)
    disk = _disk(monkeypatch)
    assert _run(args, capsys, monkeypatch, work)[0] == 0
    new_names = {p.name for p in target.iterdir()}
    writes = disk.writes
    for k in sorted({1, (writes + 1) // 2, writes}):
        work, target, args = _setup(tmp_path / f"sig{k}", path, cmd, option, sweep_graph)
        old = _old_run(target, option.type.names)
        _disk(monkeypatch, signal_at=k)
        rc, err = _run(args, capsys, monkeypatch, work)
        assert rc == 128 + signal.SIGTERM and "terminated" in err, (k, err)
        assert _snapshot(target) == old, k
        assert sorted(p.name for p in work.iterdir()) == sorted(["fine", NON_UTF8, "outdir"]), k

    work, target, args = _setup(tmp_path / "swap", path, cmd, option, sweep_graph)
    old = _old_run(target, option.type.names)
    rename = os.rename
    calls = []

    def rename_then_signal(src, dst):
        rename(src, dst)
        calls.append(dst)
        if len(calls) == 2:                   # one old file moved aside, one new file moved in, ...
            os.kill(os.getpid(), signal.SIGTERM)

    _disk(monkeypatch)
    monkeypatch.setattr(folders.os, "rename", rename_then_signal)
    rc, err = _run(args, capsys, monkeypatch, work)
    monkeypatch.setattr(folders.os, "rename", rename)
    assert rc == 128 + signal.SIGTERM and len(calls) > 2, err
    now = _snapshot(target)
    assert set(now) == new_names | {"notes.txt"}
    assert now["notes.txt"] == old["notes.txt"]
    assert not [n for n, data in now.items() if data is not None and data.startswith(b"old ")]
    assert sorted(p.name for p in work.iterdir()) == sorted(["fine", NON_UTF8, "outdir"])


def test_fetch_dest_on_a_full_disk_is_exit_1_and_leaves_nothing(tmp_path, capsys, monkeypatch, request):
    url, _, _ = request.getfixturevalue("server")
    dest = tmp_path / "dest"
    dest.mkdir()
    args = ["-q", "datasets", "fetch", "tinyGrid3D", "--url", f"{url}/tinyGrid3D.g2o", "--dest", str(dest)]
    disk = _disk(monkeypatch)
    assert _run(args, capsys, monkeypatch, tmp_path)[0] == 0
    writes = disk.writes
    (dest / "tinyGrid3D.g2o").unlink()
    for full_at in sorted({1, writes}):
        _disk(monkeypatch, full_at=full_at)
        rc, err = _run(args, capsys, monkeypatch, tmp_path)
        assert rc == 1 and f"cannot write {dest / 'tinyGrid3D.g2o'}: No space left on device" in err, err
        assert list(dest.iterdir()) == []
