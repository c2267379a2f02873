"""The file layer's promises, function by function (the command-level sweeps are in test_outputs.py).

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
import io
import os
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from posecrb.core import inputs, outputs
from posecrb.core.errors import OutputError, ParseError
from posecrb.core.inputs import gunzip
from posecrb.core.outputs import atomic_write, escape_surrogates, write_text

from .hostile.corpus import graph2, text

REPO = Path(__file__).resolve().parents[1]


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
