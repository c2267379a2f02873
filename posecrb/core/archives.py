"""The input layer's reader of ``.npz`` archives (saved results): capped, streamed, no pickles.

A ``.npz`` file is a zip archive of ``.npy`` members. An archive of a few megabytes can declare, or
inflate to, gigabytes (a zip bomb), so ``read_npz`` never lets zlib or numpy decide how much memory
to take:

* the archive itself is read through ``posecrb.core.inputs.read_regular_file`` (regular file, size);
* the members' declared sizes (the central directory's) must add up to at most the limit, derived
  from the available memory (``ARCHIVE_EXPANSION``), before anything is inflated;
* each member is inflated in chunks into a buffer of its declared size; inflating more than declared
  stops at once (zipfile stops at the declared size itself; the count is checked anyway);
* each member's ``.npy`` header is checked against its data: a known format version, no Python
  objects (which would be unpickled), and a shape whose size is exactly the bytes present; the array
  is then a view of the inflated buffer (no second copy).

Every failure -- not a zip archive (an ``.npy``, a g2o file, an empty file), a truncated or corrupt
archive, a member too large -- is a ``ParseError`` naming the file.
"""
from __future__ import annotations

import io
import math
import os
import zipfile
import zlib
from typing import cast

import numpy as np

from .errors import ParseError
from .inputs import checked_name, read_regular_file, too_large
from .resources import available_memory

# Loading an archive holds its inflated members once (the arrays are views of them); what the
# caller builds from the arrays (a copy, a sparse matrix, a factorization's input) is counted
# as up to three more copies. Archives whose members inflate beyond the available memory / this
# are refused before they are inflated.
ARCHIVE_EXPANSION = 4
_DEFAULT_LIMIT = 4 * 1024 ** 3            # without a memory figure from the system
_CHUNK = 1 << 20
_NPY_VERSIONS = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}
_HEADER_BYTES = 65536 + 16                # magic, header length and numpy's largest header


def archive_limit() -> int:
    """Largest total of inflated members read: the available memory / ``ARCHIVE_EXPANSION``."""
    avail = available_memory()
    return _DEFAULT_LIMIT if avail is None else max(avail // ARCHIVE_EXPANSION, _CHUNK)


def _inflate(zf: zipfile.ZipFile, info: zipfile.ZipInfo, name: str) -> bytearray:
    """The member's bytes, inflated chunk by chunk into a buffer of its declared size."""
    buf = bytearray(info.file_size)
    view = memoryview(buf)
    got = 0
    with zf.open(info) as member:
        fh = cast(zipfile.ZipExtFile, member)
        while True:
            n = fh.readinto(view[got:]) if got < len(buf) else len(fh.read(1))
            if not n:
                break
            if got >= len(buf):
                raise ParseError(name, None, f"member {info.filename!r} inflates to more than the "
                                             f"{info.file_size} bytes it declares")
            got += n
    if got != len(buf):
        raise ParseError(name, None, f"member {info.filename!r} is truncated ({got} of {info.file_size} bytes)")
    return buf


def _array(buf: bytearray, member: str, name: str) -> np.ndarray:
    """The ``.npy`` array in ``buf`` (a view of it), once its header agrees with its data."""
    head = io.BytesIO(bytes(buf[:_HEADER_BYTES]))
    try:
        version = np.lib.format.read_magic(head)
        reader = _NPY_VERSIONS.get(version)
        if reader is None:
            raise ParseError(name, None, f"member {member!r}: .npy format version {version} is not supported")
        shape, fortran, dtype = reader(head)
    except ValueError as exc:
        raise ParseError(name, None, f"member {member!r} is not a .npy array ({exc})") from None
    if dtype.hasobject:
        raise ParseError(name, None, f"member {member!r} holds Python objects, which would be unpickled; "
                                     "posecrb result files hold numbers and text only")
    count = math.prod(shape)
    offset = head.tell()
    if count * dtype.itemsize != len(buf) - offset:
        raise ParseError(name, None, f"member {member!r}: its header declares {count * dtype.itemsize} bytes "
                                     f"of data, the member holds {len(buf) - offset}")
    flat = np.frombuffer(buf, dtype=dtype, count=count, offset=offset)
    return flat.reshape(shape, order="F" if fortran else "C")


def read_npz(path: str | os.PathLike, *, max_bytes: int | None = None) -> dict[str, np.ndarray]:
    """The arrays of the ``.npz`` archive ``path`` by member name (without ``.npy``), read with the
    caps of the module docstring; ``max_bytes`` (default ``archive_limit()``) bounds both the
    archive and the total of its inflated members. Raises ``ParseError``."""
    name = checked_name(path)
    limit = archive_limit() if max_bytes is None else max_bytes
    raw = read_regular_file(name, max_bytes=limit)
    try:
        zf = zipfile.ZipFile(io.BytesIO(raw))
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        what = "an empty file" if not raw else f"{exc}".rstrip(".").lower()
        raise ParseError(name, None, f"not a .npz archive ({what})") from None
    with zf:
        infos = zf.infolist()
        declared = sum(i.file_size for i in infos)
        if declared > limit:
            raise too_large(name, f"{declared} (inflated)", limit, ARCHIVE_EXPANSION)
        out: dict[str, np.ndarray] = {}
        for info in infos:
            key = info.filename.removesuffix(".npy")
            if key == info.filename or key in out:
                raise ParseError(name, None, f"member {info.filename!r} is not one .npy array of a .npz archive")
            try:
                buf = _inflate(zf, info, name)
            except (zipfile.BadZipFile, zlib.error, EOFError, OSError, NotImplementedError,
                    RuntimeError) as exc:   # corrupt data, CRC, unsupported method, encryption
                raise ParseError(name, None, f"member {info.filename!r} cannot be read ({exc})") from None
            out[key] = _array(buf, info.filename, name)
    return out


__all__ = ["ARCHIVE_EXPANSION", "archive_limit", "read_npz"]
