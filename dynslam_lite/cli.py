"""Command line: ``python -m dynslam_lite {synth,run,evaluate,bench,reproduce,download}``."""
from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import sys
import threading
import time
import traceback
from pathlib import Path

from . import batch, experiments
from .download import ARCHIVES, download
from .errors import ConfigError, Interrupted, SequenceError, UserError
from .evaluation import evaluate
from .io import atomic_write_text, open_sequence, read_groundtruth, read_trajectory, write_trajectory
from .masks import SOURCES
from .pipeline import METHODS, parse_value, run_method, track_frames
from .synth import SCENES, generate

# bench: the methods of the papers' tables and their baselines
BENCHED = tuple(dict.fromkeys(r.method for r in experiments.MAIN))
# a run whose tracking failed on more than this share of frames exits with an error (1)
MAX_FAILED_SHARE = 0.5


def _parse_sets(items: list[str]) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise ConfigError(f"--set expects key=value, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = parse_value(v.strip())
    return out


def cmd_synth(a) -> int:
    st = generate(a.out_dir, a.scene, a.frames, a.seed, a.background, progress=not a.quiet)
    print(f"wrote {st.frames} frames of {a.scene} to {st.path} "
          f"({st.frames_per_s:.2f} frames/s)")
    return 0


def cmd_run(a) -> int:
    seq = open_sequence(a.seq_dir, a.camera, a.start, a.frames, step=a.stride)
    result = run_method(a.method, seq, _parse_sets(a.set), progress=not a.quiet, masks=a.masks)
    write_trajectory(a.out, result.trajectory)
    stats = result.stats()
    if a.stats:
        atomic_write_text(a.stats, json.dumps(stats, indent=2) + "\n")
    for i, reason in result.failed_frames:
        print(f"tracking failed on frame {i}: {reason}", file=sys.stderr)
    print(f"{a.method}: {stats['frames']} frames, {len(result.failed_frames)} failed, "
          f"{stats['ms_per_frame']:.1f} ms/frame, peak {stats['peak_mem_mib']:.0f} MiB -> {a.out}")
    n_failed, n = len(result.failed_frames), len(result.frames) - 1
    if n_failed > MAX_FAILED_SHARE * n:
        print(f"error: tracking failed on {n_failed} of {n} frame pairs of {seq.root}: {a.out} is mostly "
              "constant-velocity guesses, not a result", file=sys.stderr)
        return 1
    return 0


def cmd_evaluate(a) -> int:
    gt, est = read_groundtruth(a.gt, a.bonn), read_trajectory(a.est)
    try:
        errors = evaluate(gt, est)
    except ValueError as exc:  # no overlap in time, too few poses
        span = (lambda t: f"{t.timestamps[0]:.3f}-{t.timestamps[-1]:.3f} s, {len(t)} poses")
        raise SequenceError(f"{a.est} ({span(est)}) against {a.gt} ({span(gt)}): {exc}") from None
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

    The methods track the frames in lockstep: frame i of every method, in an order rotated from
    frame to frame, before frame i + 1 of any (:func:`~dynslam_lite.pipeline.track_frames`;
    ``--chunk`` frames at a time), so a shared machine that slows down for a few seconds slows
    every method alike. Measured on the first 40 frames of the Bonn dev clip, 4 rounds,
    depthcluster against opencv-odometry: one method after the other 1.19x (1.05-1.30) and
    1.28x (1.08-1.31), frame by frame 1.25x (1.24-1.29). A stage that runs
    on some frames only (later background updates) is averaged over the frames that ran it;
    'frames' says how many. With ``--repeat N`` this runs N rounds; the stages are those of the
    first round, the ratio to opencv-odometry is taken within each round and its median and
    range over the rounds printed. Peak memory is that of the process, all methods together
    (``run`` prints one method's).
    """
    import numpy as np

    if a.repeat < 1:
        raise ConfigError(f"--repeat {a.repeat}: the methods need at least one round")
    if a.chunk < 1:
        raise ConfigError(f"--chunk {a.chunk}: each turn tracks at least one frame")
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
    methods = list(dict.fromkeys(a.methods))
    masks_of = {}  # each method's mask source, as the tables run it (--masks replaces a semantic one)
    for method in methods:
        run = next(r for r in experiments.MAIN if r.method == method)
        spec = run.mask_source("real" if a.seq else "synthetic")
        masks_of[method] = a.masks if a.masks and spec != "none" else spec
    without_masks: dict[str, list[float]] = {m: [] for m in methods}  # ms/frame of each round
    for k in range(a.repeat):
        steps = {m: track_frames(m, seq, masks=masks_of[m]) for m in methods}
        for n, i in enumerate(range(0, len(seq), a.chunk)):
            turn = (n + k) % len(methods)
            for method in methods[turn:] + methods[:turn]:
                for _ in range(i, min(i + a.chunk, len(seq))):
                    next(steps[method])
        results = {}
        for method, step in steps.items():
            try:
                next(step)
            except StopIteration as done:
                results[method] = done.value
        for method, r in results.items():
            without_masks[method].append(
                (np.sum(r.frame_ms) - np.sum(r.stage_ms.get("masks", []))) / len(r.frame_ms))
            if k:
                continue
            if masks_of[method] != "none":
                print(f"{method:18s} (masks {masks_of[method]})")
            for stage, ms in r.stage_ms.items():
                print(f"{method:18s} {stage:10s} {np.mean(ms):9.1f} {np.median(ms):10.1f} {len(ms):7d}")
            s = r.stats()
            print(f"{method:18s} {'total':10s} {s['ms_per_frame']:9.1f} {np.median(r.frame_ms):10.1f}")
    print(f"peak memory of this process, the {len(methods)} methods together: "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0:.0f} MiB")
    if "opencv-odometry" in without_masks:  # speed claims: ratios within one round
        ref = np.asarray(without_masks["opencv-odometry"])
        n = len(ref)
        print("ms/frame without the mask source (segmentation), and the ratio to opencv-odometry "
              f"on the same frames in this run, {a.chunk} frame(s) per turn"
              f"{f' (median of {n} rounds, range of the ratio)' if n > 1 else ''}:")
        for method, ms in without_masks.items():
            ratio = np.asarray(ms) / ref
            spread = f"  ({ratio.min():.2f}-{ratio.max():.2f})" if n > 1 else ""
            print(f"{method:18s} {np.median(ms):9.1f} ms/frame  {np.median(ratio):5.2f}x opencv-odometry{spread}")
    return 0


def cmd_reproduce(a) -> int:
    """Batch reproduction on the embedded synthetic default (plus --data sequences)."""
    return batch.reproduce(batch.Options(a.profile, a.frames, a.data or [], a.seed, a.jobs, a.cache,
                                         a.reports, not a.no_notebooks, a.fresh, a.scheduler, a.data_root))


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
    r.add_argument("--stride", type=int, default=1,
                   help="track every N-th frame (3: a 30 Hz sequence at 10 Hz, larger motion between frames)")
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
    b.add_argument("--methods", nargs="+", default=list(BENCHED), choices=sorted(METHODS))
    b.add_argument("--repeat", type=int, default=1,
                   help="rounds over the frames, all methods in lockstep; prints the median ratio")
    b.add_argument("--chunk", type=int, default=1,
                   help="frames each method tracks before the next one takes its turn (--frames: "
                        "one method after the other)")
    b.add_argument("--cache", default=str(batch.DEFAULT_CACHE))
    b.add_argument("--masks", default=None,
                   help="mask source of weightedstatic (default: oracle on the synthetic scene, "
                        "person on --seq)")
    b.set_defaults(func=cmd_bench)

    rp = sub.add_parser("reproduce", help="batch reproduction into reports/")
    rp.add_argument("--profile", default="full",
                    help=f"a profile of {batch.REGISTRY.name}: tiny, quick, full, or papers (full plus every "
                         "paper sequence found under --data-root, whole)")
    rp.add_argument("--data-root", default=None, metavar="DIR",
                    help="where --profile papers looks for the papers' sequences (default build/datasets, "
                         "where `download` puts them)")
    rp.add_argument("--frames", type=int, default=None, help="override the profile's frame count")
    rp.add_argument("--data", action="append", help="real TUM/Bonn sequence folder (repeatable)")
    rp.add_argument("--seed", type=int, default=0)
    rp.add_argument("--jobs", type=int, default=2, help="worker processes")
    rp.add_argument("--cache", default=str(batch.DEFAULT_CACHE))
    rp.add_argument("--reports", default="reports")
    rp.add_argument("--fresh", action="store_true",
                    help="run every run again (default: take the runs finished earlier with the same code, "
                         "parameters and data from the run cache beside --cache, e.g. after an interruption)")
    rp.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="a Dask distributed scheduler (e.g. tcp://host:8786): the runs and notebooks go to "
                         "its workers, which must see this file system (README: on a cluster)")
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


def _stop_on_sigterm(signum, frame):
    raise KeyboardInterrupt  # SIGTERM stops a command as Ctrl-C does


def main(argv: list[str] | None = None) -> int:
    """Run a command. Exit codes: 0 done, 1 a run whose tracking mostly failed, 2 bad input or a
    failed step (one line: the file or key and the problem), 3 an internal error (a bug),
    130 interrupted (Ctrl-C or SIGTERM; nothing half-written)."""
    args = build_parser().parse_args(argv)
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _stop_on_sigterm) if in_main else None
    try:
        return args.func(args)
    except (KeyboardInterrupt, Interrupted) as exc:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C cannot break the clean-up
        batch.stop_children()
        what = str(exc) or f"{args.command} interrupted; nothing was written"
        print(f"\ninterrupted: {what}", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(130)  # worker threads blocked on killed processes must not delay the exit
    except (UserError, FileNotFoundError, FileExistsError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # anything else is a bug: say so, and where
        where = traceback.extract_tb(exc.__traceback__)[-1]
        print(f"internal error (a bug in dynslam_lite, please report it): {type(exc).__name__}: {exc}\n"
              f"  at {where.filename}:{where.lineno} in {where.name}; set DYNSLAM_DEBUG=1 for the "
              "whole traceback", file=sys.stderr)
        if os.environ.get("DYNSLAM_DEBUG"):
            traceback.print_exc()
        return 3
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, previous)
