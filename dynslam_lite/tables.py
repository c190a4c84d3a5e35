"""Results tables in the papers' layouts: published columns (labelled) beside measured ones.

Input is the batch's evaluated runs (:class:`dynslam_lite.experiments.RunRecord`), looked up by
sequence and run label; which runs exist is set in :mod:`dynslam_lite.experiments`. Each function
returns ``(header, rows, notes)``; :func:`write_all` writes them all. Metrics are the attributes of
:class:`dynslam_lite.evaluation.TrajectoryErrors`: ``ate`` (m), ``rpe_trans`` (m/s), ``rpe_rot_deg``.
"""
from __future__ import annotations

from . import experiments as E
from . import published as P
from .evaluation import ErrorStats, MaskScores
from .masks import MISSED
from .experiments import RunRecord
from .reports import fmt
from .synth.scene import EXPOSURE_SCENES

Table = tuple[list[str], list[list], str]
Index = dict[tuple[str, str], RunRecord]


def _index(results: list[RunRecord]) -> Index:
    return {(r.sequence, r.label): r for r in results}


def _real(results: list[RunRecord], tums=()) -> list[str]:
    """Real sequences measured, except those filling the paper rows of the TUM names ``tums``
    (see :func:`_paper_rows`): the rows below a paper's own."""
    placed = {_tum_real(results, t) for t in tums}
    return sorted({r.sequence for r in results if r.is_real} - placed)


def _tum_real(results: list[RunRecord], tum: str) -> str | None:
    """'real/<folder>' when the TUM sequence ``tum`` ('fr3/walking_xyz') itself was measured (a
    folder named as TUM's archive unpacks, e.g. from ``download``), else None."""
    seq = f"real/{P.TUM_FOLDER[tum]}"
    return seq if any(r.sequence == seq for r in results) else None


def _paper_rows(results: list[RunRecord], row: str, tum: str) -> list[tuple[str, str | None, bool]]:
    """Where paper row ``row`` (TUM sequence ``tum``) is measured: (first cell, sequence, with the
    published cells). The TUM sequence itself fills the paper's own row when it was measured, and
    the synthetic analogue follows as its own row; without it the analogue stands in the row."""
    scene = P.SYNTHETIC_ANALOGUE.get(tum)
    synthetic = f"synthetic/{scene}" if scene else None
    real = _tum_real(results, tum)
    if real is None:
        return [(row, synthetic, True)]
    return [(row, real, True)] + ([(f"synthetic analogue of {row}", synthetic, False)] if synthetic else [])


def _labels(*runs: E.Run) -> tuple[str, ...]:
    return tuple(r.label for r in runs)


def _metric(r: RunRecord, metric: str) -> ErrorStats:
    return getattr(r.errors, metric)


def _ours(results: list[RunRecord]) -> list[str]:
    """Our object scenes present in ``results`` ('synthetic/walking_carry', ...), in their order."""
    present = {r.sequence for r in results}
    return [f"synthetic/{s}" for s in E.OBJECT_SCENES if f"synthetic/{s}" in present]


def _ours_head(idx, seq: str, methods) -> list:
    """First cells of a row of our object scenes (no paper row: labelled as ours)."""
    return [f"ours: {seq.split('/', 1)[1]} (no paper row)", seq, _frames(idx, seq, methods)]


def _real_head(idx, seq: str, methods) -> list:
    """First cells of a real-data row: folder name, where measured, frames."""
    return [seq.split("/", 1)[1], seq, _frames(idx, seq, methods)]


def _frames(idx, seq: str, methods) -> str:
    n = {idx[(seq, m)].frames for m in methods if (seq, m) in idx}
    return "/".join(str(x) for x in sorted(n)) or "-"


def _ranges(runs: list[tuple[int, int]]) -> str:
    """'24-35, 60-71 and 96-107' from [(24, 35), (60, 71), (96, 107)]."""
    text = [f"{a}-{b}" for a, b in runs] or ["none"]
    return " and ".join([", ".join(text[:-1]), text[-1]]) if len(text) > 1 else text[0]


def _get(idx, seq, method, metric, stat):
    r = idx.get((seq, method))
    v = getattr(_metric(r, metric), stat) if r else None
    return "-" if v is None else fmt(v, 4)


def _stats(idx, seq, method, metric: str, keys: tuple[str, ...]) -> str:
    """Statistics ``keys`` of one measured metric joined by ' / ', '-' when not measured."""
    r = idx.get((seq, method))
    return " / ".join(fmt(getattr(_metric(r, metric), k), 4) for k in keys) if r else "-"


def _triple(idx, seq, method) -> str:
    return _stats(idx, seq, method, "ate", ("max", "min", "rmse"))


PAPER_A_MEASURED = _labels(E.STATIC_DENSE, E.OPENCV_ODOMETRY, E.DEPTHCLUSTER)


def paper_a_table1(results: list[RunRecord]) -> Table:
    """Paper A, Table 1: RPE RMSE (m/s | deg/s), published DVO/BaMVO/ref.[19]/paper A beside
    measured static-dense (our DVO-like baseline), opencv-odometry and depthcluster."""
    idx = _index(results)
    ms = PAPER_A_MEASURED
    header = (["sequence", "measured on", "frames"]
              + [f"{m} (published) m/s" for m in P.A_TABLE1_METHODS]
              + [f"{m} (measured) m/s" for m in ms]
              + [f"{m} (published) deg/s" for m in P.A_TABLE1_METHODS]
              + [f"{m} (measured) deg/s" for m in ms])
    rows = []
    for name, (trans, rot) in P.A_TABLE1.items():
        for first, seq, pub in _paper_rows(results, name, name):
            rows.append(
                [first, seq or "- (no analogue)", _frames(idx, seq, ms) if seq else "-"]
                + (list(trans) if pub else ["-"] * 4) + [_get(idx, seq, m, "rpe_trans", "rmse") for m in ms]
                + (list(rot) if pub else ["-"] * 4) + [_get(idx, seq, m, "rpe_rot_deg", "rmse") for m in ms]
            )
    for seq in _real(results, P.A_TABLE1):
        rows.append(_real_head(idx, seq, ms)
                    + ["-"] * 4 + [_get(idx, seq, m, "rpe_trans", "rmse") for m in ms]
                    + ["-"] * 4 + [_get(idx, seq, m, "rpe_rot_deg", "rmse") for m in ms])
    notes = ("Published columns: the numbers printed in paper A (TUM sequences, full length). "
             "Measured columns: this project's code on the data in 'measured on' (real = the TUM "
             "sequence itself, the paper's row; synthetic = the embedded generator's analogue of "
             "it, not the TUM sequence), "
             "RPE over 1-s pairs as TUM's evaluate_rpe.py, RMSE. static-dense plays the part of "
             "DVO (same dense photometric + depth model, no dynamic handling). '-' = not measured "
             "(no analogue, or the clip is shorter than 1 s).")
    return header, rows, notes


def paper_a_table2(results: list[RunRecord]) -> Table:
    """Paper A, Table 2: ATE max / min / RMSE (m) on the walking sequences."""
    idx = _index(results)
    ms = PAPER_A_MEASURED
    header = (["sequence", "measured on", "frames"]
              + [f"{m} (published) max / min / RMSE" for m in P.A_TABLE2_METHODS]
              + [f"{m} (measured) max / min / RMSE" for m in ms])
    rows = []
    for name, pub in P.A_TABLE2.items():
        for first, seq, with_pub in _paper_rows(results, name, name):
            rows.append([first, seq, _frames(idx, seq, ms)]
                        + [" / ".join(f"{v:.4f}" for v in p) if with_pub else "-" for p in pub]
                        + [_triple(idx, seq, m) for m in ms])
    for seq in _real(results, P.A_TABLE2):
        rows.append(_real_head(idx, seq, ms) + ["-"] * 3
                    + [_triple(idx, seq, m) for m in ms])
    notes = ("ATE after SE(3) alignment (evo, 0.02 s association), metres. Published: paper A's "
             "Table 2 (ORB-SLAM2 and ref. [5] as printed there). Measured: this project on the data "
             "in 'measured on'.")
    return header, rows, notes


def _area(r: RunRecord, key: str) -> str:
    """A removed fraction of the run's extras as a percentage, '-' when not recorded."""
    return f"{100.0 * r.extras[key]:.1f}" if key in r.extras else "-"


def _moving_pr(r: RunRecord, key: str) -> list:
    """Precision / recall / IoU of a scored mask where something moves, else '-'."""
    c = r.scores.get(key)
    return [c.precision, c.recall, c.iou] if c is not None and c.tp + c.fn > 0 else ["-"] * 3


def paper_a_masks(results: list[RunRecord]) -> Table:
    """depthcluster's moving-object masks: the area removed on every sequence, and pixel precision
    / recall / IoU against the synthetic truth where there is one."""
    header = ["sequence", "frames", "pre-removal area (%)", "pose area (%)", "final area (%)", "pre-removal P",
              "pre-removal R", "pre-removal IoU", "pose P", "pose R", "pose IoU", "final P", "final R", "final IoU",
              "mean updates"]
    rows = []
    for r in results:
        if r.label != E.DEPTHCLUSTER.label:
            continue
        moving = "pixels/final" in r.scores and r.scores["pixels/final"].tp + r.scores["pixels/final"].fn > 0
        pre = _moving_pr(r, "pixels/preremoval") if "pixels/preremoval" in r.scores else [0.0, 0.0, 0.0]
        rows.append([r.sequence, r.frames, *(_area(r, f"removed_area_{k}") for k in ("preremoval", "pose", "final")),
                     *(pre if moving else ["-"] * 3), *_moving_pr(r, "pixels/pose"), *_moving_pr(r, "pixels/final"),
                     r.extras.get("mean_updates", "-")])
    notes = ("Area: mean fraction of each reference frame's pixels removed by pre-removal (step 2, "
             "depth-change blocks), excluded from the final pose ('pose': pre-removal and the background "
             "update, step 4) and reported as moving in the end ('final': the pose's mask less the pixels "
             "the final pose explains, our release step); on static_xyz nothing moves and every removed "
             "pixel is static room (paper A's fig. 7(f): nothing should be). "
             "P / R / IoU: pooled over all reference frames against the generator's ground-truth masks "
             "of the moving objects ('-' where nothing moves or on real data). A pixel the person covers in "
             "the current frame but not in the reference counts as a false positive here, although "
             "removing it is right (its residual is corrupted): precision is a lower bound. "
             "'mean updates': background updates that re-estimated the pose, per frame pair.")
    return header, rows, notes


def _measured(results: list[RunRecord], sequences: list[str], runs: list) -> list[tuple]:
    """The (sequence, run, record) of every run of ``runs`` measured on each of ``sequences``, in
    that order (a table's rows)."""
    idx = _index(results)
    return [(seq, run, idx[seq, run.label]) for seq in sequences for run in runs if (seq, run.label) in idx]


def _missed_frames(found: list[tuple], missed: list) -> int:
    """The most frames of a run of ``missed`` among ``found`` (what its missed-detection rule
    spans; 0 when none ran)."""
    return max((r.frames for _, run, r in found if run in missed), default=0)


def paper_a_ablation(results: list[RunRecord]) -> Table:
    """What each of our additions to paper A adds: the paper alone, each addition by itself, all."""
    header = ["sequence", "configuration", "run label", "ATE RMSE (m)", "RPE RMSE (m/s)", "failed frames",
              "pose area (%)", "pose P", "pose R", "final area (%)", "final P", "final R", "final IoU"]
    seqs = sorted({r.sequence for r in results if r.label == E.DC_PAPER.label},
                  key=lambda s: (s.startswith("real/"), s))
    rows = [[seq, run.description, run.label, r.errors.ate.rmse, r.errors.rpe_trans.rmse, r.failed_frames,
             _area(r, "removed_area_pose"), *_moving_pr(r, "pixels/pose")[:2], _area(r, "removed_area_final"),
             *_moving_pr(r, "pixels/final")]
            for seq, run, r in _measured(results, seqs, E.PAPER_A_ABLATION)]
    notes = ("Measured, depthcluster without semantic masks (paper A uses none). 'paper A only': "
             "pre-removal takes the whole largest region of the moving layer, the background update "
             "takes outlier pixels only, each frame pair starts from no prior, and the mask reported "
             "is the one the pose was estimated without. Then each addition of ours alone: 'prior' "
             "(the previous pair's mask carried into this pair's first estimate), 'grow' (a "
             "depth-layer region mostly made of outliers is taken whole), 'cut' (a pre-removal region "
             "larger than 25 % of the image, a floor or wall sharing the person's layer, is cut to "
             "the dynamic blocks and their neighbours), 'brightness' (a gain and bias of the image "
             "brightness estimated with the pose, and the residuals of the update read under them: a "
             "camera with automatic exposure brightens or darkens the whole image between frames), 'gate' "
             "(a correspondence whose transformed reference depth and current depth differ by more than "
             "7 cm, OpenCV's RGB-D odometry's maxDepthDiff, is left out of both terms of the solver: two "
             "surfaces meet there, an occluding or disoccluded one such as a person entering the view); "
             "the default has these five, the pose selection and the release. 'no-brightness' is the "
             "default with eq. 5's photometric term as printed, 'no-gate' the default with every "
             "correspondence in the solver. "
             "'no-select' is the default reporting always the last estimate of a pair; "
             "the default reports the prediction or an earlier estimate instead when its median absolute "
             "photometric residual over the textured reference pixels is more than 25 % lower and its "
             "median depth residual not higher (DepthClusterConfig.select_margin, select_min_gradient, "
             "select_depth: a pose that followed the people leaves most of the static room misaligned). "
             "The release: the removed pixels that the final pose explains (photometric and depth inliers "
             "outside regions full of outliers) go back to the background. The release changes the reported "
             "mask only, not the pose: compare 'pose' and 'final' columns of the default row. "
             "Common to every row: the solver at half resolution and the early stop when the mask is "
             "stable (DepthClusterConfig). Area: mean fraction of the reference pixels; P / R / IoU: "
             "pooled against the synthetic ground truth of the moving objects ('-' on real data). "
             "An addition that does not help on a sequence shows as no gain or a loss.")
    return header, rows, notes


def _reduction(idx, seq, metric, method, base) -> float | None:
    """RMSE reduction (%) of ``method`` against ``base`` on ``seq``; None when either is missing."""
    a, b = idx.get((seq, base)), idx.get((seq, method))
    if not a or not b or not _metric(a, metric).rmse or _metric(b, metric).rmse is None:
        return None
    return 100.0 * (1.0 - _metric(b, metric).rmse / _metric(a, metric).rmse)


def _pct(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f}"


STATIC_BASELINES = _labels(*E.STATIC_BASELINES)  # the papers' DVO and ORB-SLAM2 stand-ins


def summary(results: list[RunRecord]) -> Table:
    """Every method x every sequence: ATE RMSE, 1-s RPE, failed frames, and the RMSE reduction
    against the static baselines (the papers' headline percentages, measured)."""
    idx = _index(results)
    header = ["sequence", "frames", "method", "ATE RMSE (m)", "ATE max (m)", "ATE min (m)",
              "RPE trans RMSE (m/s)", "RPE rot RMSE (deg/s)", "failed frames"]
    header += [f"{m} reduction vs {b} (%)" for b in STATIC_BASELINES for m in ("ATE", "RPE")]
    rows = [[r.sequence, r.frames, r.label, r.errors.ate.rmse, r.errors.ate.max,
             r.errors.ate.min, r.errors.rpe_trans.rmse, r.errors.rpe_rot_deg.rmse,
             r.failed_frames]
            + [_pct(_reduction(idx, r.sequence, metric, r.label, b)) if r.label != b else "-"
               for b in STATIC_BASELINES for metric in ("ate", "rpe_trans")]
            for r in results]
    notes = ("Measured by `python -m dynslam_lite reproduce` on the data named in the first column "
             "(synthetic = the embedded generator). ATE: SE(3)-aligned, 0.02 s association; RPE: "
             "1-s pairs as TUM's evaluate_rpe.py ('-' where the clip is shorter than 1 s). "
             "Reduction = 1 - RMSE(method) / RMSE(baseline) on the same sequence, in % (negative: "
             "worse than the baseline): `static-dense` stands in for DVO (paper A's baseline), "
             "`static-orb` for ORB-SLAM2 (papers B and C).")
    return header, rows, notes


# --------------------------------------------------------------------------- paper B

PAPER_B_MEASURED = _labels(E.STATIC_ORB, E.WEIGHTEDSTATIC)
ORB, WS, BG = E.STATIC_ORB.label, E.WEIGHTEDSTATIC.label, E.BGRESTORE.label


def _stats3(idx, seq, method, metric) -> str:
    return _stats(idx, seq, method, metric, ("rmse", "median", "std"))




def _improvement(idx, seq, metric, method: str = WS) -> str:
    """RMSE reduction (%) of ``method`` against static-orb, '-' when either is missing."""
    return _pct(_reduction(idx, seq, metric, method, ORB))


def _paper_b_rpe_ate(results, table, metric, unit_note) -> Table:
    idx = _index(results)
    ms = PAPER_B_MEASURED
    header = ["sequence", "measured on", "frames", "ORB-SLAM2 (published) RMSE / median / S.D.",
              "paper B (published) RMSE / median / S.D.",
              f"{ORB} (measured) RMSE / median / S.D.",
              f"{WS} (measured) RMSE / median / S.D.", "RMSE reduction % (measured)"]
    rows = []
    for name, (orb, paper) in table.items():
        for first, seq, pub in _paper_rows(results, name, P.B_SEQUENCES[name]):
            rows.append([first, seq, _frames(idx, seq, ms)]
                        + ([" / ".join(map(str, orb)), " / ".join(map(str, paper))] if pub else ["-", "-"])
                        + [_stats3(idx, seq, ORB, metric), _stats3(idx, seq, WS, metric),
                           _improvement(idx, seq, metric)])
    for seq in _ours(results):
        rows.append(_ours_head(idx, seq, ms) + ["-", "-"]
                    + [_stats3(idx, seq, m, metric) for m in ms] + [_improvement(idx, seq, metric)])
    for seq in _real(results, [P.B_SEQUENCES[n] for n in table]):
        rows.append(_real_head(idx, seq, ms) + ["-", "-"]
                    + [_stats3(idx, seq, m, metric) for m in ms] + [_improvement(idx, seq, metric)])
    notes = (f"{unit_note} Published: paper B's table as printed (TUM fr3 sequences). Measured: "
             "static-orb (this project's ORB-SLAM2-like frontend, no dynamic handling) in place of "
             "ORB-SLAM2, and weightedstatic, on the data in 'measured on'. weightedstatic uses the "
             "ground-truth instance masks ('oracle') on synthetic data and, on real data, the "
             "bundled MediaPipe person model ('person'), a stand-in for the paper's YOLOv5s-seg; "
             "paper_b_ablation has the real runs without masks. Rows 'ours: ...' are this "
             "project's object scenes (carried, pushed and still objects, crowding; no paper "
             "measured them): paper_bc_objects has every configuration there.")
    return header, rows, notes


def paper_b_table1(results: list[RunRecord]) -> Table:
    """Paper B, Table 1: ATE (m) RMSE / median / S.D., ORB-SLAM2 and paper B."""
    return _paper_b_rpe_ate(results, P.B_TABLE1, "ate",
                            "ATE after SE(3) alignment (evo, 0.02 s association), metres.")


def paper_b_table2(results: list[RunRecord]) -> Table:
    """Paper B, Table 2: RPE (translation) RMSE / median / S.D."""
    return _paper_b_rpe_ate(results, P.B_TABLE2, "rpe_trans",
                            "RPE translation over 1-s pairs (m per second of motion; the paper "
                            "does not state its RPE interval).")


def _against_others(results, published: dict, others: tuple, measured: tuple, tum_of: dict, metric: str,
                    sd: str, notes: str) -> Table:
    """Published (RMSE, SD) of other systems beside measured RMSE / SD; then the real-data rows.
    ``tum_of``: the TUM sequence of each of the paper's row names."""
    idx = _index(results)
    header = (["sequence", "measured on", "frames"]
              + [f"{m} (published) RMSE / {sd}" for m in others]
              + [f"{m} (measured) RMSE / {sd}" for m in measured])

    def pair(seq, m):
        return _stats(idx, seq, m, metric, ("rmse", "std"))

    rows = [[first, seq, _frames(idx, seq, measured)]
            + ([f"{a} / {b}" for a, b in pubs] if pub else ["-"] * len(others))
            + [pair(seq, m) for m in measured]
            for name, pubs in published.items() for first, seq, pub in _paper_rows(results, name, tum_of[name])]
    rows += [_real_head(idx, seq, measured) + ["-"] * len(others) + [pair(seq, m) for m in measured]
             for seq in _real(results, [tum_of[n] for n in published])]
    return header, rows, notes


def paper_b_table3(results: list[RunRecord]) -> Table:
    """Paper B, Table 3: ATE RMSE / S.D. of other systems (published) and ours (measured)."""
    return _against_others(results, P.B_TABLE3, P.B_TABLE3_METHODS, PAPER_B_MEASURED, P.B_SEQUENCES, "ate",
                           "S.D.", "ATE (m) after SE(3) alignment. Published: paper B's Table 3. "
                           "Measured: this project on the data in 'measured on'; the other systems "
                           "are not re-run here.")


def paper_b_table4(results: list[RunRecord]) -> Table:
    """Paper B, Table 4: tracking time per frame, published (GPU) and measured (this CPU)."""
    header = ["system", "where", "total ms/frame", "stages (ms/frame)"]
    rows = [[name, "published, GTX 1650 GPU", total,
             ", ".join(f"{k} {v}" for k, v in stages.items()) or "-"]
            for name, (total, stages) in P.B_TABLE4.items()]
    for m in PAPER_B_MEASURED:
        runs = [r for r in results if r.label == m and r.stages]
        synthetic = [r for r in runs if not r.is_real]
        real = [r for r in runs if r.is_real]
        picks = ([max(synthetic, key=lambda r: (r.frames, r.sequence == "synthetic/walking_xyz"))]
                 if synthetic else []) + real[:1]
        for r in picks:
            stages = ", ".join(f"{k} {v:.1f}" for k, v in r.stages.items())
            rows.append([m, f"measured, {r.sequence}", f"{r.ms_per_frame:.1f}", stages])
    notes = ("Measured: mean milliseconds per frame of each stage during the reproduction run on "
             "this CPU (2 cores, other runs in parallel, machine-dependent; "
             "`python -m dynslam_lite bench --methods static-orb weightedstatic` measures alone). "
             "'masks' is the mask source: on synthetic data reading ground-truth masks, on real "
             "data the bundled person model on the CPU (the segmentation time, beside the paper's "
             "YOLOv5s-seg on a GPU); 'pose' holds the robust first "
             "estimate, the geometric test and the joint optimisation; local_ba runs on keyframes "
             "only and is averaged over all frames.")
    return header, rows, notes


def paper_b_ablation(results: list[RunRecord]) -> Table:
    """What the geometric test and the weights add over semantic masks alone (ATE RMSE, m)."""
    idx = _index(results)
    seqs = sorted({r.sequence for r in results if r.label in _labels(E.WS_DEGRADED, E.WS_NONE)})
    header = ["configuration", "run label"] + seqs
    rows = [[run.description, run.label] + [_get(idx, s, run.label, "ate", "rmse") for s in seqs]
            for run in E.PAPER_B_ABLATION if any((s, run.label) in idx for s in seqs)]
    notes = ("ATE RMSE (m), measured. 'oracle' = the generator's ground-truth person masks; "
             "'degraded' = the same, randomly dilated/eroded, dropped in 10 % of frames, with false "
             "blobs in 10 % of frames (`--masks oracle:degraded`), imitating a real network; "
             "'person model' = the bundled MediaPipe Selfie Segmentation model (`--masks person`, "
             "real data only: it is a stand-in for the paper's YOLOv5s-seg). "
             "'geometric test' without weights drops the geometrically dynamic points "
             "(`--set use_weights=false`); 'weights' without the test starts every weight at 1 "
             "(`--set use_geometry=false`). '-': not run on that sequence.")
    return header, rows, notes


def _defined_pr(c) -> tuple[float, float] | None:
    """(precision, recall) of a score, None where nothing truly moving was scored (both undefined)."""
    return (c.precision, c.recall) if c and c.tp + c.fn else None


def paper_b_points(results: list[RunRecord]) -> Table:
    """Precision / recall of the dynamic-point classification against ground truth."""
    header = ["sequence", "run", "frames", "matches", "dynamic matches (truth)",
              "geometric test P", "geometric test R", "geometric false alarms",
              "weights P", "weights R", "weights false alarms"]
    rows = []
    for r in results:
        g, w = r.score("points/geometric"), r.score("points/weights")
        if r.method != "weightedstatic" or not g:
            continue
        n, dyn = r.scored_points, g.tp + g.fn
        alarm = (lambda c: f"{c.fp} ({100.0 * c.fp / max(n - dyn, 1):.1f} %)")
        pr = (lambda c: list(_defined_pr(c) or ("-", "-")))
        rows.append([r.sequence, r.label, r.frames, n, dyn, *pr(g), alarm(g), *pr(w),
                     alarm(w) if w else "-"])
    notes = ("Over the matched semantic-static points of every frame: a point is truly dynamic when "
             "the ground-truth mask covers its keypoint. 'geometric test' = delta >= sigma2 "
             "(eq. 4); 'weights' = final weight below half its initial value. False alarms: static "
             "points judged dynamic (share of the static matches). With oracle masks almost no "
             "dynamic point survives the masks, so those rows measure false alarms only "
             "(precision and recall '-' where no dynamic point was matched).")
    return header, rows, notes


PAPER_C_MEASURED = _labels(E.STATIC_ORB, E.BGRESTORE)
C_MASKS = ("bgrestore uses the ground-truth instance masks ('oracle') on synthetic data and the "
           "bundled MediaPipe person model ('person', a stand-in for the paper's Mask R-CNN) on "
           "real data.")


def paper_c_table1(results: list[RunRecord]) -> Table:
    """Paper C, Table 1: ATE (m) RMSE / Mean / SD of ORB-SLAM2 and BR-SLAM, and the reduction."""
    idx = _index(results)
    ms = PAPER_C_MEASURED
    header = ["sequence", "measured on", "frames", "ORB-SLAM2 (published) RMSE / Mean / SD",
              "BR-SLAM (published) RMSE / Mean / SD", f"{ORB} (measured) RMSE / Mean / SD",
              f"{BG} (measured) RMSE / Mean / SD", "RMSE reduction % (measured)"]

    def cell(seq, m):
        return _stats(idx, seq, m, "ate", ("rmse", "mean", "std"))

    def gain(seq):
        return _improvement(idx, seq, "ate", BG)

    rows = [[first, seq, _frames(idx, seq, ms)]
            + ([" / ".join(map(str, orb)), " / ".join(map(str, paper))] if pub else ["-", "-"])
            + [cell(seq, ORB), cell(seq, BG), gain(seq)]
            for name, (orb, paper) in P.C_TABLE1.items()
            for first, seq, pub in _paper_rows(results, name, P.C_ANALOGUE[name])]
    rows += [_ours_head(idx, seq, ms) + ["-", "-", cell(seq, ORB), cell(seq, BG), gain(seq)]
             for seq in _ours(results)]
    rows += [_real_head(idx, seq, ms) + ["-", "-", cell(seq, ORB), cell(seq, BG), gain(seq)]
             for seq in _real(results, P.C_ANALOGUE.values())]
    notes = ("ATE after SE(3) alignment (evo), metres. Published: paper C's Table 1 (TUM fr3, 5-run "
             "means). Measured: static-orb (this project's ORB-SLAM2-like frontend) in place of "
             "ORB-SLAM2, and bgrestore, one run each on the data in 'measured on'. " + C_MASKS
             + " Rows 'ours: ...': this project's object scenes (paper_bc_objects).")
    return header, rows, notes


def _paper_c_other(results, table, metric, unit_note) -> Table:
    return _against_others(results, table, P.C_OTHER_METHODS, PAPER_C_MEASURED, P.C_ANALOGUE, metric, "SD",
                           f"{unit_note} Published: paper C; the other systems are not re-run here. "
                           + C_MASKS)


def paper_c_table2(results: list[RunRecord]) -> Table:
    """Paper C, Table 2: ATE RMSE / SD against other systems."""
    return _paper_c_other(results, P.C_TABLE2, "ate", "ATE (m) after SE(3) alignment.")


def paper_c_table3(results: list[RunRecord]) -> Table:
    """Paper C, Table 3: relative translation error RMSE / SD."""
    return _paper_c_other(results, P.C_TABLE3, "rpe_trans",
                          "RTE: measured over 1-s pairs (m per second); the paper does not state its "
                          "interval, so published and measured values may differ in scale.")


def paper_c_table4(results: list[RunRecord]) -> Table:
    """Paper C, Table 4: relative rotation error RMSE / SD."""
    return _paper_c_other(results, P.C_TABLE4, "rpe_rot_deg",
                          "RRE (deg): measured over 1-s pairs (deg per second); the paper does not "
                          "state its interval.")


def paper_c_restoration(results: list[RunRecord]) -> Table:
    """How much of the removed area bgrestore restored from keyframes and by region growing."""
    header = ["sequence", "run", "frames", "removed px / frame", "restored from keyframes %",
              "depth by region growing %", "ATE RMSE (m)"]
    rows = []
    for r in results:
        ex = r.extras
        if r.method != "bgrestore":
            continue
        removed = ex.get("removed_px_per_frame")
        rows.append([r.sequence, r.label, r.frames, "-" if removed is None else f"{removed:.0f}",
                     "-" if removed is None else f"{100 * ex['restored_fraction']:.1f}",
                     "-" if removed is None else f"{100 * ex['depth_grown_fraction']:.1f}",
                     r.errors.ate.rmse])
    notes = ("Removed: the dilated instances judged dynamic (semantic + epipolar). Restored: removed "
             "pixels that received keyframe colour and depth (eq. 8-9); region growing: removed "
             "pixels no keyframe saw, given depth by 3-class Otsu region growing. Runs: "
             "'[no-restore]' removes without restoring, '[map-restored]' lets a keyframe's keypoints in "
             "restored pixels become map points (ORB-SLAM2 on the restored frames; default: matched only), "
             "'[adjacent]' compares adjacent frames as the "
             "paper does (frame_gap=1; default 6 frames), '[2-views]' and '[all-views]' restore each "
             "hole pixel from the newest 2 / all keyframes that reach it (default: the newest one; all "
             "= eq. 9 as printed), so these choices are measured. Time per frame: "
             "tables/timing.md.")
    return header, rows, notes


def paper_bc_objects(results: list[RunRecord]) -> Table:
    """Papers B and C on our object scenes: every configuration's ATE, and what its dynamic
    points / removed pixels were against the ground truth of every moving object."""
    header = ["sequence", "configuration", "run label", "ATE RMSE (m)", "failed frames",
              "dynamic points P / R (geometric / epipolar test)", "new keypoints kept out of the map P / R",
              "every verdict (dynamic points and new keypoints) P / R", "removed pixels P / R"]

    def joint(a: MaskScores, b: MaskScores) -> MaskScores:
        """The verdicts of two scores pooled."""
        return MaskScores.from_counts(a.tp + b.tp, a.fp + b.fp, a.fn + b.fn)

    def pr(c: MaskScores | None) -> str:
        if c is None:
            return "-"
        if c.tp + c.fp == 0:  # the run judged nothing dynamic: precision undefined
            return f"- (none judged dynamic; {c.fn} moving missed)" if c.fn else "-"
        p = _defined_pr(c)
        return f"{fmt(p[0], 2)} / {fmt(p[1], 2)}" if p else f"- (no moving match; {c.fp} false alarms)"

    rows = []
    found = _measured(results, _ours(results), E.OBJECT_ROWS + E.MISSED_ROWS)
    missed_frames = _missed_frames(found, E.MISSED_ROWS)
    for seq, run, r in found:
        points = r.score("points/moved" if run.method == "bgrestore" else "points/geometric")
        new = r.score("points/new")
        rows.append([seq, run.description, run.label, r.errors.ate.rmse, r.failed_frames,
                     pr(points), pr(new), pr(joint(points, new)) if points and new else "-",
                     pr(r.score("pixels/removed"))])
    notes = ("ATE RMSE (m) after SE(3) alignment, on this project's object scenes: walking_carry "
             "(a board and a box carried across the view: moving, not people), walking_push (a "
             "large printed box pushed 1.6 m about 2 m ahead of the moving camera; a person "
             "standing still for 2 s), crowd "
             "(three people, one passing close to the camera; people cover up to half the "
             "image). 'oracle' masks are the person class only (what a person detector gives); "
             "'oracle:all' every object instance with its class (paper C's Mask R-CNN); "
             f"'oracle:missed' (crowd) the person masks with every person covering more than "
             f"{MISSED.near_fraction * 100:g} % of the image missed in frames {_ranges(MISSED.near_miss_ranges(missed_frames))} "
             "(a detector losing the people close to the camera). Truth for "
             "P / R: the ground-truth mask of every moving object (people, board, boxes). "
             "'dynamic points': matched keypoints outside the masks judged dynamic by the "
             "geometric test (weightedstatic) or by their epipolar distance (bgrestore, ours: not "
             f"tracked; '{E.BG_INSTANCES.label}' tracks them, as the paper); 'new keypoints kept "
             "out of the map': a new keyframe's keypoints the free-space test keeps from becoming "
             f"map points (weightedstatic and bgrestore, ours; '{E.WS_NO_SCREEN.label}' and "
             f"'{E.BG_NO_SCREEN.label}' let them in), scored "
             "against the same truth: a moving point kept out is never matched, so it leaves the "
             "matched points' recall; 'every verdict': both counts pooled, each match in each frame "
             "and each new keypoint of a keyframe one verdict (the tests' recall over every moving "
             "point they judged, however it was caught; '-' where only one test ran); "
             "'removed pixels': the dilated instances bgrestore removed. "
             "'consistent' = the pose optimised on the matches PnP-RANSAC finds "
             "consistent (ours, FrontendConfig.consistent_pose): weightedstatic's first pose uses "
             "it by default ('orb-first-pose': ORB-SLAM2's optimisation instead), bgrestore only "
             f"in '{E.BG_CONSISTENT.label}'. Compare weightedstatic with "
             f"{E.STATIC_ORB_CONSISTENT.label} for what the geometric test and the weights add "
             f"beyond that pose (weightedstatic also drops keypoints within 10 px of the masks, ours; "
             f"'{E.WS_NO_DILATE.label}' takes the masks as given), and bgrestore with "
             f"{E.STATIC_ORB_ORACLE.label} for what removal and restoration add. "
             f"{E.STATIC_ORB_MOVING.label} masks every moving object with the ground truth (no "
             "method knows it): what removing the moving objects perfectly gives, the bound of "
             "every row above. Where it is no better than masks only, no handling of moving objects "
             "has anything to gain on that scene. A step that does not help "
             "on a scene shows as no gain; notebook 20 has the geometric test with the true poses "
             "and our along-line variant on walking_carry.")
    return header, rows, notes


def paper_bc_real(results: list[RunRecord]) -> Table:
    """Papers B and C on the real clips: masks alone, each paper's steps switched off one at a
    time, and a person model that misses the near people for a while."""
    header = ["sequence", "configuration", "run label", "ATE RMSE (m)", "RPE trans RMSE (m/s)", "failed frames"]
    found = _measured(results, _real(results), E.REAL_BC_ROWS)
    missed_frames = _missed_frames(found, E.MISSED_REAL_ROWS)
    rows = [[seq, run.description, run.label, r.errors.ate.rmse, r.errors.rpe_trans.rmse, r.failed_frames]
            for seq, run, r in found]
    notes = ("ATE RMSE (m) after SE(3) alignment and 1-s RPE on the real clips against their "
             "motion-capture poses, with the bundled person model as the mask source (a stand-in for "
             "the papers' networks). 'person:missed': the model's masks with every instance covering "
             f"more than {MISSED.near_fraction * 100:g} % of the image dropped in frames "
             f"{_ranges(MISSED.near_miss_ranges(missed_frames))} (the frames 'oracle:missed' drops on "
             "synthetic crowd): a detector losing the people close to the camera, here on real people "
             f"walking. Masks alone ({E.STATIC_ORB_PERSON.label} and the static-orb rows below it) "
             "against paper B (weightedstatic) and paper C (bgrestore) is what each paper's steps add "
             "over masking people; the '[no-screening]' rows leave out our free-space screening of a "
             "keyframe's new keypoints, so they show what the paper's own test holds by itself "
             "(B's weighted geometric test and weights, C's epipolar removal of the matches outside "
             "every mask); the other labels are those of tables/paper_bc_objects.md. One run per "
             "cell: tables/sensitivity.md says how far one run moves. Real clips only with `--data`.")
    return header, rows, notes


def sensitivity(results: list[RunRecord]) -> Table:
    """How much one ATE moves under a change that should not matter (the keypoint budget 1 %
    lower or higher), on our object scenes and the real clips: the spread a single number carries."""
    idx = _index(results)
    header = ["sequence", "method", "ATE RMSE (m), default", *[f"{n} keypoints" for n in E._BUDGETS],
              "mean", "max / min"]
    rows = []
    for seq in _ours(results) + _real(results):
        for base, variants in E.SENSITIVITY_OF.items():
            runs = [idx.get((seq, r.label)) for r in (base, *variants)]
            if any(r is None for r in runs):
                continue
            ate = [r.errors.ate.rmse for r in runs]
            rows.append([seq, base.label, *ate, sum(ate) / len(ate), f"{max(ate) / min(ate):.2f}"])
    notes = ("ATE RMSE (m) of weightedstatic and bgrestore (oracle masks on our object scenes, the "
             "person model on the real clips) with the default 1000 ORB keypoints per frame and "
             "with 1 % fewer or more. Nothing that should matter changes, yet keypoints near the "
             "budget's cut come and go, the matches and keyframes with them: the spread is the "
             "noise of one run, and differences between configurations smaller than it say "
             "nothing. The same code on another machine of this kind moves a run as much or more "
             "(floating-point differences grow through the tracking; bgrestore on walking_push "
             "1.8x between two machines, see the README). Real clips only with `--data`.")
    return header, rows, notes


def _every(n: int) -> str:
    return "every frame" if n == 1 else f"every {({2: '2nd', 3: '3rd'}).get(n, f'{n}th')} frame"


def real_frame_rate(results: list[RunRecord]) -> Table:
    """The main methods on each real clip tracked every frame and at the registry's lower frame
    rates (every 2nd, 3rd frame): how each copes with larger motion between frames."""
    strides = E.strides()
    idx = {(r.sequence, r.label, r.stride): r for r in results}
    header = ["sequence", "method", "frames", *[f"ATE RMSE (m), {_every(n)}" for n in strides],
              "failed frames", "worst / every frame"]
    rows = []
    for seq in sorted({r.sequence for r in results if r.is_real and r.stride > 1}):
        for run in E.FRAME_RATE_ROWS:
            recs = [idx.get((seq, run.label, n)) for n in strides]
            if recs[0] is None or all(r is None for r in recs[1:]):
                continue
            ate = [r.errors.ate.rmse if r else None for r in recs]
            worst = max(a for a in ate if a is not None)
            rows.append([seq, run.label, " / ".join(str(r.frames) if r else "-" for r in recs),
                         *[a if a is not None else "-" for a in ate],
                         " / ".join(str(r.failed_frames) if r else "-" for r in recs), f"{worst / ate[0]:.2f}"])
    notes = ("ATE RMSE (m) after SE(3) alignment of the main methods on each real clip tracked at every "
             "frame and at " + " and ".join(_every(n) for n in strides[1:]) + " (a 30 Hz recording at "
             + " and ".join(f"{30 / n:g} Hz" for n in strides[1:]) + "): the motion between frames "
             "grows as in the fast turns of a longer recording, and a person crosses more of the image "
             "between two frames. 'frames' and 'failed frames' per column, in the same order. Masks as in "
             "the other real rows (the person model for weightedstatic and bgrestore); "
             f"'{E.DC_NO_SELECT.label}' is depthcluster without its pose selection, "
             f"'{E.DC_NO_BRIGHTNESS.label}' without its brightness model, '{E.DC_NO_GATE.label}' without "
             "its depth gate. One run per cell: "
             "the sensitivity table says how far a single run moves. Real clips only with `--data`.")
    return header, rows, notes


def exposure(results: list[RunRecord]) -> Table:
    """Each method on a scene with automatic exposure and on the scene whose frames it shows at
    one exposure (walking_exposure and walking_xyz): ATE of both, and the frame-to-frame error of
    the pairs across an exposure change beside that of the other pairs."""
    idx = _index(results)
    header = ["scene (same frames at one exposure)", "method", "ATE RMSE (m), one exposure",
              "ATE RMSE (m), automatic exposure", "pair error (mm), across an exposure change",
              "pair error (mm), other pairs", "ratio"]
    rows = []
    for scene, base_scene in EXPOSURE_SCENES.items():
        for run in E.EXPOSURE_ROWS:
            r, base = idx.get((f"synthetic/{scene}", run.label)), idx.get((f"synthetic/{base_scene}", run.label))
            if r is None or "pair_error_mm_exposure_change" not in r.extras:
                continue
            at, other = r.extras["pair_error_mm_exposure_change"], r.extras["pair_error_mm_elsewhere"]
            rows.append([f"{scene} ({base_scene})", run.label, base.errors.ate.rmse if base else "-",
                         r.errors.ate.rmse, f"{at:.1f}", f"{other:.1f}", f"{at / other:.2f}"])
    notes = ("walking_exposure is walking_xyz (the same camera path, people, textures and sensor noise) "
             "seen by a camera with automatic exposure: every 10-13 frames the image brightness "
             "changes by a gain of 4-10 % and a new bias (the scene's exposure.txt; the median "
             "intensity of the room moves by 5-20 grey levels, up to 19 on the Bonn dev clip). Pair "
             "error: mean translation error of the frame-to-frame motion (1/30 s RPE), over the pairs "
             "across a change and over the others; ratio = the first over the second. "
             f"'{E.DC_NO_BRIGHTNESS.label}' is depthcluster with eq. 5's photometric term as printed. "
             "Masks as in the other synthetic rows (oracle for weightedstatic and bgrestore).")
    return header, rows, notes


def timing(results: list[RunRecord]) -> Table:
    """Wall-clock ms per frame of every run of the batch."""
    rows = [[r.name, r.label, f"{r.ms_per_frame:.1f}"] for r in results]
    notes = ("Wall-clock milliseconds per frame, whole pipeline, measured during the run on this "
             "machine with other jobs in parallel: varies between runs, unlike the error tables. "
             "The runs of a sequence in one worker share what they derive from its frames alone "
             "(ORB keypoints, masks, depth layers, paper A's pre-removal and paper C's removal of "
             "each frame); each run is charged the time their making took, so a row is what the "
             "method costs on its own. "
             "`python -m dynslam_lite bench` measures per stage.")
    return ["sequence", "method", "ms/frame"], rows, notes


# Every table of the batch: file stem under tables/, title, function of the evaluated runs, and
# whether it takes the runs on real clips at lower frame rates too (the others: every frame only).
REPORT_TABLES = (
    ("summary", "Every method on every sequence (measured)", summary, False),
    ("paper_a_table1", "Paper A, Table 1: relative pose error (RMSE)", paper_a_table1, False),
    ("paper_a_table2", "Paper A, Table 2: absolute trajectory error (m)", paper_a_table2, False),
    ("paper_a_masks", "Paper A: moving-object masks of depthcluster against ground truth", paper_a_masks, False),
    ("paper_a_ablation", "Paper A: what each of our additions to depthcluster adds (ablation)", paper_a_ablation, False),
    ("paper_b_table1", "Paper B, Table 1: absolute trajectory error (m)", paper_b_table1, False),
    ("paper_b_table2", "Paper B, Table 2: relative pose error (translation)", paper_b_table2, False),
    ("paper_b_table3", "Paper B, Table 3: ATE against other systems (m)", paper_b_table3, False),
    ("paper_b_table4", "Paper B, Table 4: tracking time per frame", paper_b_table4, False),
    ("paper_b_ablation", "Paper B: what the geometric test and the weights add over masks", paper_b_ablation, False),
    ("paper_b_points", "Paper B: dynamic-point classification against ground truth", paper_b_points, False),
    ("paper_bc_objects", "Papers B and C on our object scenes (carry, push, crowd)", paper_bc_objects, False),
    ("paper_bc_real", "Papers B and C on the real clips, and a person model that misses the near people", paper_bc_real,
     False),
    ("paper_c_table1", "Paper C, Table 1: ATE against the baseline (m)", paper_c_table1, False),
    ("paper_c_table2", "Paper C, Table 2: ATE against other systems (m)", paper_c_table2, False),
    ("paper_c_table3", "Paper C, Table 3: relative translation error", paper_c_table3, False),
    ("paper_c_table4", "Paper C, Table 4: relative rotation error", paper_c_table4, False),
    ("paper_c_restoration", "Paper C: removed and restored area", paper_c_restoration, False),
    ("exposure", "Automatic exposure: what a change of the image brightness costs", exposure, False),
    ("sensitivity", "How far one ATE moves when nothing that matters changes", sensitivity, False),
    ("real_frame_rate", "Real clips at lower frame rates: larger motion between frames", real_frame_rate, True),
    ("timing", "Time per frame of every run (machine-dependent)", timing, True),
)


def write_all(results: list[RunRecord], root, source: str) -> list[str]:
    """Write every table of :data:`REPORT_TABLES` under ``root/tables`` (``source`` ends each
    table's notes: the command and data). Runs on a real clip at a lower frame rate go to the
    tables flagged for them only. Returns the stems written."""
    from .reports import write_table

    every_frame = [r for r in results if r.stride == 1]
    for stem, title, make, strided in REPORT_TABLES:
        header, rows, notes = make(results if strided else every_frame)
        write_table(root, f"tables/{stem}", title, header, rows, notes=notes + " " + source)
    return [entry[0] for entry in REPORT_TABLES]
