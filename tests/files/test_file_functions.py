"""The file layer's promises, function by function (the command-level sweeps are in
tests/files/test_output_options.py).

Inputs: gzip is inflated in bounded slices (linear, never copying the remaining input per chunk);
``.npz`` archives are read with a cap on what they inflate, without pickles, and anything that is not
one is a ``ParseError``; paths with NUL characters are clean errors wherever a path enters.
Outputs: a writer reports the first error of a full disk, not its repetition at close; undecodable
file-name bytes are written as ``\\xNN``; a folder output is all of one run. Messages: dataset names
that cannot be fetched are not told to fetch; a symbolic link loop is called one.
"""
from __future__ import annotations

import errno
import gzip
import hashlib
import io
import json
import logging
import os
import signal
import subprocess
import sys
import tracemalloc
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pytest

import posecrb
from posecrb import io as graph_io
from posecrb.cli import main
from posecrb.core import archives, folders, inputs, outputs
from posecrb.core.archives import read_npz
from posecrb.core.errors import ArgumentError, OutputError, ParseError, PosecrbError
from posecrb.core.folders import MANIFEST, deferred_signals, output_folder
from posecrb.core.inputs import gunzip
from posecrb.core.outputs import atomic_write, escape_surrogates, write_text
from posecrb.core.result import Result

from ..hostile.corpus import graph2, text

REPO = Path(__file__).resolve().parents[2]


# ---------------------------------------------------------------- gzip: linear inflation
def test_gunzip_never_hands_zlib_more_than_one_slice(monkeypatch):
    """Each zlib call got the whole remaining input (its ``unconsumed_tail``), copied once per 1 MiB
    of output: a 53 MB bomb took 46 s to refuse. Now every call gets at most one slice."""
    real = zlib.decompressobj
    sizes: list[int] = []

    class Recording:
        def __init__(self, *a):
            self.d = real(*a)

        def decompress(self, data, max_length=0):
            sizes.append(len(data))
            return self.d.decompress(data, max_length)

        def __getattr__(self, name):
            return getattr(self.d, name)

    monkeypatch.setattr(inputs.zlib, "decompressobj", Recording)
    rng = np.random.default_rng(7)
    payload = rng.integers(0, 4, size=6 << 20, dtype=np.uint8).tobytes()        # compresses about 4:1
    data = gzip.compress(payload, compresslevel=1)
    assert len(data) > 8 * inputs._INPUT_SLICE
    assert gunzip(data, "x.gz", limit=len(payload)) == payload
    assert max(sizes) <= inputs._INPUT_SLICE
    sizes.clear()
    with pytest.raises(ParseError, match="need about 16 times"):
        gunzip(gzip.compress(b"\0" * (64 << 20)), "bomb.gz", limit=1 << 20)
    assert max(sizes) <= inputs._INPUT_SLICE


@pytest.mark.parametrize("cut", [1, 100, 65535, 65536, 65537, 200000])
def test_gunzip_members_across_slice_boundaries_match_pythons_gzip(cut):
    """Several members, the first ending at, before and after a slice boundary, then NUL padding."""
    rng = np.random.default_rng(cut)
    first = rng.integers(0, 256, size=cut, dtype=np.uint8).tobytes()     # incompressible: ends near ``cut``
    second = b"second member " * 1000
    members = gzip.compress(first, compresslevel=0) + gzip.compress(second)
    assert gunzip(members + b"\0" * 300, "x.gz") == gzip.decompress(members) == first + second


# ---------------------------------------------------------------- .npz archives
def _npz(tmp_path: Path, name: str = "r.npz", **arrays) -> Path:
    path = tmp_path / name
    np.savez(path, **arrays)
    return path


def test_npz_member_bomb_is_refused_before_it_is_inflated(tmp_path, monkeypatch):
    """A small archive whose member inflates to 64 MiB loaded at that size (3.2 MB -> 3.36 GB RSS)."""
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as zf:
        buf = io.BytesIO()
        np.lib.format.write_array(buf, np.zeros(8 << 20))          # 64 MiB of zeros
        zf.writestr("rot.npy", buf.getvalue())
    assert bomb.stat().st_size < 1 << 20
    monkeypatch.setattr(archives, "available_memory", lambda: archives.ARCHIVE_EXPANSION * (4 << 20))
    tracemalloc.start()
    try:
        for load in (read_npz, posecrb.SolveResult.load):
            with pytest.raises(ParseError, match="need about 4 times as much memory"):
                load(bomb)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 << 20


def test_npz_member_inflating_beyond_its_declared_size_is_refused(tmp_path):
    path = _npz(tmp_path, a=np.arange(1000.0))
    raw = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("a.npy")
    small = (200).to_bytes(4, "little")
    raw[info.header_offset + 22: info.header_offset + 26] = small          # local header: uncompressed size
    central = raw.rindex(b"PK\x01\x02")
    raw[central + 24: central + 28] = small                                 # central directory: the same
    path.write_bytes(bytes(raw))
    with pytest.raises(ParseError, match="a.npy"):
        read_npz(path)


def test_npz_with_python_objects_is_refused(tmp_path):
    path = _npz(tmp_path, a=np.array([{"x": 1}], dtype=object))
    with pytest.raises(ParseError, match="Python objects"):
        read_npz(path)


def test_npz_header_that_disagrees_with_its_data_is_refused(tmp_path):
    path = tmp_path / "h.npz"
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10 ** 12,)})
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("a.npy", np.lib.format.magic(1, 0) + header.getvalue()[8:] + b"\0" * 64)
    with pytest.raises(ParseError, match="declares 8000000000000 bytes"):
        read_npz(path)


def test_npz_arrays_come_back_as_saved(tmp_path):
    arrays = {"a": np.arange(12.0).reshape(3, 4), "f": np.asfortranarray(np.eye(3)), "s": np.array("text"),
              "i": np.array([1, 2], dtype=np.int32), "e": np.empty((0, 3))}
    got = read_npz(_npz(tmp_path, **arrays))
    assert got.keys() == arrays.keys()
    for k, v in arrays.items():
        assert got[k].dtype == v.dtype and got[k].shape == v.shape
        np.testing.assert_array_equal(got[k], v)


@pytest.fixture(scope="module")
def results(public_results) -> list[Result]:
    """One instance of every public result type (tests/conftest.py)."""
    return list(public_results.values())


def test_load_of_what_is_not_a_result_file_is_a_parse_error(tmp_path, results):
    """Result.load of a .npy, a truncated zip, an empty file or a g2o file raised TypeError, BadZipFile,
    EOFError or pickle's ValueError."""
    with pytest.raises(ArgumentError, match="is not a file name"):
        results[0].load(None)
    np.save(tmp_path / "a.npy", np.arange(3))
    (tmp_path / "empty.npz").write_bytes(b"")
    (tmp_path / "g.g2o").write_text(text(graph2()))
    for res in results:
        saved = Path(res.save(tmp_path / f"{type(res).__name__}.npz"))
        assert type(res).load(saved).to_dict() == res.to_dict()
        trunc = tmp_path / "trunc.npz"
        trunc.write_bytes(saved.read_bytes()[: saved.stat().st_size // 2])
        for path, words in ((tmp_path / "a.npy", "not a .npz archive"), (tmp_path / "empty.npz", "an empty file"),
                            (trunc, "not a .npz archive"), (tmp_path / "g.g2o", "not a .npz archive"),
                            (tmp_path, "is a directory")):
            with pytest.raises(ParseError, match=words):
                type(res).load(path)
        with pytest.raises(ArgumentError, match="NUL"):      # not a path at all: the argument is wrong
            type(res).load(str(tmp_path / "x\0.npz"))


def test_save_refuses_none_the_empty_path_and_devices(tmp_path, monkeypatch, results):
    """save(None) raised TypeError; save('') wrote a hidden '.npz'; save('/dev/null') wrote /dev/null.npz."""
    monkeypatch.chdir(tmp_path)
    for res in results:
        for bad, words in ((None, "is not a file name"), ("", "is not a file name"),
                           ("/dev/null", "is a character device"), (tmp_path, "is a directory"),
                           (str(tmp_path / "x\0"), "NUL")):
            with pytest.raises(ArgumentError, match=words):
                res.save(bad)
    assert list(tmp_path.iterdir()) == [] and not os.path.exists("/dev/null.npz")


# ---------------------------------------------------------------- NUL characters in paths
def test_a_nul_character_in_any_path_is_a_clean_error(tmp_path):
    """posecrb.load('a\\0b') raised ValueError: embedded null byte; so did every function that resolves
    a dataset, and data_dir."""
    g = tmp_path / "g.g2o"
    g.write_text(text(graph2()))
    nul = str(tmp_path / "a\0b.g2o")
    calls = [lambda: posecrb.load(nul), lambda: posecrb.bounds(nul), lambda: posecrb.fim(nul),
             lambda: posecrb.crlb(nul), lambda: posecrb.solve(nul), lambda: posecrb.select(nul, budget=1),
             lambda: posecrb.timeline(nul), lambda: posecrb.bounds("tinyGrid3D", data_dir=str(tmp_path / "\0")),
             lambda: posecrb.solve(g, out=nul), lambda: posecrb.select(g, budget=1, out=nul),
             lambda: posecrb.fim(g, estimate=nul), lambda: posecrb.timeline(g, plot=str(tmp_path / "a\0.png")),
             lambda: graph_io.load(nul), lambda: graph_io.save(posecrb.load(g), nul),
             lambda: graph_io.write_g2o(posecrb.load(g), nul)]
    for k, call in enumerate(calls):
        with pytest.raises(PosecrbError):
            call()
        assert sorted(p.name for p in tmp_path.iterdir()) == ["g.g2o"], k


# ---------------------------------------------------------------- writers keep the first error
class _FullDisk(io.FileIO):
    def write(self, b):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("mode, size", [("w", 10), ("wb", 10), ("wb", 1 << 20)])
def test_a_full_disk_is_one_output_error_naming_the_path(tmp_path, monkeypatch, mode, size):
    """The OutputError raised when the flush failed was replaced by the same OSError raised again when
    the file was closed (`internal error: OSError: [Errno 28]`). Small writes fail at the flush, large
    ones in the body's own write; both are the first error, and nothing is left."""
    monkeypatch.setattr(outputs, "RAW_FILE", _FullDisk)
    target = tmp_path / "r.out"
    with pytest.raises(OutputError, match=f"cannot write {target}: No space left on device") as exc:
        with atomic_write(target, mode) as fh:
            fh.write("x" * size if mode == "w" else b"x" * size)
    assert isinstance(exc.value.__context__, (OSError, type(None)))
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------- undecodable file names
def test_undecodable_bytes_are_written_escaped():
    name = os.fsdecode(b"caf\xe9.g2o")
    assert escape_surrogates(name) == "caf\\xe9.g2o" and escape_surrogates("café") == "café"


def test_text_outputs_escape_undecodable_bytes(tmp_path):
    name = os.fsdecode(b"caf\xe9.g2o")
    write_text(tmp_path / "t.md", f"| {name} | é |\n")
    assert (tmp_path / "t.md").read_text(encoding="utf-8") == "| caf\\xe9.g2o | é |\n"


@pytest.mark.parametrize("fmt", ["csv", "markdown", "json"])
def test_stdout_shows_a_non_utf8_file_name_under_a_strict_utf8_terminal(tmp_path, fmt):
    """`bounds caf\\xe9.g2o --format csv` died with UnicodeEncodeError where stdout is strict UTF-8."""
    g = tmp_path / os.fsdecode(b"caf\xe9.g2o")
    g.write_text(text(graph2()))
    env = {**os.environ, "PYTHONPATH": str(REPO), "PYTHONIOENCODING": "utf-8:strict", "LANG": "C.UTF-8"}
    proc = subprocess.run([sys.executable, "-m", "posecrb", "bounds", os.fsencode(g), "--format", fmt],
                          capture_output=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert b"caf\\xe9" in proc.stdout or b"caf\\\\xe9" in proc.stdout or b"caf\\udce9" in proc.stdout


# ---------------------------------------------------------------- folders
def _tree(d: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.iterdir()) if p.is_file()}


def test_a_new_folder_appears_whole_with_its_manifest(tmp_path):
    with output_folder(tmp_path / "out") as stage:
        write_text(stage / "a.csv", "1\n")
        write_text(stage / "run.json", "{}\n")
        assert not (tmp_path / "out").exists()
    files = _tree(tmp_path / "out")
    manifest = json.loads(files.pop(MANIFEST))
    assert files == {"a.csv": b"1\n", "run.json": b"{}\n"}
    assert manifest["files"] == {n: hashlib.sha256(b).hexdigest() for n, b in files.items()}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def _previous(tmp_path: Path) -> Path:
    out = tmp_path / "out"
    with output_folder(out) as stage:
        for name in ("table1.md", "table2.md", "run.json"):
            write_text(stage / name, f"old {name}\n")
    (out / "notes.txt").write_text("mine\n")
    return out


def test_a_new_run_replaces_all_of_the_old_runs_files_and_nothing_else(tmp_path):
    """tables --out over an earlier run left table2.* of that run next to the new table1.*."""
    out = _previous(tmp_path)
    (out / "table2.md").write_text("edited by hand\n")        # no longer what posecrb wrote: the user's now
    with output_folder(out) as stage:
        write_text(stage / "table1.md", "new\n")
        write_text(stage / "run.json", "new\n")
    files = _tree(out)
    files.pop(MANIFEST)
    assert files == {"table1.md": b"new\n", "run.json": b"new\n", "table2.md": b"edited by hand\n",
                     "notes.txt": b"mine\n"}


@pytest.mark.parametrize("when", ["in the block", "at the third rename"])
def test_a_failure_leaves_the_old_run_whole(tmp_path, monkeypatch, when):
    out = _previous(tmp_path)
    before = _tree(out)
    rename = os.rename
    calls = []

    def failing(src, dst):
        calls.append(dst)
        if len(calls) == 3:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), os.fspath(dst))
        rename(src, dst)

    with pytest.raises((OutputError, RuntimeError)) as exc:
        with output_folder(out) as stage:
            write_text(stage / "table1.md", "new\n")
            write_text(stage / "run.json", "new\n")
            if when == "in the block":
                raise RuntimeError("the work failed")
            monkeypatch.setattr(folders.os, "rename", failing)
    monkeypatch.setattr(folders.os, "rename", rename)
    if when != "in the block":
        assert str(exc.value).startswith(f"cannot write {out}")
    assert _tree(out) == before
    assert sorted(p.name for p in out.iterdir()) == sorted(before)        # no staging directory left
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_folder_given_as_a_symbolic_link_stays_one(tmp_path):
    """The folder is written where the link points (staged inside it, on its file system); the link
    is not replaced by a directory."""
    real = _previous(tmp_path)
    link = tmp_path / "link"
    link.symlink_to(real)
    with output_folder(link) as stage:
        write_text(stage / "table1.md", "new\n")
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert (real / "table1.md").read_text() == "new\n" and not (real / "table2.md").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "out"]


def test_when_the_rollback_fails_too_the_previous_files_are_kept_and_named(tmp_path, monkeypatch):
    out = _previous(tmp_path)
    rename = os.rename
    calls = []

    def failing(src, dst):
        calls.append(dst)
        if len(calls) >= 4:                 # the swap's fourth rename, and every rename of the rollback
            raise OSError(errno.EIO, os.strerror(errno.EIO), os.fspath(src))
        rename(src, dst)

    with pytest.raises(OutputError, match="holds files of both runs, and the previous files not put back are in") \
            as exc:
        with output_folder(out) as stage:
            write_text(stage / "table1.md", "new\n")
            monkeypatch.setattr(folders.os, "rename", failing)
    monkeypatch.setattr(folders.os, "rename", rename)
    kept = Path(str(exc.value).rsplit(" are in ", 1)[1])
    assert kept.is_dir() and {p.name for p in kept.iterdir()} <= {"table1.md", "table2.md", "run.json", MANIFEST}
    assert {p.name for p in kept.iterdir()} | {p.name for p in out.iterdir() if p.is_file()} >= \
        {"table1.md", "table2.md", "run.json", "notes.txt"}


def test_a_hostile_manifest_cannot_reach_outside_the_folder(tmp_path):
    out = _previous(tmp_path)
    victim = tmp_path / "victim.txt"
    victim.write_text("keep\n")
    digest = hashlib.sha256(b"keep\n").hexdigest()
    (out / MANIFEST).write_text(json.dumps({"files": {"../victim.txt": digest, str(victim): digest, "": digest}}))
    with output_folder(out) as stage:
        write_text(stage / "x.csv", "new\n")
    assert victim.read_text() == "keep\n"


def test_an_unreadable_manifest_leaves_the_unknown_files_and_says_so(tmp_path, caplog):
    out = _previous(tmp_path)
    (out / MANIFEST).write_text("{not json")
    with caplog.at_level(logging.WARNING, logger="posecrb"), output_folder(out) as stage:
        write_text(stage / "table1.md", "new\n")
    assert "unreadable" in caplog.text
    assert (out / "table2.md").read_text() == "old table2.md\n" and (out / "table1.md").read_text() == "new\n"


def test_signals_during_a_swap_are_held_until_it_is_done():
    got = []
    previous = signal.signal(signal.SIGTERM, lambda s, f: got.append(("handled", s)))
    try:
        with deferred_signals():
            os.kill(os.getpid(), signal.SIGTERM)
            got.append("still inside")
        assert got == ["still inside", ("handled", signal.SIGTERM)]
    finally:
        signal.signal(signal.SIGTERM, previous)


# ---------------------------------------------------------------- messages
def test_a_comma_list_is_not_told_to_fetch_it(tmp_path, capsys, monkeypatch):
    """`bounds intel,MIT` suggested `posecrb datasets fetch intel,MIT`, which cannot work."""
    monkeypatch.setenv("POSECRB_DATA", str(tmp_path))
    capsys.readouterr()
    assert main(["bounds", "intel,MIT"]) == 1
    err = capsys.readouterr().err
    assert "datasets fetch" not in err and "give one dataset per argument" in err and "(intel MIT)" in err
    assert main(["bounds", "no-such-thing"]) == 1
    err = capsys.readouterr().err
    assert "datasets fetch" not in err and "posecrb datasets list" in err
    assert main(["bounds", "intel"]) == 1                     # in the manifest, not on the path: fetch it
    assert "run `posecrb datasets fetch intel`" in capsys.readouterr().err


def test_a_symbolic_link_loop_is_called_one(tmp_path, capsys, monkeypatch):
    """A symlink loop in POSECRB_DATA was called "dangling"."""
    a, b = tmp_path / "a", tmp_path / "b"
    a.symlink_to(b)
    b.symlink_to(a)
    monkeypatch.setenv("POSECRB_DATA", str(a))
    capsys.readouterr()
    assert main(["bounds", "intel"]) == 2
    assert f"$POSECRB_DATA entry {a} is a symbolic link loop" in capsys.readouterr().err
    monkeypatch.delenv("POSECRB_DATA")
    with pytest.raises(ParseError, match="symbolic link loop"):
        inputs.read_input(a)
    with pytest.raises(PosecrbError, match="symbolic link loop"):
        outputs.check_output_dir(a)


def test_matplotlibs_warnings_reach_stderr_as_posecrb_lines(tmp_path):
    """Under a read-only $HOME matplotlib's cache warning reached stderr raw."""
    g = tmp_path / "g.g2o"
    g.write_text(text(graph2()))
    env = {k: v for k, v in os.environ.items() if k not in ("MPLCONFIGDIR", "XDG_CONFIG_HOME", "XDG_CACHE_HOME")}
    env.update(HOME="/dev/null", PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, "-m", "posecrb", "timeline", str(g), "--plot", str(tmp_path / "t.png"),
                           "--format", "json"], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert any("matplotlib" in ln for ln in lines), proc.stderr    # the condition is reproduced
    assert all(ln.startswith("posecrb: ") for ln in lines), proc.stderr
