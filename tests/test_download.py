"""``download`` against archives served from 127.0.0.1: fetch + verify + unpack, a broken transfer
resumed with a Range request, a server that ignores Range, a corrupt archive, unknown names."""
import http.server
import io
import tarfile
import threading
import zipfile
from pathlib import Path

import pytest

from dynslam_lite.cli import main
from dynslam_lite.download import ARCHIVES, DownloadError, download
from dynslam_lite.io import open_sequence
from dynslam_lite.synth import generate


class _Server(http.server.ThreadingHTTPServer):
    files: dict[str, bytes]
    cut_at: int | None = None  # close the connection after this many body bytes (once)
    ranges = True
    requests: list


class _Handler(http.server.BaseHTTPRequestHandler):
    def log_message(self, *args):
        pass

    def do_GET(self):
        srv = self.server
        srv.requests.append((self.path, self.headers.get("Range")))
        body = srv.files.get(self.path.lstrip("/"))
        if body is None:
            self.send_error(404)
            return
        start = 0
        rng = self.headers.get("Range")
        if rng and srv.ranges:
            start = int(rng.split("=")[1].split("-")[0])
            self.send_response(206)
            self.send_header("Content-Range", f"bytes {start}-{len(body) - 1}/{len(body)}")
        else:
            self.send_response(200)
        self.send_header("Content-Length", str(len(body) - start))
        self.end_headers()
        payload = body[start:]
        if srv.cut_at is not None:
            payload, srv.cut_at = payload[:srv.cut_at], None
            self.wfile.write(payload)
            self.wfile.flush()
            self.close_connection = True
            return
        self.wfile.write(payload)


@pytest.fixture(scope="module")
def archives(tmp_path_factory):
    """A tiny synthetic sequence packed as the TUM .tgz and the Bonn .zip would be."""
    root = tmp_path_factory.mktemp("src")
    tum, bonn = ARCHIVES["fr3_walking_xyz"], ARCHIVES["bonn_crowd"]
    generate(root / tum.folder, "walking_xyz", 4, seed=0)
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as t:
        t.add(root / tum.folder, arcname=tum.folder)
    zbuf = io.BytesIO()
    with zipfile.ZipFile(zbuf, "w") as z:
        for p in sorted((root / tum.folder).rglob("*")):
            z.write(p, Path(bonn.folder) / p.relative_to(root / tum.folder))
    return {tum.filename: buf.getvalue(), bonn.filename: zbuf.getvalue()}


@pytest.fixture
def server(archives):
    srv = _Server(("127.0.0.1", 0), _Handler)
    srv.files, srv.requests = dict(archives), []
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    yield srv
    srv.shutdown()
    srv.server_close()


def _url(srv):
    return f"http://127.0.0.1:{srv.server_address[1]}"


@pytest.mark.parametrize("name", ["fr3_walking_xyz", "bonn_crowd"])
def test_download_verifies_and_unpacks_a_readable_sequence(server, tmp_path, name):
    out = download(name, tmp_path, base_url=_url(server), progress=lambda s: None)
    assert out == tmp_path / ARCHIVES[name].folder
    assert len(open_sequence(out)) == 4
    assert not list(tmp_path.glob("*.part")) and not list(tmp_path.glob("*.tgz")) and not list(tmp_path.glob("*.zip"))
    n = len(server.requests)
    download(name, tmp_path, base_url=_url(server), progress=lambda s: None)  # cached: no transfer
    assert len(server.requests) == n


def test_broken_transfer_is_reported_and_resumed_with_range(server, tmp_path, archives):
    name = "fr3_walking_xyz"
    size = len(archives[ARCHIVES[name].filename])
    server.cut_at = size // 3
    with pytest.raises(DownloadError, match="run the same command again to resume"):
        download(name, tmp_path, base_url=_url(server), progress=lambda s: None)
    part = tmp_path / (ARCHIVES[name].filename + ".part")
    assert part.stat().st_size == size // 3
    assert not (tmp_path / ARCHIVES[name].folder).exists()
    assert main(["download", name, "--dest", str(tmp_path), "--base-url", _url(server)]) == 0
    assert server.requests[-1][1] == f"bytes={size // 3}-"
    assert len(open_sequence(tmp_path / ARCHIVES[name].folder)) == 4


def test_server_ignoring_range_restarts_from_zero(server, tmp_path, archives):
    name = "fr3_walking_xyz"
    part = tmp_path / (ARCHIVES[name].filename + ".part")
    part.write_bytes(b"stale bytes of an older attempt")
    server.ranges = False
    download(name, tmp_path, base_url=_url(server), progress=lambda s: None)
    assert len(open_sequence(tmp_path / ARCHIVES[name].folder)) == 4


def test_corrupt_archive_checksum_unknown_name_and_missing_file_are_clear_errors(server, tmp_path, archives, capsys):
    name = "fr3_walking_xyz"
    good = archives[ARCHIVES[name].filename]
    server.files[ARCHIVES[name].filename] = good[: len(good) // 2]  # truncated gzip, honest length
    with pytest.raises(DownloadError, match="not a readable archive"):
        download(name, tmp_path / "a", base_url=_url(server), progress=lambda s: None)
    server.files[ARCHIVES[name].filename] = good
    with pytest.raises(DownloadError, match="sha256"):
        download(name, tmp_path / "b", base_url=_url(server), sha256="0" * 64, progress=lambda s: None)
    assert main(["download", "fr9_nothing", "--dest", str(tmp_path)]) == 2
    assert "unknown sequence 'fr9_nothing'" in capsys.readouterr().err
    del server.files[ARCHIVES[name].filename]
    with pytest.raises(DownloadError, match="HTTP 404"):
        download(name, tmp_path / "c", base_url=_url(server), progress=lambda s: None)
