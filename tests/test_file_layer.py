"""The file layer's promises, function by function (the command-level sweeps are in test_outputs.py).

Inputs: gzip is inflated in bounded slices (linear, never copying the remaining input per chunk);
``.npz`` archives are read with a cap on what they inflate, without pickles, and anything that is not
one is a ``ParseError``; paths with NUL characters are clean errors wherever a path enters.
Outputs: a writer reports the first error of a full disk, not its repetition at close; undecodable
file-name bytes are written as ``\\xNN``; a folder output is all of one run. Messages: dataset names
that cannot be fetched are not told to fetch; a symbolic link loop is called one.
"""
from __future__ import annotations

import gzip
import zlib
from pathlib import Path

import numpy as np
import pytest

from posecrb.core import inputs
from posecrb.core.errors import ParseError
from posecrb.core.inputs import gunzip

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
