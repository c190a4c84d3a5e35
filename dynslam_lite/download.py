"""``python -m dynslam_lite download NAME...``: the papers' real sequences from their official archives.

Each archive is fetched into ``DEST/NAME.part`` (resumed with an HTTP ``Range`` request when a
partial file is there and the server honours it), verified, unpacked into ``DEST/`` and checked to
be a readable TUM-layout sequence. Verification: the byte count against the server's
``Content-Length``, the whole archive read back (a truncated gzip/zip fails there), every member
inside one top folder with no absolute or ``..`` paths, and ``open_sequence`` on the result. The
archives' sites publish no checksums, so none is compared; ``--sha256`` on the command line checks
one when you have it.
"""
from __future__ import annotations

import hashlib
import http.client
import shutil
import tarfile
import urllib.error
import urllib.request
import zipfile
from dataclasses import dataclass
from pathlib import Path

from .errors import UserError

TUM = "https://cvg.cit.tum.de/rgbd/dataset"
BONN = "https://www.ipb.uni-bonn.de/html/projects/rgbd_dynamic2019"


@dataclass(frozen=True)
class Archive:
    """One downloadable sequence: its folder name once unpacked and the official archive URL."""

    folder: str
    url: str

    @property
    def filename(self) -> str:
        return self.url.rsplit("/", 1)[1]


def _tum(fr: str, name: str) -> Archive:
    folder = f"rgbd_dataset_freiburg{fr}_{name}"
    return Archive(folder, f"{TUM}/freiburg{fr}/{folder}.tgz")


# short name -> archive: what papers A-C evaluate on, and the static desk used as a control
ARCHIVES: dict[str, Archive] = {
    **{f"fr3_{k}": _tum("3", k) for k in (
        "walking_xyz", "walking_static", "walking_rpy", "walking_halfsphere",
        "sitting_xyz", "sitting_static", "sitting_rpy", "sitting_halfsphere")},
    "fr2_desk_with_person": _tum("2", "desk_with_person"),
    "fr2_desk": _tum("2", "desk"),
    **{f"bonn_{k}": Archive(f"rgbd_bonn_{k}", f"{BONN}/rgbd_bonn_{k}.zip") for k in ("crowd", "crowd2", "crowd3")},
}


class DownloadError(UserError):
    """A transfer or verification failed; the message says what to do."""


def _fetch(url: str, part: Path, timeout: float, chunk: int = 1 << 20, progress=print) -> None:
    """Download ``url`` into ``part``, resuming from its current size when the server allows."""
    have = part.stat().st_size if part.exists() else 0
    req = urllib.request.Request(url, headers={"Range": f"bytes={have}-"} if have else {})
    try:
        resp = urllib.request.urlopen(req, timeout=timeout)
    except urllib.error.HTTPError as exc:
        if exc.code == 416 and have:  # nothing left to fetch: the part file is complete
            return
        raise DownloadError(f"{url}: HTTP {exc.code} {exc.reason}") from exc
    except (urllib.error.URLError, OSError) as exc:
        raise DownloadError(f"{url}: cannot connect ({exc})") from exc
    with resp:
        resumed = have and resp.status == 206
        if have and not resumed:
            progress(f"[download] {part.name}: server ignored the resume request; starting again")
            have = 0
        length = resp.headers.get("Content-Length")
        total = have + int(length) if length is not None else None
        got = have
        try:
            with open(part, "ab" if resumed else "wb") as f:
                while block := resp.read(chunk):
                    f.write(block)
                    got += len(block)
        except (OSError, http.client.HTTPException) as exc:  # reset, timeout, IncompleteRead
            raise DownloadError(
                f"{url}: transfer broke after {got} of {total or '?'} bytes ({type(exc).__name__}); "
                f"the partial file {part} is kept: run the same command again to resume") from exc
    if total is not None and got != total:
        raise DownloadError(f"{url}: transfer ended after {got} of {total} bytes; the partial file "
                            f"{part} is kept: run the same command again to resume")
    progress(f"[download] {part.name}: {got / 1e6:.1f} MB" + (" (resumed)" if resumed else ""))


def _members(archive: Path) -> list[str]:
    """Member names of a .tgz / .zip, reading the whole archive (detects truncation)."""
    try:
        if zipfile.is_zipfile(archive):
            with zipfile.ZipFile(archive) as z:
                bad = z.testzip()
                if bad is not None:
                    raise DownloadError(f"{archive}: corrupt member {bad}")
                return z.namelist()
        with tarfile.open(archive, "r:*") as t:
            return [m.name for m in t]  # iterating reads to the end of the stream
    except (tarfile.TarError, zipfile.BadZipFile, EOFError, OSError) as exc:
        raise DownloadError(f"{archive}: not a readable archive ({exc}); delete it and download again") from exc


def _unpack(archive: Path, dest: Path, folder: str) -> Path:
    names = _members(archive)
    unsafe = [n for n in names if n.startswith(("/", "\\")) or ".." in Path(n).parts]
    outside = [n for n in names if Path(n).parts and Path(n).parts[0] != folder]
    if unsafe or outside or not names:
        raise DownloadError(f"{archive}: expected every member under {folder}/, found "
                            f"{(unsafe + outside)[:3] or 'an empty archive'}")
    tmp = dest / f".{folder}.unpacking"
    shutil.rmtree(tmp, ignore_errors=True)
    if zipfile.is_zipfile(archive):
        with zipfile.ZipFile(archive) as z:
            z.extractall(tmp)
    else:
        with tarfile.open(archive, "r:*") as t:
            t.extractall(tmp, filter="data")
    target = dest / folder
    shutil.rmtree(target, ignore_errors=True)
    (tmp / folder).rename(target)
    shutil.rmtree(tmp, ignore_errors=True)
    return target


def download(name: str, dest: str | Path, base_url: str | None = None, sha256: str | None = None,
             timeout: float = 60.0, keep_archive: bool = False, progress=print) -> Path:
    """Fetch, verify and unpack one sequence; returns its folder (already there: no transfer).

    ``base_url`` replaces the official site (a mirror, or a local server in tests): the archive
    is then ``base_url/<archive file name>``.
    """
    from .io import SequenceError, open_sequence

    if name not in ARCHIVES:
        raise DownloadError(f"unknown sequence {name!r}; choose from: {', '.join(ARCHIVES)}")
    arc = ARCHIVES[name]
    dest = Path(dest)
    target = dest / arc.folder
    if (target / "rgb.txt").exists():
        progress(f"[download] {name}: already in {target}")
        return target
    dest.mkdir(parents=True, exist_ok=True)
    url = f"{base_url.rstrip('/')}/{arc.filename}" if base_url else arc.url
    archive = dest / arc.filename
    part = archive.with_name(archive.name + ".part")
    if not archive.exists():
        progress(f"[download] {name}: {url}")
        _fetch(url, part, timeout, progress=progress)
        if sha256:
            digest = hashlib.sha256(part.read_bytes()).hexdigest()
            if digest != sha256.lower():
                part.unlink()
                raise DownloadError(f"{url}: sha256 {digest} differs from the expected {sha256}; "
                                    "the download was deleted")
        part.rename(archive)
    target = _unpack(archive, dest, arc.folder)
    try:
        seq = open_sequence(target)
    except SequenceError as exc:
        raise DownloadError(f"{name}: unpacked into {target} but not a readable sequence: {exc}") from exc
    if not keep_archive:
        archive.unlink()
    progress(f"[download] {name}: {len(seq)} frames in {target}")
    return target
