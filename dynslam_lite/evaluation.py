"""Trajectory and mask metrics, on evo's maths.

- ATE: timestamps associated within 0.02 s (evo ``associate_trajectories``), SE(3) Umeyama
  alignment without scale (evo ``align``), translation error statistics (evo ``APE``), metres.
- RPE over 1 s, as TUM's ``evaluate_rpe.py --fixed_delta --delta 1 --delta_unit s``: every
  estimated pose i is paired with the pose j whose timestamp is closest to t_i + 1 s (pairs
  whose j is the last pose are dropped, as in the TUM script); each is matched to the nearest
  ground-truth pose (within twice the ground-truth period);
  ``E = (G_i^-1 G_j)^-1 (P_i^-1 P_j)`` with evo's ``relative_se3``; translation ``|t(E)|``
  (m per 1 s = m/s) and rotation angle of E (deg/s). evo's RPE has no seconds unit, so the
  pairs are built here and evo's per-pair maths is used.
- Mask metrics: precision, recall, IoU of a predicted moving-object mask.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from evo.core import geometry as evo_geometry, lie_algebra, metrics, sync
from evo.core.trajectory import PoseTrajectory3D

from .io import Trajectory

STATS = ("rmse", "mean", "median", "std", "min", "max")


@dataclass
class ErrorStats:
    """Statistics of a list of errors."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    count: int

    @classmethod
    def of(cls, errors: np.ndarray) -> "ErrorStats":
        e = np.asarray(errors, float)
        if e.size == 0:
            nan = float("nan")
            return cls(nan, nan, nan, nan, nan, nan, 0)
        return cls(float(np.sqrt(np.mean(e**2))), float(np.mean(e)), float(np.median(e)),
                   float(np.std(e)), float(np.min(e)), float(np.max(e)), int(e.size))


@dataclass
class TrajectoryErrors:
    """ATE (m) and 1-s RPE (m/s, deg/s) of an estimate against ground truth."""

    ate: ErrorStats
    rpe_trans: ErrorStats
    rpe_rot_deg: ErrorStats
    matched_poses: int
    aligned: Trajectory | None = None

    def as_dict(self) -> dict:
        """JSON-ready: undefined statistics (no RPE pair in a clip under 1 s) are None."""
        def stats(s: ErrorStats) -> dict:
            return {k: (None if isinstance(v, float) and np.isnan(v) else v) for k, v in asdict(s).items()}

        return {"ate_m": stats(self.ate), "rpe_trans_m_per_s": stats(self.rpe_trans),
                "rpe_rot_deg_per_s": stats(self.rpe_rot_deg), "matched_poses": self.matched_poses}


def to_evo(traj: Trajectory) -> PoseTrajectory3D:
    """Our Trajectory -> evo PoseTrajectory3D (copies)."""
    return PoseTrajectory3D(poses_se3=[p.copy() for p in traj.poses],
                            timestamps=traj.timestamps.copy())


def ate(gt: Trajectory, est: Trajectory, max_diff: float = 0.02) -> tuple[ErrorStats, int, Trajectory]:
    """Absolute trajectory error after SE(3) alignment (no scale).

    An estimate whose positions have no 3-D extent (Umeyama's covariance is rank-deficient) is
    aligned by its centroid alone instead of raising.

    Returns
    -------
    stats (metres), number of associated poses, the aligned estimate (associated poses only)
    """
    try:
        ref, e = sync.associate_trajectories(to_evo(gt), to_evo(est), max_diff=max_diff)
    except sync.SyncException:
        raise ValueError(f"no estimated pose within {max_diff} s of a ground-truth pose") from None
    if ref.num_poses < 3:
        raise ValueError(f"only {ref.num_poses} poses within {max_diff} s of ground truth")
    try:
        e.align(ref, correct_scale=False)
    except evo_geometry.GeometryException:
        # an estimate without 3-D extent (e.g. tracking failed on every frame and the poses stand
        # still): the rotation of the alignment is unobservable, so only the centroids are
        # aligned; exact for a motionless estimate, an upper bound otherwise
        shift = np.eye(4)
        shift[:3, 3] = ref.positions_xyz.mean(axis=0) - e.positions_xyz.mean(axis=0)
        e.transform(shift)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, e))
    aligned = Trajectory(e.timestamps, np.stack(e.poses_se3))
    return ErrorStats.of(ape.error), ref.num_poses, aligned


def _closest(stamps: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index of the closest timestamp in a sorted array for each of ``t``."""
    j = np.clip(np.searchsorted(stamps, t), 1, len(stamps) - 1)
    left = stamps[j - 1]
    right = stamps[j]
    return np.where(np.abs(t - left) <= np.abs(right - t), j - 1, j)


def rpe_pairs(est_stamps: np.ndarray, delta_s: float = 1.0) -> list[tuple[int, int]]:
    """Fixed-delta pairs (i, j) of TUM's evaluate_rpe.py with delta in seconds."""
    stamps = np.asarray(est_stamps, float)
    j = _closest(stamps, stamps + delta_s)
    return [(i, int(jj)) for i, jj in enumerate(j) if jj != len(stamps) - 1]


def rpe_errors(gt: Trajectory, est: Trajectory, delta_s: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-pair relative pose errors over ``delta_s`` seconds.

    Returns
    -------
    end timestamps of the pairs, translation errors (m), rotation errors (deg)
    """
    if len(est) < 2 or len(gt) < 2:
        raise ValueError("RPE needs at least two poses in both trajectories")
    gt_dt = np.median(np.diff(gt.timestamps))
    max_gap = 2.0 * gt_dt
    stamps, trans, rot = [], [], []
    for i, j in rpe_pairs(est.timestamps, delta_s):
        gi, gj = _closest(gt.timestamps, est.timestamps[[i, j]])
        if (abs(gt.timestamps[gi] - est.timestamps[i]) > max_gap
                or abs(gt.timestamps[gj] - est.timestamps[j]) > max_gap):
            continue
        d_est = lie_algebra.relative_se3(est.poses[i], est.poses[j])
        d_gt = lie_algebra.relative_se3(gt.poses[gi], gt.poses[gj])
        E = lie_algebra.relative_se3(d_gt, d_est)
        stamps.append(est.timestamps[j])
        trans.append(np.linalg.norm(E[:3, 3]))
        rot.append(np.degrees(lie_algebra.so3_log_angle(E[:3, :3])))
    return np.array(stamps), np.array(trans), np.array(rot)


def rpe(gt: Trajectory, est: Trajectory, delta_s: float = 1.0) -> tuple[ErrorStats, ErrorStats]:
    """Relative pose error over ``delta_s`` seconds: translation (m) and rotation (deg) stats."""
    _, trans, rot = rpe_errors(gt, est, delta_s)
    return ErrorStats.of(trans), ErrorStats.of(rot)


def exposure_pair_errors(gt: Trajectory, est: Trajectory, timestamps: np.ndarray,
                         gain: np.ndarray) -> dict[str, float]:
    """Frame-to-frame translation error (mm) of the pairs across an exposure change and of the
    others: what a change of the image brightness costs a method, with the rest of the
    trajectory's errors set aside.

    Parameters
    ----------
    timestamps, gain : (N,) each colour frame's time and exposure gain
        (:attr:`~dynslam_lite.io.RGBDSequence.exposure`); a pair is across a change when its
        two frames' gains differ
    Returns
    -------
    {'pair_error_mm_exposure_change', 'pair_error_mm_elsewhere'} means, and
    'exposure_changes': the number of pairs across a change
    """
    stamps, trans, _ = rpe_errors(gt, est, delta_s=float(np.median(np.diff(est.timestamps))))
    gain = np.asarray(gain)
    k = _closest(np.asarray(timestamps), stamps)  # the pair's later frame
    across = gain[k] != gain[np.maximum(k - 1, 0)]
    mean = lambda x: float(np.mean(x) * 1000.0) if x.size else float("nan")  # noqa: E731
    return {"pair_error_mm_exposure_change": mean(trans[across]), "pair_error_mm_elsewhere": mean(trans[~across]),
            "exposure_changes": int(across.sum())}


def evaluate(gt: Trajectory, est: Trajectory, max_diff: float = 0.02, delta_s: float = 1.0) -> TrajectoryErrors:
    """ATE and 1-s RPE of ``est`` against ``gt`` (both camera-to-world)."""
    ate_stats, n, aligned = ate(gt, est, max_diff)
    rt, rr = rpe(gt, est, delta_s)
    return TrajectoryErrors(ate_stats, rt, rr, n, aligned)


@dataclass
class MaskScores:
    """Scores of a predicted moving-object mask (or dynamic-point labels) against ground truth,
    with the counts they come from (true positives, false positives, false negatives)."""

    precision: float
    recall: float
    iou: float
    tp: int = 0
    fp: int = 0
    fn: int = 0

    @classmethod
    def of(cls, predicted: np.ndarray, truth: np.ndarray) -> "MaskScores":
        """Scores of (H, W) bool masks, or stacks (N, H, W) pooled over all frames.

        An empty prediction has precision 1 (nothing claimed wrongly); an empty truth recall 1.
        """
        p = np.asarray(predicted, bool)
        t = np.asarray(truth, bool)
        if p.shape != t.shape:
            raise ValueError(f"mask shapes differ: {p.shape} vs {t.shape}")
        return cls.from_counts(*confusion(p, t))

    @classmethod
    def from_counts(cls, tp: int, fp: int, fn: int) -> "MaskScores":
        """Scores from pixel counts (true positives, false positives, false negatives)."""
        precision = tp / (tp + fp) if tp + fp else 1.0
        recall = tp / (tp + fn) if tp + fn else 1.0
        iou = tp / (tp + fp + fn) if tp + fp + fn else 1.0
        return cls(float(precision), float(recall), float(iou), int(tp), int(fp), int(fn))

    @property
    def counted(self) -> bool:
        """Whether any pixel or point was predicted or true (the scores mean something)."""
        return self.tp + self.fp + self.fn > 0


def psnr(image: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> float:
    """Peak signal-to-noise ratio (dB, peak 255) of 8-bit ``image`` against ``reference`` over
    the pixels of ``mask`` (H, W) bool; capped at 90 dB for identical pixels."""
    diff = image[mask].astype(float) - reference[mask].astype(float)
    return float(10 * np.log10(255.0**2 / max(np.mean(diff**2), 1e-9)))


def confusion(predicted: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(3,) int64 pixel counts: true positives, false positives, false negatives."""
    p, t = np.asarray(predicted, bool), np.asarray(truth, bool)
    return np.array([np.count_nonzero(p & t), np.count_nonzero(p & ~t), np.count_nonzero(~p & t)], np.int64)
