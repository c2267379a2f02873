"""fetch against a local HTTP server on 127.0.0.1 (no external network): the ``server`` fixture of
tests/fileserver.py, serving copies of real files from $POSECRB_DATA, some of them broken on purpose."""
from __future__ import annotations

import hashlib
import http.server
import shutil
import threading
from pathlib import Path

import pytest

from posecrb.cli import main
from posecrb.datasets.fetch import FetchError, fetch, fetch_many, target_path
from posecrb.datasets.manifest import load_manifest

pytestmark = pytest.mark.usefixtures("isolated_cache")   # every test: no real cache or $POSECRB_DATA






def files_in(d: Path) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in d.rglob("*") if p.is_file()) if d.exists() else []


def test_download_verifies_and_lands_atomically(server, tmp_path, shared_datasets):
    url, requests, root = server
    dest = tmp_path / "dest"
    seen = []
    res = fetch("intel", url=f"{url}/intel.g2o", dest=dest, progress=lambda done, total: seen.append((done, total)))
    original = (shared_datasets / "intel.g2o").read_bytes()
    assert res.status == "downloaded" and res.path == dest / "intel.g2o" and res.nbytes == len(original)
    assert res.path.read_bytes() == original
    assert files_in(dest) == ["intel.g2o"]                      # no temporary file left
    assert seen[0] == (0, len(original)) and seen[-1] == (len(original), len(original)) and len(seen) > 2
    assert res.path.stat().st_mode & 0o044                      # readable by others, not mkstemp's 0600


def test_toro_file_goes_to_toro_subdir(server, tmp_path):
    url, _, _ = server
    res = fetch("w100", url=f"{url}/w100.graph", dest=tmp_path / "dest")
    assert res.path == tmp_path / "dest" / "toro" / "w100.graph"
    assert hashlib.sha256(res.path.read_bytes()).hexdigest() == load_manifest().get("w100").sha256


def test_default_destination_is_the_user_cache(server, tmp_path, monkeypatch):
    url, _, _ = server
    monkeypatch.chdir(tmp_path)   # ./datasets relative to cwd does not exist here
    entry = load_manifest().get("tinyGrid3D")
    res = fetch(entry, url=f"{url}/tinyGrid3D.g2o", data_dir=tmp_path / "nothing")
    # A verified copy may be found on the search path ($POSECRB_DATA);
    # otherwise the file lands in $XDG_CACHE_HOME/posecrb.
    if res.status == "downloaded":
        assert res.path == tmp_path / "xdg" / "posecrb" / "tinyGrid3D.g2o"
    else:
        assert res.status == "present" and res.path.name == "tinyGrid3D.g2o"
    assert target_path(entry) == tmp_path / "xdg" / "posecrb" / "tinyGrid3D.g2o"


def test_bad_checksum_is_rejected_and_leaves_no_file(server, tmp_path):
    url, _, _ = server
    dest = tmp_path / "dest"
    with pytest.raises(FetchError, match="checksum mismatch.*discarded"):
        fetch("tinyGrid3D", url=f"{url}/bad/tinyGrid3D.g2o", dest=dest)
    assert files_in(dest) == []


@pytest.mark.parametrize("mode", ["cut", "cut-nolength"])
def test_interrupted_download_leaves_no_file(server, tmp_path, mode):
    url, _, _ = server
    dest = tmp_path / "dest"
    with pytest.raises(FetchError, match="interrupted|checksum mismatch"):
        fetch("intel", url=f"{url}/{mode}/intel.g2o", dest=dest)
    assert files_in(dest) == []


def test_interrupted_with_length_says_interrupted(server, tmp_path):
    url, _, _ = server
    with pytest.raises(FetchError, match=r"interrupted: got \d+ of \d+ bytes"):
        fetch("intel", url=f"{url}/cut/intel.g2o", dest=tmp_path / "dest")


def test_http_error_leaves_no_file(server, tmp_path):
    url, _, _ = server
    with pytest.raises(FetchError, match="HTTP 404"):
        fetch("intel", url=f"{url}/nothing/here.g2o", dest=tmp_path / "dest")
    assert files_in(tmp_path / "dest") == []


def test_verified_file_is_never_overwritten_nor_downloaded(server, tmp_path, shared_datasets):
    url, requests, _ = server
    dest = tmp_path / "dest"
    dest.mkdir()
    shutil.copy(shared_datasets / "tinyGrid3D.g2o", dest / "tinyGrid3D.g2o")
    before = (dest / "tinyGrid3D.g2o").stat()
    res = fetch("tinyGrid3D", url=f"{url}/bad/tinyGrid3D.g2o", dest=dest)
    after = (dest / "tinyGrid3D.g2o").stat()
    assert res.status == "present" and requests == []
    assert (before.st_ino, before.st_mtime_ns) == (after.st_ino, after.st_mtime_ns)


def test_corrupt_existing_file_is_replaced_by_a_verified_download(server, tmp_path, shared_datasets):
    url, _, _ = server
    dest = tmp_path / "dest"
    dest.mkdir()
    (dest / "tinyGrid3D.g2o").write_text("garbage\n")
    res = fetch("tinyGrid3D", url=f"{url}/tinyGrid3D.g2o", dest=dest)
    assert res.status == "downloaded"
    assert (dest / "tinyGrid3D.g2o").read_bytes() == (shared_datasets / "tinyGrid3D.g2o").read_bytes()


def test_corrupt_existing_file_is_kept_when_the_download_is_bad(server, tmp_path):
    url, _, _ = server
    dest = tmp_path / "dest"
    dest.mkdir()
    (dest / "tinyGrid3D.g2o").write_text("garbage\n")
    with pytest.raises(FetchError):
        fetch("tinyGrid3D", url=f"{url}/bad/tinyGrid3D.g2o", dest=dest)
    assert files_in(dest) == ["tinyGrid3D.g2o"] and (dest / "tinyGrid3D.g2o").read_text() == "garbage\n"


def test_only_https_or_explicit_http(tmp_path):
    with pytest.raises(FetchError, match="only https"):
        fetch("tinyGrid3D", url="ftp://127.0.0.1/tinyGrid3D.g2o", dest=tmp_path / "dest")
    assert all(e.url.startswith("https://") for e in load_manifest())


def test_fetch_many_continues_after_a_failure(server, tmp_path, monkeypatch):
    url, _, _ = server
    man = load_manifest()
    good, bad = man.get("tinyGrid3D"), man.get("intel")
    from dataclasses import replace

    entries = [replace(bad, url="https://127.0.0.1:1/never"), good]
    monkeypatch.setattr("posecrb.datasets.fetch._check_url", lambda u, allow_http: None)
    entries[1] = replace(good, url=f"{url}/tinyGrid3D.g2o")
    res = fetch_many(entries, dest=tmp_path / "dest", manifest=man, timeout=5)
    assert [r.status for r in res] == ["failed", "downloaded"] and res[0].error
    assert files_in(tmp_path / "dest") == ["tinyGrid3D.g2o"]


def test_cli_fetch_success_and_failure(server, tmp_path, capsys):
    url, _, _ = server
    dest = tmp_path / "dest"
    assert main(["-q", "datasets", "fetch", "tinyGrid3D", "--url", f"{url}/tinyGrid3D.g2o",
                 "--dest", str(dest), "--format", "csv"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "name,status,bytes,path" and out[1].startswith("tinyGrid3D,downloaded,4106,")
    assert main(["-q", "datasets", "fetch", "intel", "--url", f"{url}/cut/intel.g2o", "--dest", str(dest)]) == 1
    assert "interrupted" in capsys.readouterr().err
    assert files_in(dest) == ["tinyGrid3D.g2o"]
    assert main(["datasets", "fetch", "--dest", str(dest)]) == 2          # neither NAME nor --all
    assert main(["datasets", "fetch", "--all", "--url", url]) == 2        # --url needs one NAME


# ---------------------------------------------------------------- misbehaving servers: bounded in time and size
class _HostileHandler(http.server.BaseHTTPRequestHandler):
    """/drip: announces 1000 bytes and sends one every 0.1 s; /stall: one byte, then nothing for 30 s;
    /slow-headers: no answer for 30 s; /announce-huge: announces 1 GB;
    /stream-huge: no Content-Length, streams zeros until the client hangs up (at most 64 MiB)."""

    def log_message(self, *args) -> None:
        pass

    def do_GET(self) -> None:
        import time

        if self.path.startswith("/slow-headers"):
            time.sleep(30)
            return
        self.send_response(200)
        self.send_header("Content-Type", "application/octet-stream")
        try:
            if self.path.startswith("/drip"):
                self.send_header("Content-Length", "1000")
                self.end_headers()
                for _ in range(1000):
                    self.wfile.write(b"x")
                    self.wfile.flush()
                    time.sleep(0.1)
            elif self.path.startswith("/stall"):
                self.send_header("Content-Length", "1000")
                self.end_headers()
                self.wfile.write(b"x")
                self.wfile.flush()
                time.sleep(30)                      # then nothing: a stalled server
            elif self.path.startswith("/announce-huge"):
                self.send_header("Content-Length", str(10 ** 9))
                self.end_headers()
                self.wfile.write(b"\0" * 4096)
            else:
                self.end_headers()
                for _ in range(1024):
                    self.wfile.write(b"\0" * 65536)
        except (BrokenPipeError, ConnectionResetError):
            pass
        self.close_connection = True


@pytest.fixture
def hostile_server():
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _HostileHandler)
    httpd.daemon_threads = True
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join(5)


@pytest.mark.timeout(60)
def test_trickling_server_hits_the_overall_deadline(hostile_server, tmp_path):
    import time

    dest = tmp_path / "dest"
    t0 = time.monotonic()
    with pytest.raises(FetchError, match=r"exceeded the deadline of 1 s"):
        fetch("intel", url=f"{hostile_server}/drip/intel.g2o", dest=dest, timeout=5, deadline=1.0)
    assert time.monotonic() - t0 < 5          # the per-read timeout (5 s) never fires: a byte every 0.1 s
    assert files_in(dest) == []


@pytest.mark.timeout(60)
@pytest.mark.parametrize("path", ["stall", "slow-headers"])
def test_fetch_keeps_its_deadline_when_the_server_stalls(hostile_server, tmp_path, path):
    """A 2 s deadline took 30 s: one read (or the wait for the headers) could last the whole
    --timeout. Now every wait is bounded by the time left."""
    import time

    dest = tmp_path / "dest"
    t0 = time.monotonic()
    with pytest.raises(FetchError, match=r"exceeded the deadline of 1 s"):
        fetch("intel", url=f"{hostile_server}/{path}/intel.g2o", dest=dest, timeout=30, deadline=1.0)
    assert time.monotonic() - t0 < 3
    assert files_in(dest) == []


@pytest.mark.timeout(60)
@pytest.mark.parametrize("path, message", [("announce-huge", "announces 1000000000 bytes, more than the expected"),
                                           ("stream-huge", "exceeds the expected size of 307525 bytes")])
def test_response_larger_than_the_manifest_size_is_aborted(hostile_server, tmp_path, path, message):
    dest = tmp_path / "dest"
    assert load_manifest().get("intel").size == 307525
    with pytest.raises(FetchError, match=message):
        fetch("intel", url=f"{hostile_server}/{path}/intel.g2o", dest=dest, timeout=5)
    assert files_in(dest) == []


def test_size_cap_without_a_manifest_size():
    from dataclasses import replace

    from posecrb.datasets.fetch import MAX_UNKNOWN_SIZE, size_cap

    entry = load_manifest().get("intel")
    assert size_cap(entry) == entry.size
    assert size_cap(replace(entry, size=None)) == MAX_UNKNOWN_SIZE


@pytest.mark.timeout(120)
def test_sigterm_during_cli_fetch_removes_the_partial_file(hostile_server, tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    dest = tmp_path / "dest"
    repo = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(repo), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    proc = subprocess.Popen([sys.executable, "-m", "posecrb", "-q", "datasets", "fetch", "intel", "--url",
                             f"{hostile_server}/drip/intel.g2o", "--dest", str(dest), "--timeout", "5"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 60
        while not any(p.name.endswith(".part") for p in dest.glob(".*")) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert any(p.name.endswith(".part") for p in dest.glob(".*")), "the download never started"
        time.sleep(0.3)                                    # some bytes written
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "terminated" in err and "Traceback" not in err
    assert files_in(dest) == []


def test_cli_fetch_options_are_validated(tmp_path, capsys):
    for opt in ("--timeout", "--deadline"):
        for bad in ("nan", "inf", "-1", "0"):
            assert main(["datasets", "fetch", "intel", opt, bad, "--dest", str(tmp_path)]) == 2
            assert opt in capsys.readouterr().err
    f = tmp_path / "afile"
    f.write_text("")
    assert main(["datasets", "fetch", "intel", "--dest", str(f)]) == 2
    assert "--dest" in capsys.readouterr().err
    assert main(["datasets", "fetch", "intel", "--dest", str(f / "sub")]) == 2     # parent is a file
    assert "is not a directory" in capsys.readouterr().err


def test_probe_answers_and_refusals(server):
    url, _, _ = server
    from posecrb.datasets.fetch import probe

    assert probe(f"{url}/intel.g2o", timeout=5) is None
    assert probe(f"{url}/nothing/here.g2o", timeout=5) is None     # an HTTP error still proves the network
    assert probe("http://127.0.0.1:1/x", timeout=5)                  # refused: a reason


def test_probe_gives_up_after_its_timeout():
    """A server that accepts the connection but never answers must not hold the caller."""
    import socket
    import time

    from posecrb.datasets.fetch import probe

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)                                                  # the kernel accepts, nobody answers
        t0 = time.perf_counter()
        reason = probe(f"http://127.0.0.1:{s.getsockname()[1]}/x", timeout=0.3)
        elapsed = time.perf_counter() - t0
    assert reason and elapsed < 2.0


def test_fetch_many_offline_server_is_probed_once_and_not_attempted(tmp_path, monkeypatch):
    man = load_manifest()
    calls = []
    monkeypatch.setattr("posecrb.datasets.fetch.probe", lambda url, timeout: calls.append(url) or "simulated outage")
    res = fetch_many(["tinyGrid3D", "intel"], dest=tmp_path / "dest", manifest=man, probe_timeout=1.0)
    assert [r.status for r in res] == ["offline", "offline"]
    assert all("simulated outage" in r.error for r in res)
    assert len(calls) == 1                                           # one server, one probe
    assert files_in(tmp_path / "dest") == []


def test_fetch_many_present_files_need_no_probe(tmp_path, shared_datasets, monkeypatch):
    dest = tmp_path / "dest"
    dest.mkdir()
    shutil.copy(shared_datasets / "tinyGrid3D.g2o", dest / "tinyGrid3D.g2o")
    monkeypatch.setattr("posecrb.datasets.fetch.probe", lambda url, timeout: pytest.fail("probed although present"))
    res = fetch_many(["tinyGrid3D"], dest=dest, probe_timeout=1.0)
    assert [r.status for r in res] == ["present"]


def test_cli_offline_is_said_once_and_offline_ok_exits_zero(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("posecrb.datasets.fetch.probe", lambda url, timeout: "simulated outage")
    dest = tmp_path / "dest"
    assert main(["datasets", "fetch", "--all", "--dest", str(dest), "--format", "csv"]) == 1
    err = capsys.readouterr().err
    assert err.count("no network") == 1 and "simulated outage" in err
    assert main(["datasets", "fetch", "--all", "--offline-ok", "--dest", str(dest), "--format", "csv"]) == 0
    out, err = capsys.readouterr()
    assert err.count("no network") == 1 and "error" not in err
    assert {r.split(",")[1] for r in out.splitlines()[1:]} == {"offline"}
    assert main(["datasets", "fetch", "rim", "--offline-ok", "--dest", str(dest)]) == 0
    assert main(["datasets", "fetch", "rim", "--dest", str(dest)]) == 1
    assert files_in(dest) == []
