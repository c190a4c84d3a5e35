"""Results tables in the papers' layouts: published columns (labelled) beside measured ones.

Input is a list of evaluated runs as produced by the batch reproduction: dicts with
``sequence`` ('synthetic/<scene>' or 'real/<folder>'), ``method``, ``frames``, ``ate_m``,
``rpe_trans_m_per_s``, ``rpe_rot_deg_per_s`` (stat dicts) and optional ``extras``.
Each function returns ``(header, rows, notes)`` for :meth:`dynslam_lite.reports.ReportWriter.table`.
"""
from __future__ import annotations

from . import published as P
from .reports import fmt

Table = tuple[list[str], list[list], str]


def _index(results: list[dict]) -> dict[tuple[str, str], dict]:
    return {(r["sequence"], r["method"]): r for r in results}


def _real(results: list[dict]) -> list[str]:
    return sorted({r["sequence"] for r in results if r["sequence"].startswith("real/")})


def _real_head(idx, seq: str, methods) -> list:
    """First cells of a real-data row: folder name, where measured, frames."""
    return [seq.split("/", 1)[1], seq, _frames(idx, seq, methods)]


def _frames(idx, seq: str, methods) -> str:
    n = {idx[(seq, m)]["frames"] for m in methods if (seq, m) in idx}
    return "/".join(str(x) for x in sorted(n)) or "-"


def _get(idx, seq, method, metric, stat):
    r = idx.get((seq, method))
    v = r[metric][stat] if r else None
    return "-" if v is None else fmt(v, 4)


def _triple(idx, seq, method) -> str:
    r = idx.get((seq, method))
    if not r:
        return "-"
    a = r["ate_m"]
    return f"{fmt(a['max'], 4)} / {fmt(a['min'], 4)} / {fmt(a['rmse'], 4)}"


PAPER_A_MEASURED = ("static-dense", "opencv-odometry", "depthcluster")


def paper_a_table1(results: list[dict]) -> Table:
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
        scene = P.SYNTHETIC_ANALOGUE.get(name)
        seq = f"synthetic/{scene}" if scene else None
        rows.append(
            [name, seq or "- (no analogue)", _frames(idx, seq, ms) if seq else "-"]
            + list(trans) + [_get(idx, seq, m, "rpe_trans_m_per_s", "rmse") for m in ms]
            + list(rot) + [_get(idx, seq, m, "rpe_rot_deg_per_s", "rmse") for m in ms]
        )
    for seq in _real(results):
        rows.append(_real_head(idx, seq, ms)
                    + ["-"] * 4 + [_get(idx, seq, m, "rpe_trans_m_per_s", "rmse") for m in ms]
                    + ["-"] * 4 + [_get(idx, seq, m, "rpe_rot_deg_per_s", "rmse") for m in ms])
    notes = ("Published columns: the numbers printed in paper A (TUM sequences, full length). "
             "Measured columns: this project's code on the data in 'measured on' (synthetic = the "
             "embedded generator's analogue of the TUM sequence, not the TUM sequence itself), "
             "RPE over 1-s pairs as TUM's evaluate_rpe.py, RMSE. static-dense plays the part of "
             "DVO (same dense photometric + depth model, no dynamic handling). '-' = not measured "
             "(no analogue, or the clip is shorter than 1 s).")
    return header, rows, notes


def paper_a_table2(results: list[dict]) -> Table:
    """Paper A, Table 2: ATE max / min / RMSE (m) on the walking sequences."""
    idx = _index(results)
    ms = PAPER_A_MEASURED
    header = (["sequence", "measured on", "frames"]
              + [f"{m} (published) max / min / RMSE" for m in P.A_TABLE2_METHODS]
              + [f"{m} (measured) max / min / RMSE" for m in ms])
    rows = []
    for name, pub in P.A_TABLE2.items():
        seq = f"synthetic/{P.SYNTHETIC_ANALOGUE[name]}"
        rows.append([name, seq, _frames(idx, seq, ms)]
                    + [" / ".join(f"{v:.4f}" for v in p) for p in pub]
                    + [_triple(idx, seq, m) for m in ms])
    for seq in _real(results):
        rows.append(_real_head(idx, seq, ms) + ["-"] * 3
                    + [_triple(idx, seq, m) for m in ms])
    notes = ("ATE after SE(3) alignment (evo, 0.02 s association), metres. Published: paper A's "
             "Table 2 (ORB-SLAM2 and ref. [5] as printed there). Measured: this project on the data "
             "in 'measured on'.")
    return header, rows, notes


def paper_a_masks(results: list[dict]) -> Table:
    """Pixel precision / recall / IoU of depthcluster's moving-object masks (synthetic truth)."""
    header = ["sequence", "frames", "pre-removal P", "pre-removal R", "pre-removal IoU",
              "final P", "final R", "final IoU", "mean updates"]
    rows = []
    for r in results:
        ex = r.get("extras") or {}
        if r["method"] != "depthcluster" or "mask" not in ex:
            continue
        pre, fin = ex["preremoval_mask"], ex["mask"]
        rows.append([r["sequence"], r["frames"], pre["precision"], pre["recall"], pre["iou"],
                     fin["precision"], fin["recall"], fin["iou"], ex.get("mean_updates", "-")])
    notes = ("Pooled over all reference frames against the generator's ground-truth masks of the "
             "people. 'pre-removal' = step 2 alone (depth-change blocks), 'final' = after the "
             "background update. A pixel the person covers in the current frame but not in the "
             "reference counts as a false positive here, although removing it is right (its "
             "residual is corrupted): precision is a lower bound.")
    return header, rows, notes


def summary(results: list[dict]) -> Table:
    """Every method x every sequence: ATE RMSE, 1-s RPE, failed frames."""
    header = ["sequence", "frames", "method", "ATE RMSE (m)", "ATE max (m)", "ATE min (m)",
              "RPE trans RMSE (m/s)", "RPE rot RMSE (deg/s)", "failed frames"]
    rows = [[r["sequence"], r["frames"], r["method"], r["ate_m"]["rmse"], r["ate_m"]["max"],
             r["ate_m"]["min"], r["rpe_trans_m_per_s"]["rmse"], r["rpe_rot_deg_per_s"]["rmse"],
             r["failed_frames"]] for r in results]
    notes = ("Measured by `python -m dynslam_lite reproduce` on the data named in the first column "
             "(synthetic = the embedded generator). ATE: SE(3)-aligned, 0.02 s association; RPE: "
             "1-s pairs as TUM's evaluate_rpe.py ('-' where the clip is shorter than 1 s).")
    return header, rows, notes
