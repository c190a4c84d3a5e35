"""Command line: ``python -m dynslam_lite {synth,run,evaluate,bench,reproduce,download}``."""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import shutil
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from pathlib import Path

from .download import ARCHIVES, DownloadError, download
from .evaluation import evaluate
from .io import (SequenceError, Trajectory, atomic_write_text, bonn_marker_to_camera, format_trajectory,
                 is_bonn, open_sequence, read_trajectory, write_trajectory)
from .masks import SOURCES
from .pipeline import METHODS, parse_value, run_method
from .reports import ReportWriter, code_fingerprint, fmt
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

NOTEBOOK_DIR = Path(__file__).resolve().parents[1] / "notebooks"
REGISTRY = NOTEBOOK_DIR / "reproduce.yaml"


def load_registry(path: Path = REGISTRY) -> tuple[dict, dict]:
    """(profiles, notebooks) of the reproduction registry (``notebooks/reproduce.yaml``)."""
    import yaml

    try:
        reg = yaml.safe_load(path.read_text(encoding="utf-8"))
        profiles, notebooks = reg["profiles"], reg["notebooks"]
    except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a readable reproduction registry ({exc})") from exc
    for prof in profiles.values():
        prof["scenes"] = tuple(SCENES) if prof["scenes"] == "all" else tuple(prof["scenes"])
    for name, params in notebooks.items():
        if not (NOTEBOOK_DIR / f"{name}.ipynb").exists():
            raise ValueError(f"{path}: notebook {name}.ipynb does not exist")
        if set(params) != set(profiles):
            raise ValueError(f"{path}: notebook {name} needs parameters for every profile {sorted(profiles)}")
    return profiles, notebooks


def _notebook_job(job: tuple) -> tuple[str, float, str]:
    """Execute one notebook with papermill; returns (name, seconds, error or '')."""
    name, params = job
    import papermill as pm

    t = time.perf_counter()
    print(f"[notebook] {name}: started", flush=True)
    try:
        pm.execute_notebook(
            str(NOTEBOOK_DIR / f"{name}.ipynb"), str(Path(params["output_dir"]) / "executed" / f"{name}.ipynb"),
            parameters=params,
            cwd=str(NOTEBOOK_DIR.parent), progress_bar=False, kernel_name="python3",
        )
        return name, time.perf_counter() - t, ""
    except Exception as exc:  # reported in the summary; the run fails without touching reports/
        return name, time.perf_counter() - t, f"{type(exc).__name__}: {str(exc).strip().splitlines()[-1] if str(exc).strip() else ''}"


def _worker_init(jobs: int) -> None:
    """OpenCV's own thread pool: one thread per worker when the workers share the cores."""
    if jobs > 1:
        import cv2

        cv2.setNumThreads(1)


def _scene_job(job: tuple) -> str:
    """Generate (or find cached) one synthetic scene; runs in a worker process."""
    cache, scene, frames, seed = job
    return str(ensure_scene(cache, scene, frames, seed))


def _evaluate_job(job: tuple) -> dict:
    """One (sequence, run) tracked and evaluated in a worker process; an exception is returned
    as ``error`` (reported in the summary) instead of ending the batch."""
    label, path, (run, (method, masks, params)) = job
    t = time.perf_counter()
    try:
        seq = open_sequence(path)
        print(f"[run] {label:32s} {run:42s} started ({len(seq)} frames)", flush=True)
        r = run_method(method, seq, params, masks=masks)
        text = format_trajectory(r.trajectory)  # scored as written: notebook 90 gets the same numbers
        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / "t.txt").write_text(text)
            e = evaluate(seq.groundtruth, read_trajectory(Path(tmp) / "t.txt"))
    except Exception as exc:
        return {"sequence": label, "method": run, "error": f"{type(exc).__name__}: {exc}",
                "seconds": time.perf_counter() - t}
    stats = r.stats()
    return {"sequence": label, "method": run, "path": str(path), "frames": len(seq), **e.as_dict(),
            "failed_frames": len(r.failed_frames), "ms_per_frame": stats["ms_per_frame"],
            "stages": {k: float(sum(v)) / len(seq) for k, v in r.stage_ms.items()},
            "extras": r.extras, "seconds": time.perf_counter() - t,
            "trajectory": text}


def _file_name(label: str) -> str:
    """A run label ('weightedstatic[oracle:degraded]') as a plain file name."""
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in label).strip("_")


def _relative(path) -> str:
    """A path relative to the repository root where possible (committed reports stay portable)."""
    p = Path(path).resolve()
    return os.path.relpath(p, NOTEBOOK_DIR.parent)


def _write_runs(writer: ReportWriter, results: list[dict]) -> None:
    """Every estimated trajectory (TUM) and ``runs.json`` (where each came from, what it measured)
    under ``trajectories/``: the input of notebook 90."""
    index = []
    for r in results:
        rel = f"trajectories/{r['sequence']}/{_file_name(r['method'])}.txt"
        writer.write_text(rel, r["trajectory"])
        index.append({k: v for k, v in r.items() if k not in ("trajectory", "seconds")}
                     | {"path": _relative(r["path"]), "trajectory": rel.split("/", 1)[1]})
    writer.write_text("trajectories/runs.json", json.dumps(index, indent=1) + "\n")


def cmd_reproduce(a) -> int:
    """Batch reproduction on the embedded synthetic default (plus --data sequences)."""
    profiles, notebooks = load_registry()
    if a.profile not in profiles:
        raise ValueError(f"unknown profile {a.profile!r}: {REGISTRY} has {', '.join(profiles)}")
    prof = profiles[a.profile]
    frames = a.frames or prof["frames"]
    cache = Path(a.cache)
    t0 = time.perf_counter()
    fingerprint = code_fingerprint(NOTEBOOK_DIR.parent)
    if a.jobs > 1:  # one BLAS thread per worker and notebook kernel (inherited): with 2 workers on
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # 2 cores,
            os.environ.setdefault(var, "1")  # OpenBLAS's spinning threads doubled the run time
    jobs = []
    for d in a.data or []:
        seq = open_sequence(d)  # validate real data before any long work, with a clear error
        print(f"[data] {d}: {len(seq)} frames", flush=True)
    # spawn, not fork: a forked child inherits OpenCV's thread pool in a broken state and hangs
    with ProcessPoolExecutor(max_workers=a.jobs, mp_context=mp.get_context("spawn"),
                             initializer=_worker_init, initargs=(a.jobs,)) as pool:
        scenes = list(prof["scenes"])
        paths = pool.map(_scene_job, [(str(cache), s, frames, a.seed) for s in scenes])
        for scene, path in zip(scenes, paths):
            print(f"[data] synthetic {scene}: {frames} frames at {path}", flush=True)
            runs = dict(SYNTHETIC_RUNS, **(ABLATION_RUNS if scene in ABLATION_SCENES else {}),
                        **(PAPER_C_RUNS if scene in PAPER_C_SCENES else {}),
                        **(PAPER_C_ABLATION if scene == "walking_xyz" else {}))
            jobs += [(f"synthetic/{scene}", path, run) for run in runs.items()]
        for d in a.data or []:
            jobs += [(f"real/{Path(d).resolve().name}", d, run) for run in REAL_RUNS.items()]
        t_runs = time.perf_counter()
        print(f"[runs] {len(jobs)} runs on {a.jobs} worker(s)", flush=True)
        futures = [pool.submit(_evaluate_job, job) for job in jobs]
        for k, fut in enumerate(as_completed(futures), 1):
            res = fut.result()
            head = f"[run {k}/{len(jobs)}] {res['sequence']:32s} {res['method']:42s}"
            if "error" in res:
                print(f"{head} FAILED {res['error']}", flush=True)
            else:
                print(f"{head} ATE {res['ate_m']['rmse']:.4f} m RPE {fmt(res['rpe_trans_m_per_s']['rmse'])} m/s "
                      f"({res['frames']} frames, {res['seconds']:.0f} s)", flush=True)
        results = [f.result() for f in futures]  # job order: deterministic tables
    failed_runs = [r for r in results if "error" in r]
    results = [r for r in results if "error" not in r]
    t_nb = time.perf_counter()
    writer = ReportWriter(a.reports)
    nb_times, failed_nbs = {}, []
    try:
        source = (f"Run: `python -m dynslam_lite reproduce --profile {a.profile}` (synthetic seed "
                  f"{a.seed}, {frames} frames" + "".join(f", --data {Path(d).name}" for d in a.data or []) + ").")
        tables.write_all(results, writer.tmp, source)
        writer.adopt_all()
        _write_runs(writer, results)
        (writer.tmp / "executed").mkdir(exist_ok=True)
        out = str(writer.tmp.resolve())
        nb_jobs = [(name, {**params[a.profile], "output_dir": out,
                           **({"runs_dir": str(writer.tmp.resolve() / "trajectories"), "source": source}
                              if name.startswith("90_") else {"cache_dir": str(cache.resolve())})})
                   for name, params in notebooks.items() if not a.no_notebooks]
        with ThreadPoolExecutor(max_workers=a.jobs) as threads:  # kernels are processes
            for name, secs, err in threads.map(_notebook_job, nb_jobs):
                print(f"[notebook] {name}: {'FAILED ' + err if err else 'ok'} ({secs:.0f} s)", flush=True)
                nb_times[name] = secs
                if err:
                    failed_nbs.append((name, err))
        command = (f"python -m dynslam_lite reproduce --profile {a.profile}"
                   + (f" --frames {a.frames}" if a.frames else "") + (f" --seed {a.seed}" if a.seed else "")
                   + "".join(f" --data {_relative(d)}" for d in a.data or []))
        writer.write_text("provenance.json", json.dumps({
            "command": command, "profile": a.profile, "frames": frames, "seed": a.seed,
            "scenes": list(prof["scenes"]), "data": [_relative(d) for d in a.data or []],
            "notebooks": not a.no_notebooks, "code_sha256": fingerprint}, indent=1) + "\n")
        writer.write_text("README.md", (Path(__file__).with_name("reports_README.md")).read_text().replace(
            "{{provenance}}",
            f"This folder was written by `{command}` ({a.profile} profile: {len(prof['scenes'])} synthetic "
            f"scenes x {frames} frames, seed {a.seed}"
            + (", plus the real clips " + ", ".join(f"`{Path(d).name}`" for d in a.data) if a.data else "")
            + "; which methods run where is set in `dynslam_lite/cli.py`)."))
        _summary(results, failed_runs, nb_times, failed_nbs, t_nb - t_runs, time.perf_counter() - t0)
        if failed_runs or failed_nbs:
            keep = cache.parent / "failed_notebooks"
            for name, _ in failed_nbs:
                src = writer.tmp / "executed" / f"{name}.ipynb"
                if src.exists():
                    keep.mkdir(parents=True, exist_ok=True)
                    shutil.copy(src, keep / src.name)
            raise RuntimeError(f"{len(failed_runs)} run(s) and {len(failed_nbs)} notebook(s) failed; "
                               f"{a.reports}/ left as it was"
                               + (f"; executed copies with the error in {keep}" if failed_nbs else ""))
        writer.adopt_all()
        done = writer.commit()
    except BaseException:
        writer.abort()
        raise
    print(f"[done] wrote {len(done)} files under {a.reports}/ (index: {a.reports}/README.md)")
    return 0


def _summary(results, failed_runs, nb_times, failed_nbs, run_secs, total_secs) -> None:
    """What ran, how long, what failed: printed at the end of the batch."""
    seqs = sorted({r["sequence"] for r in results})
    print("\n[summary]")
    print(f"  runs:      {len(results)} ok, {len(failed_runs)} failed, on {len(seqs)} sequences, "
          f"{run_secs / 60:.1f} min")
    for r in failed_runs:
        print(f"    FAILED {r['sequence']} {r['method']}: {r['error']}")
    lost = [(r["sequence"], r["method"], r["failed_frames"]) for r in results if r["failed_frames"]]
    for seq, m, n in lost:
        print(f"    tracking failed on {n} frame(s): {seq} {m}")
    print(f"  notebooks: {len(nb_times) - len(failed_nbs)} ok, {len(failed_nbs)} failed"
          + "".join(f"; {n} {t:.0f} s" for n, t in nb_times.items()))
    for name, err in failed_nbs:
        print(f"    FAILED {name}: {err}")
    print(f"  total:     {total_secs / 60:.1f} min", flush=True)


def cmd_download(a) -> int:
    if a.list or not a.names:
        for name, arc in ARCHIVES.items():
            print(f"{name:24s} {arc.url}")
        return 0
    for name in a.names:
        download(name, a.dest, a.base_url, a.sha256, keep_archive=a.keep_archive)
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
    rp.add_argument("--profile", default="full", help=f"a profile of {REGISTRY.name}: tiny, quick or full")
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

    dl = sub.add_parser("download", help="fetch the papers' TUM / Bonn sequences (resumable, verified)")
    dl.add_argument("names", nargs="*", metavar="NAME", help="e.g. fr3_walking_xyz bonn_crowd (--list)")
    dl.add_argument("--dest", default=str(Path("build") / "datasets"), help="download cache folder")
    dl.add_argument("--list", action="store_true", help="list the known sequences and their URLs")
    dl.add_argument("--base-url", default=None, help="a mirror serving the same archive file names")
    dl.add_argument("--sha256", default=None, help="expected checksum (one NAME)")
    dl.add_argument("--keep-archive", action="store_true", help="keep the .tgz/.zip after unpacking")
    dl.set_defaults(func=cmd_download)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (SequenceError, DownloadError, ValueError, FileNotFoundError, FileExistsError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
