import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from dynslam_lite.cli import main
from dynslam_lite.reports import code_fingerprint

from conftest import tiny_plan
from test_notebooks import FIGURES

ROOT = Path(__file__).resolve().parents[1]


def test_synth_run_evaluate_end_to_end(tmp_path, capsys):
    seq = tmp_path / "rgbd_synth"
    assert main(["synth", str(seq), "--scene", "walking_static", "--frames", "40", "--quiet"]) == 0
    traj, stats = tmp_path / "est.txt", tmp_path / "stats.json"
    assert main(["run", "static-dense", str(seq), "--out", str(traj), "--stats", str(stats),
                 "--frames", "35", "--set", "finest_level=2", "--quiet"]) == 0
    s = json.loads(stats.read_text())
    assert s["frames"] == 35 and s["failed_frames"] == [] and s["ms_per_frame"] > 0
    assert {"load", "align"} <= set(s["stages"]) and s["peak_mem_mib"] > 0
    assert s["params"]["finest_level"] == 2
    assert len(traj.read_text().splitlines()) == 36  # header + 35 poses
    every3 = tmp_path / "every3.txt"
    assert main(["run", "static-dense", str(seq), "--out", str(every3), "--stride", "3",
                 "--set", "finest_level=2", "--quiet"]) == 0
    stamps = [float(l.split()[0]) for l in every3.read_text().splitlines() if not l.startswith("#")]
    assert len(stamps) == 14 and stamps[1] - stamps[0] == pytest.approx(0.1, abs=0.01)  # 40 frames at 10 Hz
    capsys.readouterr()
    assert main(["evaluate", str(seq / "groundtruth.txt"), str(traj), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["matched_poses"] == 35 and out["ate_m"]["rmse"] < 0.5
    assert out["rpe_trans_m_per_s"]["count"] > 0
    capsys.readouterr()
    assert main(["bench", "--seq", str(seq), "--frames", "6", "--methods", "opencv-odometry", "static-orb",
                 "--repeat", "2"]) == 0
    out = capsys.readouterr().out
    rows = re.findall(r"^(\S+)\s+[\d.]+ ms/frame\s+([\d.]+)x opencv-odometry  \(([\d.]+)-([\d.]+)\)$", out, re.M)
    ratios = {m: tuple(map(float, r)) for m, *r in rows}
    assert set(ratios) == {"opencv-odometry", "static-orb"} and ratios["opencv-odometry"] == (1.0, 1.0, 1.0)
    lo, mid, hi = sorted(ratios["static-orb"])  # the median of two rounds lies within their range
    assert ratios["static-orb"] == (mid, lo, hi) and out.count("static-orb         total") == 1


def test_errors_name_the_problem(tmp_path, capsys):
    assert main(["run", "static-dense", str(tmp_path), "--out", str(tmp_path / "t.txt")]) == 2
    assert "rgb.txt: file not found" in capsys.readouterr().err
    assert main(["run", "static-dense", str(tmp_path), "--out", "x", "--set", "bogus"]) == 2
    capsys.readouterr()
    assert main(["bench", "--seq", str(tmp_path), "--repeat", "0"]) == 2
    assert "--repeat 0: the methods need at least one round" in capsys.readouterr().err
    seq = tmp_path / "s"
    main(["synth", str(seq), "--scene", "static_xyz", "--frames", "3", "--quiet"])
    assert main(["run", "static-dense", str(seq), "--out", str(tmp_path / "t.txt"),
                 "--set", "nonsense=1"]) == 2
    assert "unknown parameter 'nonsense'" in capsys.readouterr().err


TIMED = ("timing", "paper_b_table4")  # wall-clock figures: the only tables that vary run to run


def _linked(readme: Path) -> list[str]:
    """Files a reports index links to, with whether they need the shared real data."""
    return [(m.group(1), "../shared/data" in line) for line in readme.read_text().splitlines()
            for m in re.finditer(r"\]\(((?:tables|figures|trajectories|executed)/[^)]+|provenance\.json)\)", line)]


def test_reproduce_tiny_writes_every_indexed_file_and_a_failed_run_keeps_reports(tmp_path, capsys, tiny_tables):
    """The tiny profile end to end (every notebook executed by papermill), identical to another
    tiny batch, and a failing run leaves reports/ as it was."""
    reports = tmp_path / "reports"
    cache = tmp_path / "cache"
    args = ["reproduce", "--profile", "tiny", "--jobs", "2", "--cache", str(cache), "--reports", str(reports)]
    assert main(args) == 0
    out = capsys.readouterr().out
    n = tiny_plan()[0]
    assert "[summary]" in out and "6 ok, 0 failed" in out and f"[run {n}/{n}]" in out
    table = (reports / "tables" / "summary.md").read_text()
    assert "synthetic/walking_xyz" in table and "opencv-odometry" in table and "reduction vs static-orb" in table
    a1 = (reports / "tables" / "paper_a_table1.md").read_text()
    assert "DVO (published)" in a1 and "fr3/walking_xyz" in a1
    for name, figs in FIGURES.items():
        assert (reports / "executed" / f"{name}.ipynb").exists(), name
        for fig in figs:
            assert (reports / "figures" / fig).stat().st_size > 10_000, fig
    shared = (ROOT.parent / "shared" / "data").exists()
    linked = _linked(reports / "README.md")
    assert len(linked) > 40
    for rel, needs_real in linked:
        assert (reports / rel).exists() or (needs_real and not shared), rel
    prov = json.loads((reports / "provenance.json").read_text())
    assert prov["profile"] == "tiny" and prov["code_sha256"] == code_fingerprint(ROOT)
    runs = json.loads((reports / "trajectories" / "runs.json").read_text())
    assert len(runs) == n and all((reports / "trajectories" / r["trajectory"]).exists() for r in runs)
    figures = sorted(p.name for p in (reports / "figures").iterdir())
    tables = {p.name: p.read_bytes() for p in (reports / "tables").iterdir() if p.stem not in TIMED}
    # deterministic (another batch, its own runs), and notebook 90's tables equal the batch's own
    assert tables == {k: v for k, v in tiny_tables.items() if k.split(".")[0] not in TIMED}
    capsys.readouterr()
    assert main(args + ["--no-notebooks"]) == 0  # every run taken from the run cache
    out = capsys.readouterr().out
    assert f"{n} finished earlier" in out and out.count("[cached ") == n and "[run 1/" not in out
    cached = {p.name: p.read_bytes() for p in (reports / "tables").iterdir()}
    assert {k: v for k, v in cached.items() if k.split(".")[0] not in TIMED} == tables
    assert sorted(p.name for p in (reports / "figures").iterdir()) == figures  # left in place
    bad = tmp_path / "rgbd_broken"
    bad.mkdir()
    (bad / "rgb.txt").write_text("1.0 rgb/x.png\n")
    assert main(args + ["--no-notebooks", "--data", str(bad)]) == 2
    assert (reports / "tables" / "summary.md").read_text() == table
    assert not [p for p in reports.iterdir() if p.name.startswith(".tmp")]


def test_module_entry_point_help():
    out = subprocess.run([sys.executable, "-m", "dynslam_lite", "--help"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    for cmd in ("synth", "run", "evaluate", "bench", "reproduce", "download"):
        assert cmd in out


def test_failed_run_and_failed_notebook_are_reported_and_reports_kept(tmp_path, capsys, monkeypatch):
    """A run that raises (an unreadable PNG mid-sequence) and a notebook that raises are both
    listed in the summary; the command fails and reports/ keeps what an earlier run wrote."""
    import dynslam_lite.batch as batch

    reports = tmp_path / "reports"
    (reports / "tables").mkdir(parents=True)
    (reports / "tables" / "summary.md").write_text("earlier good run\n")
    seq = tmp_path / "rgbd_dataset_freiburg3_broken"
    assert main(["synth", str(seq), "--scene", "static_xyz", "--frames", "6", "--quiet"]) == 0
    sorted((seq / "rgb").iterdir())[3].write_bytes(b"not a png")
    monkeypatch.setattr(batch, "load_registry", lambda: (
        {"tiny": {"scenes": ("static_xyz",), "frames": 6}},
        {"10_depthcluster_clustering_and_masks": {"tiny": {"frames": 6, "scene": "no_such_scene"}}}))
    rc = main(["reproduce", "--profile", "tiny", "--jobs", "2", "--cache", str(tmp_path / "cache"),
               "--reports", str(reports), "--data", str(seq)])
    captured = capsys.readouterr()
    assert rc == 2
    assert re.search(r"FAILED real/rgbd_dataset_freiburg3_broken static-dense: .*rgb", captured.out)
    assert re.search(r"FAILED 10_depthcluster_clustering_and_masks: \w+", captured.out)
    assert "run(s) and 1 notebook(s) failed" in captured.err and "left as it was" in captured.err
    assert (reports / "tables" / "summary.md").read_text() == "earlier good run\n"
    assert sorted(p.name for p in reports.rglob("*")) == ["summary.md", "tables"]


def test_code_changed_during_the_batch_fails_it_and_keeps_reports(tmp_path, capsys, monkeypatch):
    """Runs and notebooks import the working tree: when its code fingerprint at the end differs
    from the start, the batch stops before provenance.json and reports/ keeps what it had."""
    import dynslam_lite.batch as batch

    reports = tmp_path / "reports"
    (reports / "tables").mkdir(parents=True)
    (reports / "tables" / "summary.md").write_text("earlier good run\n")
    prints = iter(["start", "edited"])
    monkeypatch.setattr(batch, "code_fingerprint", lambda root, **kw: "cache" if kw else next(prints))
    monkeypatch.setattr(batch, "load_registry", lambda: ({"tiny": {"scenes": ("static_xyz",), "frames": 6}}, {}))
    rc = main(["reproduce", "--profile", "tiny", "--jobs", "2", "--cache", str(tmp_path / "cache"),
               "--reports", str(reports)])
    captured = capsys.readouterr()
    assert rc == 2 and "the code changed while the batch ran" in captured.err and "left as it was" in captured.err
    assert (reports / "tables" / "summary.md").read_text() == "earlier good run\n"
    assert sorted(p.name for p in reports.rglob("*")) == ["summary.md", "tables"]
