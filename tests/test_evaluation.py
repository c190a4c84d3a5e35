"""Our evo-based ATE/RPE against an independent implementation of the TUM formulas."""
import numpy as np
import pytest

from dynslam_lite.evaluation import MaskScores, evaluate, rpe_pairs
from dynslam_lite.geometry import se3_exp
from dynslam_lite.io import Trajectory


def _tum_ate(gt, est):
    """TUM evaluate_ate.py: Horn alignment of associated positions, RMSE of residuals."""
    model = est.positions.T  # 3xN
    data = gt.positions.T
    mz, dz = model.mean(1, keepdims=True), data.mean(1, keepdims=True)
    W = (model - mz) @ (data - dz).T
    U, _, Vh = np.linalg.svd(W.T)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vh) < 0:
        S[2, 2] = -1
    rot = U @ S @ Vh
    trans = dz - rot @ mz
    err = np.linalg.norm(rot @ model + trans - data, axis=0)
    return np.sqrt(np.mean(err**2)), err.max()


def _tum_rpe(gt, est, delta=1.0):
    """TUM evaluate_rpe.py with --fixed_delta --delta 1 --delta_unit s (same stamps)."""
    st = est.timestamps
    errs_t, errs_r = [], []
    for i in range(len(st)):
        j = int(np.argmin(np.abs(st - (st[i] + delta))))
        if j == len(st) - 1:
            continue
        a = np.linalg.inv(np.linalg.inv(gt.poses[i]) @ gt.poses[j])
        b = np.linalg.inv(est.poses[i]) @ est.poses[j]
        E = a @ b
        errs_t.append(np.linalg.norm(E[:3, 3]))
        errs_r.append(np.degrees(np.arccos(min(1, max(-1, (np.trace(E[:3, :3]) - 1) / 2)))))
    return np.sqrt(np.mean(np.square(errs_t))), np.sqrt(np.mean(np.square(errs_r)))


def _trajectories(seed):
    rng = np.random.default_rng(seed)
    t = 100.0 + np.arange(90) / 30.0
    gt, est = [], []
    offset = se3_exp(rng.normal(0, 1, 6))
    pose = np.eye(4)
    for _ in t:
        pose = pose @ se3_exp(np.concatenate([rng.normal(0, 0.01, 3), rng.normal(0, 0.01, 3)]))
        gt.append(pose.copy())
        est.append(offset @ pose @ se3_exp(rng.normal(0, 0.004, 6)))
    return Trajectory(t, np.stack(gt)), Trajectory(t, np.stack(est))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_tum_formulas(seed):
    gt, est = _trajectories(seed)
    e = evaluate(gt, est)
    rmse, mx = _tum_ate(gt, est)
    assert e.ate.rmse == pytest.approx(rmse, rel=1e-6)
    assert e.ate.max == pytest.approx(mx, rel=1e-6)
    assert e.matched_poses == 90
    t_rmse, r_rmse = _tum_rpe(gt, est)
    assert e.rpe_trans.rmse == pytest.approx(t_rmse, rel=1e-6)
    assert e.rpe_rot_deg.rmse == pytest.approx(r_rmse, rel=1e-6)


def test_perfect_estimate_in_other_world_frame_has_zero_error():
    gt, _ = _trajectories(3)
    est = Trajectory(gt.timestamps + 0.005, se3_exp([1, 2, 3, 0.1, 0.2, 0.3]) @ gt.poses)
    e = evaluate(gt, est)
    assert e.ate.rmse < 1e-9 and e.rpe_trans.rmse < 1e-9 and e.rpe_rot_deg.rmse < 1e-6


def test_rpe_pairs_are_one_second_apart():
    stamps = np.arange(0, 3.0, 0.1)
    pairs = rpe_pairs(stamps)
    assert all(abs(stamps[j] - stamps[i] - 1.0) < 0.051 for i, j in pairs)
    assert pairs[0] == (0, 10) and all(j != len(stamps) - 1 for _, j in pairs)


def test_association_drops_far_timestamps():
    gt, est = _trajectories(4)
    shifted = Trajectory(gt.timestamps + 10.0, est.poses)  # no overlap in time
    with pytest.raises(ValueError, match="within 0.02 s"):
        evaluate(gt, shifted)


def test_mask_scores_hand_computed():
    truth = np.zeros((4, 4), bool)
    truth[:2, :2] = True  # 4 pixels
    pred = np.zeros((4, 4), bool)
    pred[:2, 1:3] = True  # 4 pixels, 2 overlap
    s = MaskScores.of(pred, truth)
    assert (s.precision, s.recall, s.iou) == (0.5, 0.5, pytest.approx(2 / 6))
    assert MaskScores.of(np.zeros((2, 2), bool), np.zeros((2, 2), bool)).iou == 1.0


def test_motionless_estimate_is_scored_not_raised():
    # tracking that failed everywhere leaves every pose at the origin: Umeyama is degenerate,
    # the centroid alignment gives the spread of the ground truth about its mean
    t = np.arange(30) / 30.0
    gt = Trajectory(t, np.stack([se3_exp([0.1 * k, 0.02 * k, 0, 0, 0, 0]) for k in range(30)]))
    est = Trajectory(t, np.repeat(np.eye(4)[None], 30, axis=0))
    e = evaluate(gt, est)
    spread = np.linalg.norm(gt.positions - gt.positions.mean(axis=0), axis=1)
    assert e.ate.rmse == pytest.approx(np.sqrt(np.mean(spread**2)))


def test_exposure_pair_errors_split_the_frame_to_frame_errors_at_the_changes():
    """A 5 mm error in each pair across an exposure change, 1 mm elsewhere: the two means."""
    from dynslam_lite.evaluation import exposure_pair_errors

    t = np.arange(40) / 30.0
    gain = np.where(t < 12 / 30, 1.0, np.where(t < 25 / 30, 1.1, 0.95))
    gt = Trajectory(t, np.stack([se3_exp([0.01 * k, 0, 0, 0, 0.002 * k, 0]) for k in range(40)]))
    poses, T = [gt.poses[0]], gt.poses[0]
    for k in range(1, 40):
        step = np.linalg.inv(gt.poses[k - 1]) @ gt.poses[k]
        T = T @ step @ se3_exp([0.005 if gain[k] != gain[k - 1] else 0.001, 0, 0, 0, 0, 0])
        poses.append(T)
    out = exposure_pair_errors(gt, Trajectory(t, np.stack(poses)), t, gain)
    assert out["exposure_changes"] == 2
    assert out["pair_error_mm_exposure_change"] == pytest.approx(5.0, abs=1e-6)
    assert out["pair_error_mm_elsewhere"] == pytest.approx(1.0, abs=1e-6)
