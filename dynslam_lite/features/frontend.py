"""An ORB-SLAM2-style RGB-D tracking frontend, lite: the shared base of papers B and C.

Per frame (ORB-SLAM2's Tracking thread, without loop closing or relocalisation database):

1. ORB keypoints spread over the image, with depth (:mod:`.orb`); keypoints inside the
   semantic masks are dropped when a method asks for it;
2. pose prediction by the constant-velocity motion model;
3. search by projection of the local map (the points of the latest keyframes) in a window
   around the predicted position, then pose-only optimisation with outlier rounds; a second,
   narrow search with the optimised pose adds matches and the pose is optimised again. When the
   window search finds too few matches, descriptor matching against the local map and PnP with
   RANSAC (``cv2.solvePnPRansac``) re-initialise the pose. When the narrow search at the optimised
   pose keeps less than half of the first search's matches and the pose would still be accepted,
   the pose step has left the frame's support (ours, ``support_check``): the prediction's matches
   in the narrow window give a second pose, and the one with more inliers is kept;
4. keyframe decision (tracked points below 90 % of the last keyframe's, or a maximum gap);
   a keyframe creates map points from its unmatched keypoints with depth and runs local bundle
   adjustment over a window of keyframes; points found in too few of the frames where they
   were visible are culled. With ``screen_new_points`` (ours; papers B and C turn it on) a new
   keypoint becomes a map point only if the free-space test (:mod:`.freespace`) against the
   reference keyframes passes: a point on a carried board, a pushed box or a person the mask
   source misses would otherwise be matched in the next frames before anything could test it.

The frame poses are kept relative to their reference keyframe and composed with the final
keyframe poses at the end (:meth:`FeatureTracker.trajectory`), as ORB-SLAM2 writes its
trajectory.

Dynamic methods change step 3 through :meth:`FeatureTracker.estimate` (paper B) or the images
(paper C).
"""
from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..geometry import (PinholeCamera, backproject, invert, normalize_pose, project, sample_nearest,
                        transform_points)
from ..io import Frame
from .freespace import free_space_test, median_over_references, nearest_depth
from .matching import match_descriptors, search_by_projection
from .optimize import Observations, PoseResult, local_bundle_adjustment, optimize_pose, residuals
from .orb import Features, ORBConfig, frame_keypoints


@dataclass
class FrontendConfig:
    """Parameters of the frontend (ORB-SLAM2's RGB-D TUM settings where they exist).

    Attributes
    ----------
    orb : keypoint extraction, see :class:`ORBConfig`
    baseline_m : virtual stereo baseline of the RGB-D error (b_f = fx * baseline; 40 / fx in
        ORB-SLAM2's TUM files, i.e. 0.075-0.08 m)
    search_radius_px : window of the first search by projection (octave 0)
    refine_radius_px : window of the second search, with the optimised pose
    max_descriptor_distance : Hamming distance accepted in the searches
    min_inliers : fewer inlier matches = tracking failure on this frame
    keyframe_ratio : new keyframe when the inliers drop below this fraction of the last
        keyframe's tracked points
    keyframe_max_gap : ... or after this many frames without one
    max_point_depth_m : map points are created from keypoints closer than this (ORB-SLAM2's
        ThDepth = 40 baselines = 3.2 m) ...
    min_new_points : ... topped up with the nearest farther ones to this many (ORB-SLAM2: 100);
        the first keyframe takes every keypoint with depth, as ORB-SLAM2's initialisation
    local_map_keyframes : the local map holds the points of this many latest keyframes
    ba_window : keyframes optimised by local bundle adjustment (older observers held fixed);
        0 = no local BA
    ba_iterations : Levenberg-Marquardt steps of the robust phase of a local BA (the inlier phase runs
        twice as many; ORB-SLAM2: 5 and 10). Measured and not adopted (2026-12-07, for speed): 3
        steps take 35-45 % off the local BA (4-7 ms a frame); synthetic carry, push and crowd
        (oracle masks) stay within a run's spread, but the Bonn dev clip with the person model
        goes static-orb 0.0290 -> 0.0316, weightedstatic 0.0182 -> 0.0211, bgrestore 0.0200 ->
        0.0393 m ATE RMSE
    cull_ratio, cull_min_visible : a point found in fewer than ``cull_ratio`` of the frames
        where it was visible (after ``cull_min_visible`` of them) is removed
    consistent_pose : the pose step optimises on the matches PnP-RANSAC finds consistent
        (:meth:`FeatureTracker.consistent_pose`; ours, off = ORB-SLAM2's pose optimisation)
    mask_dilate_px : the semantic masks are dilated by this radius before keypoints inside them
        are dropped (0: as the mask source gives them)
    screen_new_points : a new keyframe's unmatched keypoints with depth whose median free-space
        score over the reference keyframes reaches ``screen_threshold`` do not become map points
        (ours, off = ORB-SLAM2's map point creation)
    screen_threshold : free-space score (relative depth, paper B's sigma2) of a moved keypoint
    screen_references : reference keyframes of the screening: those sharing most map points
        with the frame, among the latest 20
    free_space_window : side of the window whose nearest depth the free-space test reads (px)
    support_check : when the narrow search at the optimised pose finds fewer than this fraction of
        the first search's matches and the pose keeps at least ``min_inliers`` inliers (so it
        would be accepted), a second pose from the prediction's matches in the narrow window
        competes, and the pose with more inliers is kept (ours; 0 = off, ORB-SLAM2's tracking).
        Where people cover most of the image, a few dozen matches are left and a group of them
        on a person the masks miss can pull the pose step away; the re-search at that pose then
        finds only the group. Measured (2026-12-06): bgrestore on the Bonn dev clip with the
        removed instances dilated by 15 px, frame 80 (people on 60 % of the image): 54 matches
        around the prediction, the pose step moved 0.66 m and its re-search kept 24 (the
        prediction's matches: 38 inliers, 5 cm from the truth); ATE 0.307 m without the check,
        0.019 m with it. A pose below ``min_inliers`` is a reported failure either way: acting
        there too turned a reported failure on synthetic crowd with ``oracle:all`` into a pose
        0.23 m off (ATE 0.0186 -> 0.0257 m). In the whole reproduction (279 runs) it acts in
        that Bonn run only; every other run is unchanged
    """

    orb: ORBConfig = field(default_factory=ORBConfig)
    baseline_m: float = 0.08
    search_radius_px: float = 15.0
    refine_radius_px: float = 4.0
    max_descriptor_distance: int = 80
    min_inliers: int = 20
    keyframe_ratio: float = 0.9
    keyframe_max_gap: int = 10
    max_point_depth_m: float = 4.0
    min_new_points: int = 100
    local_map_keyframes: int = 8
    ba_window: int = 5
    ba_iterations: int = 5
    cull_ratio: float = 0.25
    cull_min_visible: int = 4
    consistent_pose: bool = False
    mask_dilate_px: int = 0
    screen_new_points: bool = False
    screen_threshold: float = 0.05
    screen_references: int = 5
    free_space_window: int = 5
    support_check: float = 0.5


class PointMap:
    """Map points: world positions, descriptors and visibility counts.

    Attributes
    ----------
    P_w : (M, 3) float, world frame, metres
    desc : (M, 32) uint8, descriptor of the creating keypoint
    visible, found : (M,) int, frames where the point projected into the image / was matched
    alive : (M,) bool
    """

    def __init__(self):
        self.P_w = np.zeros((0, 3))
        self.desc = np.zeros((0, 32), np.uint8)
        self.visible = np.zeros(0, int)
        self.found = np.zeros(0, int)
        self.alive = np.zeros(0, bool)

    def __len__(self) -> int:
        return len(self.P_w)

    def add(self, P_w: np.ndarray, desc: np.ndarray) -> np.ndarray:
        ids = np.arange(len(self), len(self) + len(P_w))
        self.P_w = np.vstack([self.P_w, P_w])
        self.desc = np.vstack([self.desc, desc])
        self.visible = np.concatenate([self.visible, np.ones(len(P_w), int)])
        self.found = np.concatenate([self.found, np.ones(len(P_w), int)])
        self.alive = np.concatenate([self.alive, np.ones(len(P_w), bool)])
        return ids


@dataclass
class Keyframe:
    """A keyframe: its pose, keypoints and the map point each keypoint observes.

    Attributes
    ----------
    frame : index of the frame in the sequence
    T_c_w : (4, 4) world to camera
    feats : keypoints
    point_ids : (N,) int, map point observed by each keypoint, -1 = none
    weights : (N,) float, static weight of each observation (1 without weighting)
    """

    frame: int
    T_c_w: np.ndarray
    feats: Features
    point_ids: np.ndarray
    weights: np.ndarray


@dataclass
class Estimate:
    """What the pose step of a frame returns.

    Attributes
    ----------
    T_c_w : (4, 4) world to camera
    inliers : (K,) bool per match
    weights : (K,) float per match, static weight (1 = fully trusted)
    dynamic : (N,) bool per keypoint of the frame, judged moving (never becomes a map point)
    info : anything a method wants to keep for inspection (notebooks)
    """

    T_c_w: np.ndarray
    inliers: np.ndarray
    weights: np.ndarray
    dynamic: np.ndarray
    info: dict = field(default_factory=dict)


@dataclass
class TrackedFrame:
    """One frame's tracking: keypoints, matches to map points and the estimate."""

    index: int
    feats: Features
    map_idx: np.ndarray
    kp_idx: np.ndarray
    estimate: Estimate | None
    ok: bool
    reason: str = ""
    keyframe: bool = False
    screened: tuple[np.ndarray, np.ndarray] | None = None  # a new keyframe's (uv, moved) candidates


class FeatureTracker:
    """The frontend. ``process(frame)`` tracks one frame; ``trajectory()`` gives all poses."""

    REFERENCE_CANDIDATES = 20  # reference keyframes are chosen among this many latest keyframes

    def __init__(self, camera: PinholeCamera, config: FrontendConfig | None = None):
        self.camera = camera
        self.config = cfg = config or FrontendConfig()
        self.bf = camera.fx * cfg.baseline_m
        self.map = PointMap()
        self.keyframes: list[Keyframe] = []
        self.frame_ref: list[tuple[int, np.ndarray]] = []  # (keyframe id, T_c_kf) per frame
        self.T_last: np.ndarray | None = None
        self.T_before: np.ndarray | None = None
        self.last_tracked = 0
        self.frames_since_kf = 0
        self.nearest: dict[int, np.ndarray] = {}  # keyframe index -> nearest-depth image
        self.reverted = 0  # pose steps that kept the prediction's matches (``support_check``)

    # ------------------------------------------------------------------ per frame
    def process(self, frame, exclude: np.ndarray | None = None, timer=None,
                T_init: np.ndarray | None = None, refined: bool = False,
                unmapped: np.ndarray | None = None, keypoints: Features | None = None) -> TrackedFrame:
        """Track one frame (a :class:`dynslam_lite.io.Frame`); failures are reported, not raised.

        ``exclude``: (H, W) bool, keypoints inside are dropped (semantic masks).
        ``T_init``: world-to-camera start of the search (default: the constant-velocity prediction);
        ``refined``: it is already this frame's pose (a trial pose), see :meth:`locate`.
        ``unmapped``: (H, W) bool, keypoints inside are tracked but never become map points
        (pixels that were not measured, e.g. paper C's restoration).
        ``keypoints``: the frame's keypoints as :func:`extract` gives them without ``exclude``, where
        the caller extracted them already from this image (with this depth outside ``exclude``).
        """
        stage = timer.stage if timer else (lambda name: nullcontext())
        with stage("orb"):
            if keypoints is None:
                keypoints = frame_keypoints(frame, self.config.orb, timer)
            feats = keypoints.outside(exclude)
        if not self.keyframes:
            self._add_keyframe(frame, np.eye(4), feats, np.zeros(0, int), np.zeros(0, int),
                               np.ones(0), np.zeros(len(feats), bool))
            self._record(np.eye(4))
            return TrackedFrame(frame.index, feats, np.zeros(0, int), np.zeros(0, int), None, True,
                                keyframe=True)
        T_pred = self.predict() if T_init is None else T_init
        mi, ki, est, T_pred, reason = self.locate(frame, feats, T_pred, timer, refined=refined)
        if est is None or reason:
            self._record(T_pred)
            return TrackedFrame(frame.index, feats, mi, ki, est, False, reason)
        n_in = int(est.inliers.sum())
        self.map.found[mi[est.inliers]] += 1
        self.frames_since_kf += 1
        is_kf = (n_in < self.config.keyframe_ratio * self.last_tracked
                 or self.frames_since_kf >= self.config.keyframe_max_gap)
        screened = None
        if is_kf:
            with stage("keyframe"):
                dynamic = est.dynamic if unmapped is None else est.dynamic | sample_nearest(unmapped, feats.uv)
                screened = self._add_keyframe(frame, est.T_c_w, feats, mi, ki, est.weights * est.inliers, dynamic)
                self.last_tracked = n_in
            with stage("local_ba"):
                self._local_ba()
            T = self.keyframes[-1].T_c_w
        else:
            T = est.T_c_w
        self._record(T)
        return TrackedFrame(frame.index, feats, mi, ki, est, True, keyframe=is_kf, screened=screened)

    def locate(self, frame, feats: Features, T_init: np.ndarray, timer=None, count: bool = True,
               refined: bool = False):
        """Pose of ``feats`` against the local map: search by projection from ``T_init``, pose,
        search again in a narrow window, pose. Changes no map or keyframe; ``count`` = False
        also leaves the points' visibility counts alone (a trial pose). ``refined``: ``T_init``
        is already this frame's pose (a trial pose), so one search in the narrow window and one
        pose step are enough (widened as the first search is when it finds too few matches).

        Returns (map indices, keypoint indices, Estimate or None, the start pose used, failure
        reason or '').
        """
        stage = timer.stage if timer else (lambda name: nullcontext())
        with stage("match"):
            local = self._local_points()
            radius = self.config.refine_radius_px if refined else self.config.search_radius_px
            mi, ki, T_init = self._search(local, feats, T_init, radius, True, count)
        if len(mi) < self.config.min_inliers:
            return mi, ki, None, T_init, f"{len(mi)} matches to the local map (need {self.config.min_inliers})"
        with stage("pose"):
            est = self.estimate(frame, feats, mi, ki, T_init)
        if not refined:
            n_first = len(mi)
            with stage("match"):
                mi, ki, _ = self._search(local, feats, est.T_c_w, self.config.refine_radius_px, False)
            with stage("pose"):
                est = self.estimate(frame, feats, mi, ki, est.T_c_w)
            if len(mi) < self.config.support_check * n_first and est.inliers.sum() >= self.config.min_inliers:
                with stage("match"):
                    mp, kp, _ = self._search(local, feats, T_init, self.config.refine_radius_px, False)
                if len(mp) > len(mi):
                    with stage("pose"):
                        est_p = self.estimate(frame, feats, mp, kp, T_init)
                    if est_p.inliers.sum() > est.inliers.sum():
                        mi, ki, est = mp, kp, est_p
                        self.reverted += 1
        n_in = int(est.inliers.sum())
        if n_in < self.config.min_inliers:
            return mi, ki, est, T_init, f"{n_in} inlier matches (need {self.config.min_inliers})"
        return mi, ki, est, T_init, ""

    def estimate(self, frame, feats: Features, map_idx: np.ndarray, kp_idx: np.ndarray,
                 T_init: np.ndarray) -> Estimate:
        """Pose from the matches: ORB-SLAM2's pose-only optimisation (overridden by paper B)."""
        obs = self.observations(feats, kp_idx)
        r = self.first_pose(T_init, self.map.P_w[map_idx], obs)
        return Estimate(r.T_c_w, r.inliers, np.ones(len(map_idx)), np.zeros(len(feats), bool))

    def first_pose(self, T_init: np.ndarray, P_w: np.ndarray, obs: Observations) -> PoseResult:
        """The pose from all matches: :meth:`consistent_pose` where ``config.consistent_pose``,
        else ORB-SLAM2's pose-only optimisation."""
        if self.config.consistent_pose:
            return self.consistent_pose(T_init, P_w, obs)
        return optimize_pose(self.camera, self.bf, T_init, P_w, obs)

    def consistent_pose(self, T_init: np.ndarray, P_w: np.ndarray, obs: Observations,
                        threshold_px: float = 3.0) -> PoseResult:
        """Pose-only optimisation on the largest set of matches one rigid motion explains.

        ``cv2.solvePnPRansac`` (AP3P minimal sets, ``threshold_px`` reprojection error) picks the
        set; :func:`optimize_pose` on it from ``T_init`` gives a pose at which every match is
        gated by its chi2, and :func:`optimize_pose` on the matches within the gate gives the
        result (every match classified at it). A group of matches that move together (a
        carried board) can pull the Huber rounds of ORB-SLAM2's pose optimisation; here it
        never enters unless it agrees with the consistent set. Where the moving matches
        outnumber the static ones the consistent set is theirs (masks must remove most of a
        crowd first). Without enough RANSAC inliers it is :func:`optimize_pose` from ``T_init``.
        """
        n_min = self.config.min_inliers
        if len(P_w) >= n_min:
            ok, _, _, inl = cv2.solvePnPRansac(
                P_w.astype(np.float64), obs.uvr[:, :2].astype(np.float64), self.camera.K, None,
                iterationsCount=100, reprojectionError=threshold_px, confidence=0.999,
                flags=cv2.SOLVEPNP_AP3P)
            if ok and inl is not None and len(inl) >= n_min:
                sel = inl.ravel()
                T = optimize_pose(self.camera, self.bf, T_init, P_w[sel], obs[sel]).T_c_w
                e, _ = residuals(self.camera, self.bf, T[:3, :3], T[:3, 3], P_w, obs)
                agree = obs.info * np.sum(e**2, axis=1) < obs.chi2_gate
                return optimize_pose(self.camera, self.bf, T, P_w, obs, weights=agree.astype(float))
        return optimize_pose(self.camera, self.bf, T_init, P_w, obs)

    def observations(self, feats: Features, kp_idx: np.ndarray) -> Observations:
        info = feats.inv_sigma2(self.config.orb.scale_factor)[kp_idx]
        return Observations.of(feats.uv[kp_idx], feats.z[kp_idx], info, self.bf)

    def reference_keyframes(self, map_idx: np.ndarray, n: int) -> list[int]:
        """Indices of the ``n`` keyframes (among the latest :attr:`REFERENCE_CANDIDATES`) sharing
        most of the map points ``map_idx``; none that shares no point."""
        first = max(0, len(self.keyframes) - self.REFERENCE_CANDIDATES)
        wanted = np.zeros(len(self.map) + 1, bool)  # the last entry: a keypoint without a point (-1)
        wanted[map_idx] = True
        shared = [np.count_nonzero(wanted[kf.point_ids]) for kf in self.keyframes[first:]]
        order = np.argsort(-np.asarray(shared), kind="stable")[:n]
        return [first + int(i) for i in order if shared[i] > 0]

    def moved_new_points(self, feats: Features, map_idx: np.ndarray, kp_idx: np.ndarray,
                         T_c_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A new keyframe's keypoints that must not become map points, (N,) bool over ``feats``,
        and the candidates tested (indices): unmatched keypoints with depth whose median
        free-space score over the reference keyframes reaches ``screen_threshold``."""
        cfg = self.config
        new = np.ones(len(feats), bool)
        new[kp_idx] = False
        cand = np.flatnonzero(new & (feats.z > 0))
        refs = [k for k in self.reference_keyframes(map_idx, cfg.screen_references) if k in self.nearest]
        out = np.zeros(len(feats), bool)
        if not refs or not cand.size:
            return out, cand[:0]
        score = self.free_space_scores(refs, T_c_w, feats.uv[cand], feats.z[cand])
        seen = np.isfinite(score).any(axis=1)
        out[cand[seen]] = median_over_references(score[seen]) >= cfg.screen_threshold
        return out, cand

    def free_space_scores(self, refs: list[int], T_c_w: np.ndarray, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(N, len(refs)) free-space scores (:func:`free_space_test`) of keypoints ``uv`` with depth
        ``z`` of the frame at ``T_c_w`` against the depth image of each keyframe in ``refs`` (nan
        for a keyframe that keeps none)."""
        score = np.full((len(uv), len(refs)), np.nan)
        T_w_c = invert(T_c_w)
        for r, k in enumerate(refs):
            if k in self.nearest:
                score[:, r] = free_space_test(self.camera, self.keyframes[k].T_c_w @ T_w_c, uv, z, self.nearest[k])
        return score

    def keeps_nearest_depth(self) -> bool:
        """Whether keyframes keep the nearest-depth image the free-space test reads."""
        return self.config.screen_new_points

    # ------------------------------------------------------------------ results
    def trajectory(self) -> np.ndarray:
        """(N, 4, 4) camera-to-world pose of every processed frame, with the final keyframe poses."""
        return np.stack([invert(T_c_kf @ self.keyframes[k].T_c_w) for k, T_c_kf in self.frame_ref])

    # ------------------------------------------------------------------ internals
    def _record(self, T_c_w: np.ndarray) -> None:
        k = len(self.keyframes) - 1
        T_c_w = normalize_pose(T_c_w)
        self.frame_ref.append((k, T_c_w @ invert(self.keyframes[k].T_c_w)))
        self.T_before, self.T_last = self.T_last, T_c_w

    def predict(self) -> np.ndarray:
        """Constant-velocity prediction of the next pose (world to camera)."""
        if self.T_before is None:
            return self.T_last.copy()
        return normalize_pose(self.T_last @ invert(self.T_before) @ self.T_last)

    def _local_points(self) -> np.ndarray:
        ids = np.concatenate([kf.point_ids for kf in self.keyframes[-self.config.local_map_keyframes:]])
        ids = np.unique(ids[ids >= 0])
        return ids[self.map.alive[ids]]

    def _project(self, ids: np.ndarray, T_c_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        P_c = transform_points(T_c_w, self.map.P_w[ids])
        uv = np.column_stack(project(self.camera, P_c))
        inside = ((P_c[:, 2] > 0.05) & (uv[:, 0] >= 0) & (uv[:, 0] < self.camera.width)
                  & (uv[:, 1] >= 0) & (uv[:, 1] < self.camera.height))
        return uv, inside

    def _search(self, local: np.ndarray, feats: Features, T_c_w: np.ndarray, radius: float,
                first: bool, count: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Search by projection; on the first search, widen the window and then re-initialise
        the pose by PnP-RANSAC when too few matches are found."""
        cfg = self.config

        def find(T, r):
            uv, inside = self._project(local, T)
            ids = local[inside]
            m, k = search_by_projection(uv[inside], self.map.desc[ids], feats, r,
                                        cfg.orb.scale_factor, cfg.max_descriptor_distance)
            return ids[m], k, ids

        mi, ki, seen = find(T_c_w, radius)
        if not first:
            return mi, ki, T_c_w
        if count:
            self.map.visible[seen] += 1
        if len(mi) < 2 * cfg.min_inliers:
            mi, ki, _ = find(T_c_w, 4 * radius)
        if len(mi) >= 2 * cfg.min_inliers:
            return mi, ki, T_c_w
        T = self._pnp(local, feats)
        if T is None:
            return mi, ki, T_c_w
        mi, ki, _ = find(T, radius)
        return mi, ki, T

    def _pnp(self, local: np.ndarray, feats: Features) -> np.ndarray | None:
        a, b = match_descriptors(self.map.desc[local], feats.desc)
        if len(a) < self.config.min_inliers:
            return None
        ok, rvec, tvec, inl = cv2.solvePnPRansac(
            self.map.P_w[local[a]].astype(np.float64), feats.uv[b].astype(np.float64),
            self.camera.K, None, iterationsCount=200, reprojectionError=4.0, confidence=0.99,
            flags=cv2.SOLVEPNP_EPNP)
        if not ok or inl is None or len(inl) < self.config.min_inliers:
            return None
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(rvec)[0]
        T[:3, 3] = tvec.ravel()
        return T

    def _add_keyframe(self, frame: Frame, T_c_w: np.ndarray, feats: Features, map_idx: np.ndarray,
                      kp_idx: np.ndarray, weights: np.ndarray,
                      dynamic: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """``frame`` becomes a keyframe at ``T_c_w``: its matched keypoints observe their map
        points, its new keypoints with depth (not ``dynamic``, not screened out) become map
        points. Returns the screening's (uv, moved) of the candidates, or None."""
        screened = None
        if self.config.screen_new_points and self.keyframes:
            moved, cand = self.moved_new_points(feats, map_idx, kp_idx, T_c_w)
            dynamic = dynamic | moved
            screened = (feats.uv[cand], moved[cand])
        point_ids = -np.ones(len(feats), int)
        w = np.ones(len(feats))
        good = weights > 0
        point_ids[kp_idx[good]] = map_idx[good]
        w[kp_idx[good]] = weights[good]
        new = (point_ids < 0) & (feats.z > 0) & ~dynamic
        if self.keyframes:  # close points, topped up with the nearest far ones
            far = np.flatnonzero(new & (feats.z >= self.config.max_point_depth_m))
            n_close = int(np.count_nonzero(new)) - far.size
            keep_far = far[np.argsort(feats.z[far], kind="stable")][: max(0, self.config.min_new_points - n_close)]
            new[np.setdiff1d(far, keep_far)] = False
        P_c = backproject(self.camera, feats.uv[new, 0], feats.uv[new, 1], feats.z[new])
        point_ids[new] = self.map.add(transform_points(invert(T_c_w), P_c), feats.desc[new])
        self.keyframes.append(Keyframe(frame.index, T_c_w.copy(), feats, point_ids, w))
        self.frames_since_kf = 0
        if self.last_tracked == 0:
            self.last_tracked = int(new.sum())
        if self.keeps_nearest_depth():  # the latest keyframes' nearest-depth images
            k = len(self.keyframes) - 1
            self.nearest[k] = nearest_depth(frame.depth, self.config.free_space_window)
            self.nearest.pop(k - self.REFERENCE_CANDIDATES, None)
        return screened

    def _local_ba(self) -> None:
        cfg = self.config
        n_kf = len(self.keyframes)
        if cfg.ba_window <= 0 or n_kf < 2:
            return
        window = list(range(max(0, n_kf - cfg.ba_window), n_kf))
        pts = np.concatenate([self.keyframes[k].point_ids for k in window])
        pts = np.unique(pts[pts >= 0])
        pts = pts[self.map.alive[pts]]
        # every keyframe observing these points takes part; those outside the window are fixed
        lookup = -np.ones(len(self.map), int)
        lookup[pts] = np.arange(len(pts))
        kf_ids, sels = [], []
        for k, kf in enumerate(self.keyframes):
            sel = np.flatnonzero(kf.point_ids >= 0)
            sel = sel[lookup[kf.point_ids[sel]] >= 0]
            if sel.size:
                kf_ids.append(k)
                sels.append(sel)
        fixed = np.array([k not in window or k == 0 for k in kf_ids])
        if fixed.all():
            return
        kfs = [self.keyframes[k] for k in kf_ids]
        kf_of_obs = np.concatenate([np.full(s.size, j) for j, s in enumerate(sels)])
        pt_of_obs = lookup[np.concatenate([kf.point_ids[s] for kf, s in zip(kfs, sels)])]
        obs = Observations.concat([self.observations(kf.feats, s) for kf, s in zip(kfs, sels)])
        w = np.concatenate([kf.weights[s] for kf, s in zip(kfs, sels)])
        T = np.stack([kf.T_c_w for kf in kfs])
        T, P, chi2 = local_bundle_adjustment(self.camera, self.bf, T, fixed, self.map.P_w[pts],
                                             kf_of_obs, pt_of_obs, obs, w, cfg.ba_iterations)
        self.map.P_w[pts] = P
        bad = chi2 > obs.chi2_gate  # outlier observations are erased, as in ORB-SLAM2
        for j, (kf, s) in enumerate(zip(kfs, sels)):
            kf.T_c_w = T[j]
            kf.point_ids[s[bad[kf_of_obs == j]]] = -1
        seen = self.map.visible >= cfg.cull_min_visible
        self.map.alive &= ~(seen & (self.map.found < cfg.cull_ratio * self.map.visible))
