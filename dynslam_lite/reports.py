"""Writing tables to ``reports/``: Markdown + CSV, stable names, all-or-nothing updates."""
from __future__ import annotations

import ast
import csv
import hashlib
import io
import json
import math
import os
import shutil
import signal
import tempfile
import time
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


def write_table(root: str | Path, rel_stem: str, title: str, header, rows, notes: str = "") -> None:
    """Write ``root/rel_stem``.md (title, table, notes) and ``root/rel_stem``.csv."""
    md = f"# {title}\n\n" + markdown_table(header, rows)
    if notes:
        md += "\n" + notes.strip() + "\n"
    csv_text = csv_table(header, rows)
    path = Path(root) / rel_stem
    path.parent.mkdir(parents=True, exist_ok=True)
    path.with_suffix(".md").write_text(md, encoding="utf-8")
    path.with_suffix(".csv").write_text(csv_text, encoding="utf-8")


# what the committed reports depend on: the package's code (download.py aside) and the notebooks
FINGERPRINTED = ("dynslam_lite/**/*.py", "notebooks/*.ipynb", "notebooks/reproduce.yaml")


def _parse(source: str, attempts: int = 8) -> ast.Module:
    """``ast.parse``, tried again when CPython 3.11 reports "AST constructor recursion depth
    mismatch": its AST constructor keeps that depth per interpreter, not per thread, so a parse in
    another thread of the process (a Dask scheduler's, a library's) can break ours when a garbage
    collection hands over the GIL midway (python/cpython#106905). Waits 10 ms, then twice as
    long each time (1.3 s in all)."""
    for k in range(attempts - 1):
        try:
            return ast.parse(source)
        except SystemError:
            time.sleep(0.01 * 2**k)
    return ast.parse(source)


def _code_only(source: str) -> str:
    """Python source as its syntax tree without docstrings: comments, docstrings, blank lines
    and line breaks do not change it. Source that does not parse is taken as it is."""
    try:
        tree = _parse(source)
    except SyntaxError:
        return source
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                and body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree, annotate_fields=False)


def _meaning(path: Path) -> str:
    """What of a fingerprinted file can change the reports: Python code without comments and
    docstrings; a notebook's code cells (not its Markdown); the registry's data (not comments)."""
    text = path.read_text(encoding="utf-8")
    if path.suffix == ".py":
        return _code_only(text)
    if path.suffix == ".ipynb":
        cells = json.loads(text)["cells"]
        return "\0".join(_code_only("".join(c["source"])) for c in cells if c["cell_type"] == "code")
    import yaml

    return json.dumps(yaml.safe_load(text), sort_keys=True)


def code_fingerprint(repo: str | Path, exclude: set[str] = frozenset({"dynslam_lite/download.py"}),
                     patterns: tuple[str, ...] = FINGERPRINTED) -> str:
    """sha256 over what produces the reports (``patterns`` less ``exclude``, by relative path): a
    comment, docstring or Markdown edit keeps it, any change of code or parameters changes it."""
    repo = Path(repo)
    h = hashlib.sha256()
    files = sorted({p for pattern in patterns for p in repo.glob(pattern)} - {repo / e for e in exclude})
    for path in files:
        h.update(path.relative_to(repo).as_posix().encode() + b"\0" + _meaning(path).encode() + b"\0")
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

    def adopt_all(self) -> None:
        """Take every file written straight into the temporary folder (figures, notebooks)."""
        known = set(self.files)
        for path in sorted(self.tmp.rglob("*")):
            rel = path.relative_to(self.tmp)
            if path.is_file() and rel not in known:
                self.files.append(rel)

    def commit(self) -> list[Path]:
        """Move every file into place; Ctrl-C and SIGTERM wait until all are moved (a second
        or so), so reports/ never holds half of a run."""
        out = []
        blocked = {signal.SIGINT, signal.SIGTERM}
        old = signal.pthread_sigmask(signal.SIG_BLOCK, blocked)
        try:
            for rel in self.files:
                dest = self.root / rel
                dest.parent.mkdir(parents=True, exist_ok=True)
                os.replace(self.tmp / rel, dest)
                out.append(dest)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
        shutil.rmtree(self.tmp, ignore_errors=True)
        return out

    def abort(self) -> None:
        shutil.rmtree(self.tmp, ignore_errors=True)
