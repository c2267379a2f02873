"""A local HTTP server on 127.0.0.1 serving copies of real datasets (no external network): the fixture
``server`` of the fetch and output tests, registered in conftest.py.

Special path prefixes make it misbehave: ``/cut/`` announces the full Content-Length and closes after half the
bytes, ``/cut-nolength/`` does the same without a Content-Length, ``/missing`` answers 404, ``/bad/`` serves a
copy with one flipped bit.
"""
from __future__ import annotations

import http.server
import shutil
import threading
from pathlib import Path

import pytest


class _Handler(http.server.BaseHTTPRequestHandler):
    root: Path
    requests: list

    def log_message(self, *args) -> None:  # keep pytest output clean
        pass

    def do_GET(self) -> None:
        self.requests.append(self.path)
        mode, _, name = self.path.lstrip("/").rpartition("/")
        f = self.root / name
        if not f.is_file():
            self.send_error(404, "no such file")
            return
        data = f.read_bytes()
        self.send_response(200)
        self.send_header("Content-Type", "application/octet-stream")
        if mode != "cut-nolength":
            self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        if mode.startswith("cut"):
            self.wfile.write(data[: len(data) // 2])
            self.wfile.flush()
            self.close_connection = True
            return
        self.wfile.write(data)


@pytest.fixture
def server(tmp_path, shared_datasets):
    root = tmp_path / "srv"
    root.mkdir()
    for name in ("tinyGrid3D.g2o", "intel.g2o"):
        shutil.copy(shared_datasets / name, root / name)
    shutil.copy(shared_datasets / "toro" / "w100.graph", root / "w100.graph")
    bad = bytearray((root / "tinyGrid3D.g2o").read_bytes())
    bad[10] ^= 1
    (root / "bad").mkdir()
    (root / "bad" / "tinyGrid3D.g2o").write_bytes(bytes(bad))
    handler = type("H", (_Handler,), {"root": root, "requests": []})

    class Routed(handler):
        def do_GET(self):
            if self.path.startswith("/bad/"):
                self.root = root / "bad"
                self.path = "/" + self.path.rsplit("/", 1)[1]
            super().do_GET()

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Routed)
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}", handler.requests, root
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join(5)
