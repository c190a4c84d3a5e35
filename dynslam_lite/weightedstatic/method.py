"""Paper B's method ``weightedstatic`` on the shared feature frontend.

Per frame, in the frontend's pose step (:meth:`WeightedStaticTracker.estimate`):

1. keypoints inside the semantic masks are dropped at extraction ("semantic static points"; ours:
   the masks dilated by 10 px, see ``frontend.mask_dilate_px``);
2. a first pose by the frontend's robust pose-only optimisation (ours, the frontend's
   ``consistent_pose``, on by default here: on the matches PnP-RANSAC finds consistent, so that
   an object moving as a whole cannot pull the pose the geometric test is judged with; see
   :meth:`~dynslam_lite.features.frontend.FeatureTracker.consistent_pose`);
3. the weighted geometric test (:mod:`.geometric`) of every match against the keyframes sharing
   most points with the frame, with that pose: eq. 4 where the reference observed the match's
   map point, else (ours, ``geometric.free_space``) the free-space test against the reference's
   depth image; the median score over the references decides. Ours because a point on a carried
   board is in the map for a frame or two: eq. 4 can only compare it with the keyframe just
   before, whose small baseline the pose absorbs the board's motion over (measured on
   walking_carry: the test's dynamic-point P / R 0.18 / 0.12 with eq. 4 alone, 0.68 / 0.75 with
   the free-space test; `geometric.free_space=false` is its run in the tables);
4. initial weights ``phi0 = eta * mask_seg + omega * mask_geo`` (eq. 6; mask_seg = 1 for a point
   outside the semantic masks, mask_geo = 1 for a point the geometric test keeps);
5. joint LM over pose and weights (:mod:`.weighted_ba`). Matches with a final weight below
   ``min_weight`` or a chi2 beyond the gate are outliers; points judged dynamic never become
   map points, and keyframe observations keep their weights for the local bundle adjustment;
6. (ours, the frontend's ``screen_new_points``, on by default here) a new keyframe's keypoints
   become map points only if the free-space test against the references passes: a point on a
   carried board or a pushed box would otherwise be matched in the next frames, before any
   reference could test it (measured: walking_carry ATE 0.0073 -> 0.0056 m, walking_push
   0.0272 -> 0.0157 m).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..features.freespace import median_over_references
from ..features.frontend import Estimate, FeatureTracker, FrontendConfig
from ..features.method import FrontendMethod
from ..features.optimize import CHI2_STEREO, optimize_pose
from ..geometry import invert
from ..tracking import Labels, Tracked
from .geometric import GeometricConfig, weighted_geometric_test
from .weighted_ba import initial_weights, joint_pose_and_weights


@dataclass
class WeightedStaticConfig:
    """Parameters of paper B (the paper's values where it gives them).

    Attributes
    ----------
    frontend : the shared feature frontend, see :class:`FrontendConfig`; here with
        ``consistent_pose`` on: the first pose from the matches PnP-RANSAC finds consistent
        (ours; False = ORB-SLAM2's pose-only optimisation over all matches, the paper's), and
        ``mask_dilate_px`` 10: keypoints within 10 px of a semantic mask dropped too (ours, the
        dilation paper C gives its removed instances: a corner on a person's outline moves with
        the person, and a network's outline is a few pixels off; 0 = the masks as given), and
        ``screen_new_points`` on (step 6)
    geometric : the weighted geometric test (sigma1, sigma2), see :class:`GeometricConfig`
    eta, omega : contributions of the semantic and geometric masks to the initial weight
        (eq. 6; 0.5 and 0.5 in the paper)
    lam : weight of the prior pulling each weight to its initial value (units of chi2)
    lm_iterations : Levenberg-Marquardt iterations of the joint optimisation
    min_weight : a match whose final weight is below this is an outlier
    use_geometry : False skips the geometric test (ablation: mask_geo = 1 everywhere)
    use_weights : False replaces the joint optimisation by dropping the geometrically dynamic
        points and running the frontend's pose-only optimisation (ablation)
    cull_dynamic : points judged dynamic are removed from the map
    """

    frontend: FrontendConfig = field(default_factory=lambda: FrontendConfig(
        consistent_pose=True, mask_dilate_px=10, screen_new_points=True))
    geometric: GeometricConfig = field(default_factory=GeometricConfig)
    eta: float = 0.5
    omega: float = 0.5
    lam: float = CHI2_STEREO
    lm_iterations: int = 20
    min_weight: float = 0.25
    use_geometry: bool = True
    use_weights: bool = True
    cull_dynamic: bool = True


class WeightedStaticTracker(FeatureTracker):
    """The frontend with paper B's pose step."""

    def __init__(self, camera, config: WeightedStaticConfig):
        self.paper = config
        super().__init__(camera, config.frontend)

    def keeps_nearest_depth(self) -> bool:
        return super().keeps_nearest_depth() or self.paper.geometric.free_space

    def geometric_scores(self, feats, map_idx: np.ndarray, kp_idx: np.ndarray,
                         T_c_w: np.ndarray) -> np.ndarray:
        """(K,) median delta of each match over its reference keyframes (nan: seen in none).

        A reference observing the match's map point scores it by eq. 4; one that does not, by
        the free-space test against its depth image (``geometric.free_space``, ours)."""
        cfg = self.paper.geometric
        refs = self.reference_keyframes(map_idx, cfg.reference_keyframes)
        delta = np.full((len(map_idx), max(len(refs), 1)), np.nan)
        for r, k in enumerate(refs):
            kf = self.keyframes[k]
            lookup = -np.ones(len(self.map), int)
            seen = kf.point_ids >= 0
            lookup[kf.point_ids[seen]] = np.flatnonzero(seen)
            idx = lookup[map_idx]
            has = idx >= 0
            T = T_c_w @ invert(kf.T_c_w)
            test = weighted_geometric_test(self.camera, T[:3, :3], T[:3, 3], kf.feats.uv[idx[has]],
                                           kf.feats.z[idx[has]], feats.uv[kp_idx[has]],
                                           feats.z[kp_idx[has]], cfg)
            delta[has, r] = test.delta
            if cfg.free_space and not has.all():
                kp = kp_idx[~has]
                delta[~has, r] = self.free_space_scores([k], T_c_w, feats.uv[kp], feats.z[kp])[:, 0]
        out = np.full(len(map_idx), np.nan)  # nan: the point is seen in no reference
        seen = np.isfinite(delta).any(axis=1)
        out[seen] = median_over_references(delta[seen])
        return out

    def estimate(self, frame, feats, map_idx, kp_idx, T_init) -> Estimate:
        cfg = self.paper
        obs = self.observations(feats, kp_idx)
        P = self.map.P_w[map_idx]
        first = self.first_pose(T_init, P, obs)
        if cfg.use_geometry:
            delta = self.geometric_scores(feats, map_idx, kp_idx, first.T_c_w)
            geo_dynamic = np.nan_to_num(delta) >= cfg.geometric.sigma2
        else:
            delta = np.full(len(map_idx), np.nan)
            geo_dynamic = np.zeros(len(map_idx), bool)
        phi0 = initial_weights(True, ~geo_dynamic, cfg.eta, cfg.omega)  # outside the masks: mask_seg = 1
        info = {"delta": delta, "geo_dynamic": geo_dynamic, "phi0": phi0, "T_first": first.T_c_w}
        if cfg.use_weights:
            jr = joint_pose_and_weights(self.camera, self.bf, first.T_c_w, P, obs, phi0, cfg.lam,
                                        cfg.lm_iterations)
            T, phi = jr.T_c_w, jr.phi
            inliers = (jr.chi2 < obs.chi2_gate) & (phi >= cfg.min_weight)
            weights = phi**2
            info.update(phi=phi, cost=jr.cost)
        else:
            keep = np.flatnonzero(~geo_dynamic)
            r = optimize_pose(self.camera, self.bf, first.T_c_w, P[keep], obs[keep])
            T = r.T_c_w
            inliers = np.zeros(len(map_idx), bool)
            inliers[keep] = r.inliers
            weights = np.ones(len(map_idx))
        dynamic = np.zeros(len(feats), bool)
        dynamic[kp_idx[geo_dynamic]] = True
        if cfg.cull_dynamic:
            self.map.alive[map_idx[geo_dynamic]] = False
        return Estimate(T, inliers, weights, dynamic, info)


class WeightedStaticMethod(FrontendMethod):
    """Method ``weightedstatic``. Each frame's labels are its matched keypoints judged dynamic by
    the geometric test ('geometric') and by the final weights ('weights': phi < phi0 / 2), and a
    keyframe's new keypoints kept out of the map by the frontend's screening ('new')."""

    name = "weightedstatic"
    config_type = WeightedStaticConfig
    tracker_type = WeightedStaticTracker

    def tracked(self, frame, tf, record) -> Tracked:
        labels, est = None, tf.estimate
        if est is not None and len(tf.kp_idx):
            points = {"geometric": est.info["geo_dynamic"]}
            if "phi" in est.info:
                points["weights"] = est.info["phi"] < 0.5 * est.info["phi0"]
            labels = Labels(frame.index, uv=tf.feats.uv[tf.kp_idx], points=points)
        return Tracked(np.eye(4), tf.ok, tf.reason, tf.keyframe, self.screened_labels(frame, tf, labels), tf)
