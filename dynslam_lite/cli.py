"""Command line: ``python -m dynslam_lite {synth,run,evaluate,bench,reproduce}``."""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

from .evaluation import evaluate
from .io import (SequenceError, Trajectory, atomic_write_text, bonn_marker_to_camera, is_bonn,
                 open_sequence, read_trajectory, write_trajectory)
from .masks import SOURCES
from .pipeline import METHODS, parse_value, run_method
from .reports import ReportWriter
from .synth import SCENES, ensure_scene, generate
from . import tables

DEFAULT_CACHE = Path("build") / "data"
BASELINES = ("static-dense", "opencv-odometry")
REPRODUCED = BASELINES + ("depthcluster", "static-orb", "weightedstatic", "bgrestore")

# Runs of the reproduction: label -> (method, mask source, parameters). The label is the
# 'method' column of the tables. Synthetic runs use the ground-truth masks where a method takes
# masks; real data has no ground-truth masks.
MASKED = ("weightedstatic", "bgrestore")  # built on semantic masks (static-orb takes them optionally)
# paper C's tables cover the walking sequences only: bgrestore (the slowest method) runs there
SYNTHETIC_RUNS = {m: (m, "oracle" if m in MASKED else "none", {}) for m in REPRODUCED if m != "bgrestore"}
PAPER_C_SCENES = ("walking_xyz", "walking_halfsphere", "walking_rpy", "walking_static")
PAPER_C_RUNS = {"bgrestore": ("bgrestore", "oracle", {})}
# real data: the bundled person model (a stand-in for the papers' networks), and without masks
REAL_RUNS = {m: (m, "person" if m in MASKED else "none", {}) for m in REPRODUCED}
REAL_RUNS.update({"static-orb[person]": ("static-orb", "person", {}),
                  "weightedstatic[none]": ("weightedstatic", "none", {}),
                  "bgrestore[none]": ("bgrestore", "none", {})})
# Paper B's ablation, on two walking scenes (the batch's time budget)
ABLATION_SCENES = ("walking_xyz", "walking_rpy")
# Paper C's choices measured on walking_xyz: removal without restoration, the paper's adjacent frames
PAPER_C_ABLATION = {
    "bgrestore[no-restore]": ("bgrestore", "oracle", {"restore": False}),
    "bgrestore[adjacent]": ("bgrestore", "oracle", {"removal.frame_gap": 1}),
}
ABLATION_RUNS = {
    "static-orb[oracle]": ("static-orb", "oracle", {}),
    "static-orb[oracle:degraded]": ("static-orb", "oracle:degraded", {}),
    "weightedstatic[oracle:degraded,geometry]": ("weightedstatic", "oracle:degraded", {"use_weights": False}),
    "weightedstatic[oracle:degraded,weights]": ("weightedstatic", "oracle:degraded", {"use_geometry": False}),
    "weightedstatic[oracle:degraded]": ("weightedstatic", "oracle:degraded", {}),
    "weightedstatic[none]": ("weightedstatic", "none", {}),
}


def _parse_sets(items: list[str]) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"--set expects key=value, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = parse_value(v.strip())
    return out


def cmd_synth(a) -> int:
    st = generate(a.out_dir, a.scene, a.frames, a.seed, a.background, progress=not a.quiet)
    print(f"wrote {st.frames} frames of {a.scene} to {st.path} "
          f"({st.frames_per_s:.2f} frames/s)")
    return 0


def cmd_run(a) -> int:
    seq = open_sequence(a.seq_dir, a.camera, a.start, a.frames)
    result = run_method(a.method, seq, _parse_sets(a.set), progress=not a.quiet, masks=a.masks)
    write_trajectory(a.out, result.trajectory)
    stats = result.stats()
    if a.stats:
        atomic_write_text(a.stats, json.dumps(stats, indent=2) + "\n")
    for i, reason in result.failed_frames:
        print(f"tracking failed on frame {i}: {reason}", file=sys.stderr)
    print(f"{a.method}: {stats['frames']} frames, {len(result.failed_frames)} failed, "
          f"{stats['ms_per_frame']:.1f} ms/frame, peak {stats['peak_mem_mib']:.0f} MiB -> {a.out}")
    return 0


def cmd_evaluate(a) -> int:
    gt_path = Path(a.gt)
    gt = read_trajectory(gt_path)
    if a.bonn or (a.bonn is None and is_bonn(gt_path.parent)):

        gt = Trajectory(gt.timestamps, gt.poses @ bonn_marker_to_camera())
    errors = evaluate(gt, read_trajectory(a.est))
    if a.json:
        print(json.dumps(errors.as_dict()))
    else:
        e = errors
        print(f"matched poses      {e.matched_poses}")
        print(f"ATE  (m)      rmse {e.ate.rmse:.4f} mean {e.ate.mean:.4f} median {e.ate.median:.4f} "
              f"std {e.ate.std:.4f} min {e.ate.min:.4f} max {e.ate.max:.4f}")
        print(f"RPE  (m/s)    rmse {e.rpe_trans.rmse:.4f} mean {e.rpe_trans.mean:.4f} "
              f"median {e.rpe_trans.median:.4f} ({e.rpe_trans.count} pairs over 1 s)")
        print(f"RPE  (deg/s)  rmse {e.rpe_rot_deg.rmse:.4f} mean {e.rpe_rot_deg.mean:.4f} "
              f"median {e.rpe_rot_deg.median:.4f}")
    return 0


def cmd_bench(a) -> int:
    """Print ms/frame per stage of every method on the same frames, and the generator's rate.

    A stage that runs on some frames only (later background updates) is averaged over the
    frames that ran it; 'frames' says how many.
    """
    import numpy as np

    cache = Path(a.cache)
    if a.seq:
        seq = open_sequence(a.seq, a.camera, 0, a.frames)
        print(f"sequence: {a.seq} ({len(seq)} frames)")
    else:
        t = time.perf_counter()
        path = generate(cache / f"bench_{a.scene}", a.scene, a.frames, 0)
        dt = time.perf_counter() - t
        print(f"generator: {a.scene}, {a.frames} frames at 640x480 in {dt:.1f} s = "
              f"{a.frames / dt:.2f} frames/s")
        seq = open_sequence(path.path)
    print(f"{'method':18s} {'stage':10s} {'mean ms':>9s} {'median ms':>10s} {'frames':>7s}")
    for method in a.methods:
        masks = (a.masks or ("person" if a.seq else "oracle")) if method in MASKED else "none"
        r = run_method(method, seq, masks=masks)
        if masks != "none":
            print(f"{method:18s} (masks {masks})")
        for stage, ms in r.stage_ms.items():
            print(f"{method:18s} {stage:10s} {np.mean(ms):9.1f} {np.median(ms):10.1f} {len(ms):7d}")
        s = r.stats()
        print(f"{method:18s} {'total':10s} {s['ms_per_frame']:9.1f} {np.median(r.frame_ms):10.1f}"
              f"   peak memory {s['peak_mem_mib']:.0f} MiB")
    return 0


# --------------------------------------------------------------------------- reproduction

PROFILES = {
    "quick": {"scenes": ("static_xyz", "walking_xyz"), "frames": 45},
    "full": {"scenes": SCENES, "frames": 150},
}

# The notebooks the reproduction executes (papermill), with their parameters per profile.
# Paths in parameters are relative to the repository root; output_dir and cache_dir are set by
# the run.
NOTEBOOK_RUNS = {
    "10_depthcluster_clustering_and_masks": {
        "quick": {"frames": 12, "pair": 6, "eval_frames": 10},
        "full": {"frames": 150, "pair": 30, "eval_frames": 150},
    },
    "11_depthcluster_iterations": {
        "quick": {"frames": 20, "pair": 6, "map_stride": 5},
        "full": {"frames": 150, "pair": 30, "map_stride": 10},
    },
    "20_weightedstatic_masks_and_geometry": {
        "quick": {"frames": 20, "pair": 12, "eval_stride": 4, "real_stride": 20},
        "full": {"frames": 150, "pair": 30, "eval_stride": 5},
    },
    "21_weightedstatic_weighted_ba": {
        "quick": {"frames": 20, "pair": 12},
        "full": {"frames": 150, "pair": 30},
    },
    "30_bgrestore_inpainting": {
        "quick": {"frames": 20, "shown": 15, "eval_stride": 10},
        "full": {"frames": 150, "shown": 60, "eval_stride": 10},
    },
}
NOTEBOOK_DIR = Path(__file__).resolve().parents[1] / "notebooks"


def _notebook_job(job: tuple) -> tuple[str, float, str]:
    """Execute one notebook with papermill; returns (name, seconds, error or '')."""
    name, params, out_dir, cache = job
    import papermill as pm

    t = time.perf_counter()
    try:
        pm.execute_notebook(
            str(NOTEBOOK_DIR / f"{name}.ipynb"), str(Path(out_dir) / "executed" / f"{name}.ipynb"),
            parameters={**params, "output_dir": str(out_dir), "cache_dir": str(cache)},
            cwd=str(NOTEBOOK_DIR.parent), progress_bar=False, kernel_name="python3",
        )
        return name, time.perf_counter() - t, ""
    except Exception as exc:  # reported in the summary; the run fails without touching reports/
        return name, time.perf_counter() - t, f"{type(exc).__name__}: {str(exc).strip().splitlines()[-1] if str(exc).strip() else ''}"


def _scene_job(job: tuple) -> str:
    """Generate (or find cached) one synthetic scene; runs in a worker process."""
    cache, scene, frames, seed = job
    return str(ensure_scene(cache, scene, frames, seed))


def _evaluate_job(job: tuple) -> dict:
    """One (sequence, run) evaluated; runs in a worker process."""
    label, path, camera, count, (run, (method, masks, params)) = job
    seq = open_sequence(path, camera, 0, count)
    r = run_method(method, seq, params, masks=masks)
    e = evaluate(seq.groundtruth, r.trajectory)
    stats = r.stats()
    return {"sequence": label, "method": run, "frames": len(seq), **e.as_dict(),
            "failed_frames": len(r.failed_frames), "ms_per_frame": stats["ms_per_frame"],
            "stages": {k: float(sum(v)) / len(seq) for k, v in r.stage_ms.items()},
            "extras": r.extras}


def cmd_reproduce(a) -> int:
    """Batch reproduction on the embedded synthetic default (plus --data sequences)."""
    prof = PROFILES[a.profile]
    frames = a.frames or prof["frames"]
    cache = Path(a.cache)
    t0 = time.perf_counter()
    jobs = []
    for d in a.data or []:
        seq = open_sequence(d)  # validate real data before any long work, with a clear error
        print(f"[data] {d}: {len(seq)} frames", flush=True)
    # spawn, not fork: a forked child inherits OpenCV's thread pool in a broken state and hangs
    with ProcessPoolExecutor(max_workers=a.jobs, mp_context=mp.get_context("spawn")) as pool:
        scenes = list(prof["scenes"])
        paths = pool.map(_scene_job, [(str(cache), s, frames, a.seed) for s in scenes])
        for scene, path in zip(scenes, paths):
            print(f"[data] synthetic {scene}: {frames} frames at {path}", flush=True)
            runs = dict(SYNTHETIC_RUNS, **(ABLATION_RUNS if scene in ABLATION_SCENES else {}),
                        **(PAPER_C_RUNS if scene in PAPER_C_SCENES else {}),
                        **(PAPER_C_ABLATION if scene == "walking_xyz" else {}))
            jobs += [(f"synthetic/{scene}", path, None, None, run) for run in runs.items()]
        for d in a.data or []:
            jobs += [(f"real/{Path(d).resolve().name}", d, None, None, run) for run in REAL_RUNS.items()]
        results = []
        for res in pool.map(_evaluate_job, jobs):
            print(f"[run] {res['sequence']:32s} {res['method']:42s} ATE {res['ate_m']['rmse']:.4f} m "
                  f"RPE {res['rpe_trans_m_per_s']['rmse']:.4f} m/s "
                  f"{res['rpe_rot_deg_per_s']['rmse']:.3f} deg/s", flush=True)
            results.append(res)
    writer = ReportWriter(a.reports)
    try:
        src = (f" Run: `python -m dynslam_lite reproduce --profile {a.profile}` "
               f"(synthetic seed {a.seed}).")
        for stem, title, make in (
            ("summary", f"Every method on every sequence ({a.profile} profile, measured)", tables.summary),
            ("paper_a_table1", "Paper A, Table 1: relative pose error (RMSE)", tables.paper_a_table1),
            ("paper_a_table2", "Paper A, Table 2: absolute trajectory error (m)", tables.paper_a_table2),
            ("paper_a_masks", "Paper A: moving-object masks of depthcluster against ground truth",
             tables.paper_a_masks),
            ("paper_b_table1", "Paper B, Table 1: absolute trajectory error (m)", tables.paper_b_table1),
            ("paper_b_table2", "Paper B, Table 2: relative pose error (translation)", tables.paper_b_table2),
            ("paper_b_table3", "Paper B, Table 3: ATE against other systems (m)", tables.paper_b_table3),
            ("paper_b_table4", "Paper B, Table 4: tracking time per frame", tables.paper_b_table4),
            ("paper_b_ablation", "Paper B: what the geometric test and the weights add over masks",
             tables.paper_b_ablation),
            ("paper_b_points", "Paper B: dynamic-point classification against ground truth",
             tables.paper_b_points),
            ("paper_c_table1", "Paper C, Table 1: ATE against the baseline (m)", tables.paper_c_table1),
            ("paper_c_table2", "Paper C, Table 2: ATE against other systems (m)", tables.paper_c_table2),
            ("paper_c_table3", "Paper C, Table 3: relative translation error", tables.paper_c_table3),
            ("paper_c_table4", "Paper C, Table 4: relative rotation error", tables.paper_c_table4),
            ("paper_c_restoration", "Paper C: removed and restored area", tables.paper_c_restoration),
        ):
            header, rows, notes = make(results)
            writer.table(f"tables/{stem}", title, header, rows, notes=notes + src)
        writer.table(
            "tables/timing", "Time per frame of every run (machine-dependent)",
            ["sequence", "method", "ms/frame"],
            [[r["sequence"], r["method"], f"{r['ms_per_frame']:.1f}"] for r in results],
            notes="Wall-clock milliseconds per frame, whole pipeline, measured during the run on "
                  "this machine with other jobs in parallel: varies between runs, unlike the "
                  "error tables. `python -m dynslam_lite bench` measures per stage.",
        )
        (writer.tmp / "executed").mkdir(exist_ok=True)
        nb_jobs = [(name, prof_params[a.profile], str(writer.tmp.resolve()), str(cache.resolve()))
                   for name, prof_params in NOTEBOOK_RUNS.items() if not a.no_notebooks]
        failed = []
        with ThreadPoolExecutor(max_workers=a.jobs) as threads:  # kernels are processes
            for name, secs, err in threads.map(_notebook_job, nb_jobs):
                print(f"[notebook] {name}: {'FAILED ' + err if err else 'ok'} ({secs:.0f} s)", flush=True)
                if err:
                    failed.append(name)
        if failed:
            keep = Path(a.cache).parent / "failed_notebooks"
            keep.mkdir(parents=True, exist_ok=True)
            for name in failed:
                src = writer.tmp / "executed" / f"{name}.ipynb"
                if src.exists():
                    shutil.copy(src, keep / src.name)
            raise RuntimeError(f"notebook(s) failed: {', '.join(failed)}; reports/ left as it was; "
                               f"executed copies with the error in {keep}")
        writer.adopt_all()
        done = writer.commit()
    except BaseException:
        writer.abort()
        raise
    print(f"[done] {len(results)} runs in {time.perf_counter() - t0:.0f} s; wrote "
          + ", ".join(str(p) for p in done))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m dynslam_lite", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("synth", help="generate a synthetic dynamic RGB-D sequence (TUM layout)")
    s.add_argument("out_dir")
    s.add_argument("--scene", default="walking_xyz", choices=SCENES)
    s.add_argument("--frames", type=int, default=300)
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--background", action="store_true", help="also render frames without people")
    s.add_argument("--quiet", action="store_true")
    s.set_defaults(func=cmd_synth)

    r = sub.add_parser("run", help="run a method on a sequence, write a TUM trajectory")
    r.add_argument("method", choices=sorted(METHODS))
    r.add_argument("seq_dir")
    r.add_argument("--out", required=True, help="trajectory file to write (TUM format)")
    r.add_argument("--start", type=int, default=0)
    r.add_argument("--frames", type=int, default=None)
    r.add_argument("--camera", default=None, help="fr1, fr2, fr3 or bonn (default: guessed)")
    r.add_argument("--set", action="append", metavar="KEY=VALUE", help="method parameter")
    r.add_argument("--stats", help="write run statistics (JSON) here")
    r.add_argument("--masks", default="none",
                   help=f"semantic masks for methods that use them: {SOURCES} (see dynslam_lite/masks.py)")
    r.add_argument("--quiet", action="store_true")
    r.set_defaults(func=cmd_run)

    e = sub.add_parser("evaluate", help="ATE and 1-s RPE of an estimate against ground truth")
    e.add_argument("gt")
    e.add_argument("est")
    e.add_argument("--json", action="store_true")
    e.add_argument("--bonn", action="store_true", default=None,
                   help="convert Bonn marker poses to the camera frame (default: if the folder "
                        "name contains 'bonn')")
    e.set_defaults(func=cmd_evaluate)

    b = sub.add_parser("bench", help="ms/frame per stage of the baselines, generator frames/s")
    b.add_argument("--seq", help="a sequence folder (default: a generated synthetic scene)")
    b.add_argument("--scene", default="walking_xyz", choices=SCENES)
    b.add_argument("--frames", type=int, default=60)
    b.add_argument("--camera", default=None)
    b.add_argument("--methods", nargs="+", default=list(REPRODUCED), choices=sorted(METHODS))
    b.add_argument("--cache", default=str(DEFAULT_CACHE))
    b.add_argument("--masks", default=None,
                   help="mask source of weightedstatic (default: oracle on the synthetic scene, "
                        "person on --seq)")
    b.set_defaults(func=cmd_bench)

    rp = sub.add_parser("reproduce", help="batch reproduction into reports/")
    rp.add_argument("--profile", choices=sorted(PROFILES), default="full")
    rp.add_argument("--frames", type=int, default=None, help="override the profile's frame count")
    rp.add_argument("--data", action="append", help="real TUM/Bonn sequence folder (repeatable)")
    rp.add_argument("--seed", type=int, default=0)
    rp.add_argument("--jobs", type=int, default=2, help="worker processes")
    rp.add_argument("--cache", default=str(DEFAULT_CACHE))
    rp.add_argument("--reports", default="reports")
    rp.add_argument("--no-notebooks", action="store_true",
                    help="tables only: skip the notebooks (figures and executed notebooks in "
                         "reports/ stay as they are)")
    rp.set_defaults(func=cmd_reproduce)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (SequenceError, ValueError, FileNotFoundError, FileExistsError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
