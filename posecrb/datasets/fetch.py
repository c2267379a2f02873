"""Download manifest datasets into the user cache, verified before they become visible.

Guarantees: the bytes go to a temporary file in the destination directory; the
checksum (sha256, or the git blob id where only that is known) is checked BEFORE an
atomic ``os.replace`` onto the final name; a file that already verifies is never
overwritten; a bad checksum or an interrupted download leaves no file behind and
raises ``FetchError`` (exit 1). Downloads are bounded: ``timeout`` per connection and
read, an overall ``deadline`` (a server trickling one byte at a time never trips the
read timeout), and a size cap, the manifest's size of the file (``MAX_UNKNOWN_SIZE``
where the manifest has none): a larger response is aborted as soon as it exceeds it.
On SIGTERM the CLI raises ``posecrb.cli.signals.Terminated``, so the temporary is removed
then too.
"""
from __future__ import annotations

import http.client
import logging
import os
import socket
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from .._version import __version__
from ..core.errors import PosecrbError
from ..core.outputs import atomic_write, make_output_dir
from .manifest import DatasetEntry, Manifest, load_manifest, verify_file
from .search import cache_dir, locate

log = logging.getLogger("posecrb")

Progress = Callable[[int, "int | None"], None]   # (bytes so far, total bytes or None)
_CHUNK = 1 << 16
DEFAULT_DEADLINE = 600.0            # seconds, per file
MAX_UNKNOWN_SIZE = 256 * 1024 ** 2  # cap for manifest entries without a size (grid3D, rim)
PROBE_TIMEOUT = 3.0                 # seconds: an offline machine must not hold `make run` for long


class FetchError(PosecrbError):
    """A download failed or did not verify; nothing was written."""


@dataclass(frozen=True)
class FetchResult:
    name: str
    path: Path
    status: str          # "downloaded" | "present" | "failed" | "offline" (fetch_many)
    nbytes: int
    algorithm: str
    digest: str
    url: str | None = None
    error: str | None = None   # set by fetch_many for a failed dataset (status "failed")

    def row(self) -> dict:
        return {"name": self.name, "status": self.status, "bytes": self.nbytes,
                "checksum": f"{self.algorithm}:{self.digest}" if self.digest else None,
                "path": str(self.path) if self.path else None, "error": self.error}


def target_path(entry: DatasetEntry, dest: str | os.PathLike | None = None) -> Path:
    """Where ``fetch`` puts ``entry``: ``dest`` (default the user cache) / subdir / file, never
    outside ``dest`` (the manifest's paths are plain names, ``posecrb.datasets.manifest``)."""
    root = Path(dest if dest is not None else cache_dir())
    target = root / entry.relpath
    inside = os.path.normpath(os.path.abspath(target))
    if os.path.commonpath([inside, os.path.normpath(os.path.abspath(root))]) != os.path.normpath(
            os.path.abspath(root)):
        raise FetchError(f"{entry.name}: manifest path {entry.relpath!r} leaves the destination {root}")
    return target


def _check_url(url: str, allow_http: bool) -> None:
    scheme = urllib.parse.urlsplit(url).scheme
    if scheme != "https" and not (allow_http and scheme == "http"):
        raise FetchError(f"refusing to download from {url!r}: only https:// URLs "
                         "(http:// only as an explicit override)")


def size_cap(entry: DatasetEntry) -> int:
    """Largest response accepted for ``entry``: its manifest size, else ``MAX_UNKNOWN_SIZE``."""
    return int(entry.size) if entry.size else MAX_UNKNOWN_SIZE


def _download(url: str, fh: IO[bytes], progress: Progress | None, timeout: float, deadline: float | None = None,
              max_bytes: int | None = None) -> int:
    """Stream ``url`` into ``fh``; raises FetchError unless every announced byte arrived within
    ``deadline`` seconds and no more than ``max_bytes`` came.

    The deadline bounds everything after the name lookup: the connection and the response
    headers wait at most ``min(timeout, deadline)``, and before every read the socket's timeout is
    lowered to the time left, so a server that stalls or trickles cannot hold the download past
    it (``read1`` returns whatever has arrived; ``read(n)`` would wait for n bytes).
    """
    req = urllib.request.Request(url, headers={"User-Agent": f"posecrb/{__version__}"})
    start = time.monotonic()
    limit = None if deadline is None else start + deadline

    def left() -> float:
        return timeout if limit is None else max(min(timeout, limit - time.monotonic()), 1e-3)

    def past_deadline() -> bool:
        return limit is not None and time.monotonic() >= limit

    done = 0
    try:
        with urllib.request.urlopen(req, timeout=left()) as resp:
            sock = _socket_of(resp)
            length = resp.headers.get("Content-Length")
            total = int(length) if length and length.isdigit() else None
            if max_bytes is not None and total is not None and total > max_bytes:
                raise FetchError(f"{url}: the server announces {total} bytes, more than the expected "
                                 f"{max_bytes}; not downloaded")
            if progress:
                progress(0, total)
            while True:
                if past_deadline():
                    raise FetchError(f"download from {url} exceeded the deadline of {deadline:g} s "
                                     f"({done} bytes received); aborted")
                if sock is not None:
                    sock.settimeout(left())
                chunk = resp.read1(_CHUNK)
                if not chunk:
                    break
                done += len(chunk)
                if max_bytes is not None and done > max_bytes:
                    raise FetchError(f"download from {url} exceeds the expected size of {max_bytes} bytes; "
                                     "aborted")
                fh.write(chunk)
                if progress:
                    progress(done, total)
    except urllib.error.HTTPError as exc:
        raise FetchError(f"{url}: HTTP {exc.code} {exc.reason}") from None
    except (urllib.error.URLError, http.client.HTTPException, OSError) as exc:
        if past_deadline():
            raise FetchError(f"download from {url} exceeded the deadline of {deadline:g} s "
                             f"({done} bytes received); aborted") from None
        if isinstance(exc, urllib.error.URLError):
            raise FetchError(f"cannot reach {url}: {exc.reason}") from None
        raise FetchError(f"download from {url} interrupted: {type(exc).__name__}: {exc}") from None
    # http.client returns a short read instead of raising when the peer closes early.
    if total is not None and done != total:
        raise FetchError(f"download from {url} interrupted: got {done} of {total} bytes")
    return done


def _socket_of(resp: object) -> socket.socket | None:
    """The socket under an ``http.client.HTTPResponse`` (None where the layout differs)."""
    raw = getattr(getattr(resp, "fp", None), "raw", None)
    sock = getattr(raw, "_sock", None)
    return sock if isinstance(sock, socket.socket) else None


def present(entry: DatasetEntry, *, dest: str | os.PathLike | None = None,
            data_dir: str | os.PathLike | None = None) -> FetchResult | None:
    """The verified copy of ``entry`` that makes a download unnecessary, or None.

    Candidates: the download target, and without ``dest`` also the first file of that name on
    the search path. A target that exists but does not verify is reported (it will be replaced).
    """
    target = target_path(entry, dest)
    algo, expected = entry.checksum
    candidates = [target]
    if dest is None:
        on_path = locate(entry, data_dir)
        if on_path is not None:
            candidates.append(on_path)
    for cand in candidates:
        if cand.is_file():
            v = verify_file(entry, cand)
            if v.ok:
                return FetchResult(entry.name, cand, "present", cand.stat().st_size, algo, expected)
            if cand == target:
                log.warning("%s: existing file does not match the manifest (%s %s); "
                            "it will be replaced by a verified download", cand, algo, v.actual)
    return None


def probe(url: str, timeout: float = PROBE_TIMEOUT) -> str | None:
    """None if the server of ``url`` answers an HTTPS HEAD request within ``timeout`` seconds,
    else why not (no name resolution, refused, no answer in time).

    Any HTTP answer, even an error status, proves the network works. The request runs in a
    daemon thread so that a hanging name lookup (which no socket timeout bounds) cannot hold
    the caller longer than ``timeout``.
    """
    result: list[str | None] = []

    def ask() -> None:
        req = urllib.request.Request(url, method="HEAD", headers={"User-Agent": f"posecrb/{__version__}"})
        try:
            with urllib.request.urlopen(req, timeout=timeout):
                result.append(None)
        except urllib.error.HTTPError:
            result.append(None)
        except urllib.error.URLError as exc:
            reason = exc.reason
            result.append(getattr(reason, "strerror", None) or str(reason))
        except (http.client.HTTPException, OSError) as exc:
            result.append(f"{type(exc).__name__}: {exc}")

    thread = threading.Thread(target=ask, name="posecrb-probe", daemon=True)
    thread.start()
    thread.join(timeout)
    if not result:
        return f"no answer within {timeout:g} s"
    return result[0]


def fetch(name: str | DatasetEntry, *, dest: str | os.PathLike | None = None, url: str | None = None,
          manifest: Manifest | None = None, progress: Progress | None = None, timeout: float = 60.0,
          data_dir: str | os.PathLike | None = None, deadline: float | None = DEFAULT_DEADLINE,
          max_bytes: int | None = None) -> FetchResult:
    """Download one manifest dataset and verify it.

    ``dest``: directory (default ``posecrb.datasets.search.cache_dir()``); the file lands in
    ``dest/<subdir>/<file>`` (TORO files under ``toro/``).
    ``url`` overrides the manifest URL (mirrors, tests); only an override may be
    plain ``http://``. Without ``dest``, a verified copy anywhere on the search path
    (``--data-dir``, $POSECRB_DATA, ...) counts as present and nothing is downloaded.
    ``deadline``: overall seconds for the download (None: no limit); ``max_bytes``: size
    cap (default ``size_cap(entry)``).
    """
    entry = name if isinstance(name, DatasetEntry) else (manifest or load_manifest()).get(name)
    found = present(entry, dest=dest, data_dir=data_dir)
    if found is not None:
        return found
    return _download_verified(entry, dest, url, progress, timeout, deadline, max_bytes)


def _download_verified(entry: DatasetEntry, dest: str | os.PathLike | None, url: str | None,
                       progress: Progress | None, timeout: float, deadline: float | None = DEFAULT_DEADLINE,
                       max_bytes: int | None = None) -> FetchResult:
    """The download half of ``fetch`` (the caller checked that no verified copy exists)."""
    target = target_path(entry, dest)
    algo, expected = entry.checksum

    src = url or entry.url
    _check_url(src, allow_http=url is not None)
    root = make_output_dir(dest if dest is not None else cache_dir(), parents=dest is None)
    if target.parent != root:
        make_output_dir(target.parent)
    nbytes = 0

    def check(tmp: Path) -> None:
        v = verify_file(entry, tmp)
        if not v.ok:
            raise FetchError(
                f"{entry.name}: checksum mismatch for the download from {src} "
                f"({algo} expected {expected}, got {v.actual}, {nbytes} bytes); the download was discarded")
        # Another process may have completed the same fetch meanwhile: keep its verified file.
        if target.is_file() and verify_file(entry, target).ok:
            raise _AlreadyPresent

    # atomic_write: .NAME.<random>.part beside the target, fsynced, verified by `check`, renamed;
    # any failure, KeyboardInterrupt and Terminated (SIGTERM) included, removes it.
    try:
        with atomic_write(target, "wb", suffix=".part", before_replace=check) as fh:
            nbytes = _download(src, fh, progress, timeout, deadline,
                               size_cap(entry) if max_bytes is None else max_bytes)
    except _AlreadyPresent:
        return FetchResult(entry.name, target, "present", target.stat().st_size, algo, expected, src)
    log.info("%s: %d bytes from %s verified (%s) -> %s", entry.name, nbytes, src, algo, target)
    return FetchResult(entry.name, target, "downloaded", nbytes, algo, expected, src)


class _AlreadyPresent(Exception):
    """Raised inside the write when a verified copy appeared meanwhile (the download is dropped)."""


def fetch_many(names: Iterable[str | DatasetEntry], *, dest: str | os.PathLike | None = None,
               manifest: Manifest | None = None,
               progress_factory: Callable[[DatasetEntry], Progress | None] | None = None,
               timeout: float = 60.0, data_dir: str | os.PathLike | None = None,
               deadline: float | None = DEFAULT_DEADLINE, probe_timeout: float | None = None) -> list[FetchResult]:
    """``fetch`` each dataset; a failure is recorded (status ``failed``) and the others continue.

    With ``probe_timeout``, each server that has something to download is first probed
    (``probe``) for at most that many seconds; the datasets of a server that does not answer
    get status ``offline`` (``error`` says why) and are not attempted, so an offline machine
    learns so in seconds instead of one long timeout per file.
    """
    manifest = manifest or load_manifest()
    entries = [name if isinstance(name, DatasetEntry) else manifest.get(name) for name in names]
    have = {e.name: present(e, dest=dest, data_dir=data_dir) for e in entries}
    reason_by_host: dict[str, str | None] = {}
    if probe_timeout is not None:
        for e in entries:
            host = urllib.parse.urlsplit(e.url).netloc
            if have[e.name] is None and host not in reason_by_host:
                reason_by_host[host] = probe(e.url, probe_timeout)
    out: list[FetchResult] = []
    for entry in entries:
        algo, expected = entry.checksum
        host = urllib.parse.urlsplit(entry.url).netloc
        if (found := have[entry.name]) is not None:
            out.append(found)
        elif reason_by_host.get(host):
            out.append(FetchResult(entry.name, target_path(entry, dest), "offline", 0, algo, expected,
                                   entry.url, f"{host}: {reason_by_host[host]}"))
        else:
            try:
                out.append(_download_verified(entry, dest, None,
                                              progress_factory(entry) if progress_factory else None, timeout,
                                              deadline))
            except FetchError as exc:
                out.append(FetchResult(entry.name, target_path(entry, dest), "failed", 0, algo, expected,
                                       entry.url, str(exc)))
    return out
