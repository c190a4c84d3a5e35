"""What a user meets when things go wrong: one-line errors naming the file or key (exit 2),
bugs reported as bugs (exit 3), runs that mostly failed (exit 1), Ctrl-C / SIGTERM (exit 130,
no process left, reports/ untouched), and the package usable from any folder."""
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import psutil
import pytest

from dynslam_lite.cli import main
from dynslam_lite.pipeline import METHODS, make_config

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """A short synthetic walking clip (TUM layout)."""
    from dynslam_lite.synth import ensure_scene

    return ensure_scene(tmp_path_factory.mktemp("clip"), "walking_xyz", 24, 0)


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def _one_line_error(err: str, *needles: str) -> None:
    lines = [l for l in err.strip().splitlines() if l.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    for n in needles:
        assert n in lines[0], (n, lines[0])


def test_unusable_depth_stops_with_an_error_naming_the_folder(clip, tmp_path, capsys):
    seq = _copy(clip, tmp_path / "zero_depth")
    for png in (seq / "depth").iterdir():
        cv2.imwrite(str(png), np.zeros((480, 640), np.uint16))
    out = tmp_path / "t.txt"
    assert main(["run", "static-dense", str(seq), "--out", str(out), "--quiet"]) == 2
    _one_line_error(capsys.readouterr().err, str(seq / "depth"), "no usable depth")
    assert not out.exists()


def test_set_values_are_checked_against_the_config(clip, tmp_path, capsys):
    for item, expected in (("orb.n_features=abc", "expected a number (int)"),
                           ("orb=3", "orb is a group of parameters"),
                           ("orb.n_features=-5", "non-negative"),
                           ("max_point_depth_m=abc", "expected a number (float)"),
                           ("keyframe_ratio=1.5", "between 0 and 1"),
                           ("nonsense", "expects key=value")):
        assert main(["run", "static-orb", str(clip), "--out", str(tmp_path / "t.txt"), "--set", item]) == 2
        _one_line_error(capsys.readouterr().err, expected)
    # a count whose name holds 'ratio' inside a word ('iterations') is a count, not a fraction
    assert make_config(METHODS["static-orb"].config_type, {"ba_iterations": 3}).ba_iterations == 3
    assert make_config(METHODS["depthcluster"].config_type, {"update_iterations": 3}).update_iterations == 3
    assert make_config(METHODS["weightedstatic"].config_type, {"lm_iterations": 30}).lm_iterations == 30


def test_short_sequences_are_refused_by_every_method(clip, tmp_path, capsys):
    from dynslam_lite.pipeline import METHODS

    for method in METHODS:
        assert main(["run", method, str(clip), "--out", str(tmp_path / "t.txt"), "--frames", "1", "--quiet"]) == 2
        _one_line_error(capsys.readouterr().err, "1 frame(s): tracking needs at least 2")


def test_a_run_that_mostly_failed_exits_non_zero(clip, tmp_path, capsys):
    out = tmp_path / "t.txt"
    rc = main(["run", "static-orb", str(clip), "--out", str(out), "--quiet", "--frames", "6",
               "--set", "min_inliers=100000"])
    assert rc == 1 and out.exists()
    assert "error: tracking failed on 5 of 5 frame pairs" in capsys.readouterr().err


def test_internal_errors_are_reported_as_bugs(clip, tmp_path, capsys, monkeypatch):
    import dynslam_lite.cli as cli

    def broken(*args, **kwargs):
        return 1 / 0

    monkeypatch.setattr(cli, "run_method", broken)
    assert main(["run", "static-dense", str(clip), "--out", str(tmp_path / "t.txt")]) == 3
    err = capsys.readouterr().err
    assert "internal error (a bug in dynslam_lite" in err and "ZeroDivisionError" in err
    assert "Traceback" not in err and "DYNSLAM_DEBUG=1" in err


def test_evaluate_names_both_files_and_writes_valid_json(clip, tmp_path, capsys):
    gt = clip / "groundtruth.txt"
    far = tmp_path / "far.txt"
    far.write_text("".join(f"{5000 + i:.6f} 0 0 0 0 0 0 1\n" for i in range(5)))
    assert main(["evaluate", str(gt), str(far)]) == 2
    _one_line_error(capsys.readouterr().err, str(far), str(gt), "5000.000-5004.000 s")
    zero_q = tmp_path / "zero_q.txt"
    zero_q.write_text("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 0\n")
    assert main(["evaluate", str(gt), str(zero_q)]) == 2
    _one_line_error(capsys.readouterr().err, str(zero_q), "2.000000", "quaternion norm 0")
    short = tmp_path / "short.txt"  # 0.3 s: no 1-s RPE pair
    assert main(["run", "static-dense", str(clip), "--out", str(short), "--frames", "10", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(gt), str(short), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)  # strict JSON: NaN would not parse as null
    assert out["rpe_trans_m_per_s"]["rmse"] is None and out["ate_m"]["rmse"] > 0


def test_the_package_runs_from_any_folder(tmp_path):
    out = subprocess.run([sys.executable, "-m", "dynslam_lite", "--help"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "reproduce" in out.stdout, out.stderr


def _session_alive(sid: int) -> list[int]:
    """Live processes (not zombies) of session ``sid``."""
    alive = []
    for p in psutil.process_iter(["pid", "status"]):
        try:
            if os.getsid(p.pid) == sid and p.info["status"] != psutil.STATUS_ZOMBIE:
                alive.append(p.pid)
        except (ProcessLookupError, PermissionError, psutil.Error):
            pass
    return alive


def _as_from_a_terminal():
    """Ctrl-C handled as a terminal's foreground command has it: a suite started as a background
    job (``cmd &`` in a script) passes SIGINT down ignored, and Python then keeps ignoring it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _interrupt(cmd, sig, after, to_group, cwd=ROOT):
    """Start ``cmd`` in a session of its own and send ``sig`` ``after`` seconds, or (a string)
    once a line starting with it was printed; (rc, seconds to exit, stderr, live processes left)."""
    p = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True, preexec_fn=_as_from_a_terminal)
    try:
        if isinstance(after, str):
            deadline = time.monotonic() + 300
            while not p.stdout.readline().startswith(after):
                assert time.monotonic() < deadline and p.poll() is None, f"no line {after!r}"
        else:
            time.sleep(after)
        t = time.monotonic()
        if to_group:
            os.killpg(p.pid, sig)  # what a terminal's Ctrl-C does
        else:
            p.send_signal(sig)  # what a scheduler's SIGTERM does
        _, err = p.communicate(timeout=30)
        took = time.monotonic() - t
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    deadline = time.monotonic() + 5
    while _session_alive(p.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    return p.returncode, took, err, _session_alive(p.pid)


def _tree(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize("sig, to_group", [(signal.SIGINT, True), (signal.SIGTERM, False)], ids=["ctrl-c", "sigterm"])
def test_reproduce_stops_at_once_on_interrupt_keeps_reports_and_resumes(tmp_path, sig, to_group, capsys,
                                                                      tiny_tables):
    reports = tmp_path / "reports"
    (reports / "tables").mkdir(parents=True)
    (reports / "tables" / "summary.md").write_text("an earlier run\n")
    before = _tree(reports)
    cmd = [sys.executable, "-m", "dynslam_lite", "reproduce", "--profile", "tiny", "--jobs", "2",
           "--cache", str(tmp_path / "cache"), "--reports", str(reports)]
    # Ctrl-C once four runs have finished (the last one printed may not be stored yet); SIGTERM
    # early, while the scenes are generated
    rc, took, err, left = _interrupt(cmd, sig, "[run 4/" if sig == signal.SIGINT else 8, to_group)
    assert rc == 130 and took < 10, (rc, took, err)
    lines = [l for l in err.strip().splitlines() if l.startswith("interrupted")]
    assert len(lines) == 1 and "left as it was" in lines[0] and "Traceback" not in err, err
    assert not left, left
    assert _tree(reports) == before and not list(reports.glob(".tmp*"))
    if sig == signal.SIGINT:  # resumed: the runs finished before the interrupt are not repeated
        resumed = tmp_path / "resumed"
        base = ["reproduce", "--profile", "tiny", "--jobs", "2", "--cache", str(tmp_path / "cache"), "--no-notebooks"]
        capsys.readouterr()
        assert main(base + ["--reports", str(resumed)]) == 0
        done = int(re.search(r"(\d+) finished earlier", capsys.readouterr().out).group(1))
        assert 3 <= done < 25, done
        timed = ("timing.md", "timing.csv", "paper_b_table4.md", "paper_b_table4.csv")
        tables = {f: b for f, b in _tree(resumed / "tables").items() if f not in timed}
        assert tables == {f: b for f, b in tiny_tables.items() if f not in timed}  # as a fresh batch


def test_run_stops_at_once_on_ctrl_c_and_writes_nothing(scene, tmp_path):
    out = tmp_path / "t.txt"
    # 150 frames (the suite's shared scene): 15 s or more, still tracking after 3 s on a fast machine
    cmd = [sys.executable, "-m", "dynslam_lite", "run", "bgrestore", str(scene("walking_xyz", 150)), "--out", str(out),
           "--quiet", "--masks", "oracle"]
    rc, took, err, left = _interrupt(cmd, signal.SIGINT, 3, True)
    assert rc == 130 and took < 5 and not left, (rc, took, err)
    assert err.strip() == "interrupted: run interrupted; nothing was written" and not out.exists()
