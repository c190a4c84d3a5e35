"""Writing tables to ``reports/``: Markdown + CSV, stable names, all-or-nothing updates."""
from __future__ import annotations

import csv
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
        md = f"# {title}\n\n" + markdown_table(header, rows, digits)
        if notes:
            md += "\n" + notes.strip() + "\n"
        self.write_text(rel_stem + ".md", md)
        self.write_text(rel_stem + ".csv", csv_table(header, rows))

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
