"""Writing tables to ``reports/``: Markdown + CSV, stable names, all-or-nothing updates."""
from __future__ import annotations

import csv
import hashlib
import io
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Sequence


def fmt(value, digits: int = 4) -> str:
    """A table cell: numbers with fixed decimals, NaN/None as '-'."""
    if value is None:
        return "-"
    if isinstance(value, float):
        return "-" if math.isnan(value) else f"{value:.{digits}f}"
    return str(value)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence], digits: int = 4) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v, digits) for v in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def csv_table(header: Sequence[str], rows: Sequence[Sequence]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in row])
    return buf.getvalue()


def table_files(title: str, header, rows, notes: str = "", digits: int = 4) -> tuple[str, str]:
    """(Markdown with title, table and notes; CSV) of one results table."""
    md = f"# {title}\n\n" + markdown_table(header, rows, digits)
    if notes:
        md += "\n" + notes.strip() + "\n"
    return md, csv_table(header, rows)


def write_table(root: str | Path, rel_stem: str, title: str, header, rows, notes: str = "") -> None:
    """Write ``root/rel_stem``.md and .csv (see :func:`table_files`)."""
    md, csv_text = table_files(title, header, rows, notes)
    path = Path(root) / rel_stem
    path.parent.mkdir(parents=True, exist_ok=True)
    path.with_suffix(".md").write_text(md, encoding="utf-8")
    path.with_suffix(".csv").write_text(csv_text, encoding="utf-8")


# what the committed reports depend on: the package's code (download.py aside) and the notebooks
FINGERPRINTED = ("dynslam_lite/**/*.py", "notebooks/*.ipynb", "notebooks/reproduce.yaml")


def code_fingerprint(repo: str | Path) -> str:
    """sha256 over the files that produce the reports (:data:`FINGERPRINTED`), by relative path."""
    repo = Path(repo)
    h = hashlib.sha256()
    files = sorted({p for pattern in FINGERPRINTED for p in repo.glob(pattern)} - {repo / "dynslam_lite/download.py"})
    for path in files:
        h.update(path.relative_to(repo).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


class ReportWriter:
    """Collects report files in a temporary folder; :meth:`commit` moves them into place.

    A run that fails before ``commit`` leaves every file already in ``reports/`` untouched.
    Each file is replaced with ``os.replace`` (atomic on one file system).
    """

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(tempfile.mkdtemp(dir=self.root, prefix=".tmp-"))
        self.files: list[Path] = []

    def write_text(self, rel: str, text: str) -> Path:
        path = self.tmp / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        self.files.append(Path(rel))
        return path

    def table(self, rel_stem: str, title: str, header, rows, notes: str = "", digits: int = 4):
        """Write ``rel_stem``.md (title, table, notes) and ``rel_stem``.csv."""
        md, csv_text = table_files(title, header, rows, notes, digits)
        self.write_text(rel_stem + ".md", md)
        self.write_text(rel_stem + ".csv", csv_text)

    def adopt_all(self) -> None:
        """Take every file written straight into the temporary folder (figures, notebooks)."""
        known = set(self.files)
        for path in sorted(self.tmp.rglob("*")):
            rel = path.relative_to(self.tmp)
            if path.is_file() and rel not in known:
                self.files.append(rel)

    def commit(self) -> list[Path]:
        out = []
        for rel in self.files:
            dest = self.root / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            os.replace(self.tmp / rel, dest)
            out.append(dest)
        shutil.rmtree(self.tmp, ignore_errors=True)
        return out

    def abort(self) -> None:
        shutil.rmtree(self.tmp, ignore_errors=True)
