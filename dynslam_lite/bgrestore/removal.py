"""Paper C, sec. 2: which semantic instances to remove, by the epipolar distance of their points.

Between the previous and the current frame, ORB keypoints are matched by descriptor and the
fundamental matrix F is estimated with RANSAC (``cv2.findFundamentalMat``) from the matches
outside every instance (the static prior; with the moving points in, RANSAC would fit them when
they dominate). For each match the epipolar distance ``d = |p2^T F p1| / sqrt(A^2 + B^2)`` with
``(A, B, C) = F p1`` (eq. 3) decides: ``d < 1 px`` static, else dynamic. An instance is removed
when more than half of its matched points are dynamic; one with fewer than ``min_points`` matches
has no geometric evidence and is removed (people are the dynamic class; our choice, the paper is
silent). Removed instances are dilated to cover motion ghosts at their edges.

Ours: the paper votes only on what the network segments, so an object it does not segment (a
carried board, a pushed box when the mask source gives people only) moves unnoticed. The same
epipolar test is applied to the matches outside every instance: those judged dynamic are not
tracked (``drop_unsegmented``; the reproduction also runs without it).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..features import Features, match_descriptors
from ..geometry import epipolar_distance, sample_nearest
from ..imageops import dilate


@dataclass
class RemovalConfig:
    """Parameters of the removal step.

    Attributes
    ----------
    epipolar_px : a point farther than this from its epipolar line is dynamic (1 px in the paper)
    dynamic_fraction : an instance with more than this share of dynamic points is removed (0.5)
    min_points : instances with fewer matched points are removed without a vote
    dilate_px : radius of the dilation of removed instances
    ransac_px : RANSAC inlier threshold of the F estimate
    frame_gap : the frame compared with is this many frames back (1 = adjacent, the paper)
    drop_unsegmented : matches outside every instance judged dynamic are not tracked (ours)
    unsegmented_px : epipolar distance that makes such a match dynamic: one match has no vote to
        average its noise, so the threshold is stricter than ``epipolar_px``
    point_px : radius around such a match where no keypoint is tracked
    """

    epipolar_px: float = 1.0
    dynamic_fraction: float = 0.5
    min_points: int = 5
    dilate_px: int = 10
    ransac_px: float = 1.0
    frame_gap: int = 6
    drop_unsegmented: bool = True
    unsegmented_px: float = 3.0
    point_px: int = 4


@dataclass
class Removal:
    """Result of :func:`decide_removal`.

    Attributes
    ----------
    mask : (H, W) bool, the dilated union of the removed instances
    removed : per instance, removed or kept
    votes : per instance (dynamic points, matched points)
    F : (3, 3) fundamental matrix previous -> current, or None when it could not be estimated
    uv_prev, uv_cur, distance : the matches and their epipolar distances (for figures)
    outside : per match, outside every instance
    moved : per match, outside every instance and judged dynamic (``drop_unsegmented``; not tracked)
    """

    mask: np.ndarray
    removed: list[bool]
    votes: list[tuple[int, int]]
    F: np.ndarray | None
    uv_prev: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    uv_cur: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    distance: np.ndarray = field(default_factory=lambda: np.zeros(0))
    outside: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    moved: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    @property
    def unsegmented(self) -> np.ndarray:
        """(K, 2) current-frame pixels of the matches in ``moved``."""
        return self.uv_cur[self.moved]


def decide_removal(instances: list[np.ndarray], prev: Features | None, cur: Features,
                   shape: tuple[int, int], config: RemovalConfig | None = None) -> Removal:
    """Remove or keep each instance of the current frame (module docstring)."""
    cfg = config or RemovalConfig()
    empty = np.zeros(shape, bool)
    if not instances and not cfg.drop_unsegmented:
        return Removal(empty, [], [], None)
    F, uv_p, uv_c, d = None, np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    hits, inside = [], np.zeros(0, bool)
    if prev is not None and len(prev) and len(cur):
        ia, ib = match_descriptors(prev.desc, cur.desc)
        uv_p, uv_c = prev.uv[ia], cur.uv[ib]
        hits = [sample_nearest(m, uv_c) for m in instances]  # matches inside each instance
        inside = np.logical_or.reduce(hits) if hits else np.zeros(len(ib), bool)
        if (~inside).sum() >= 8:
            F, _ = cv2.findFundamentalMat(uv_p[~inside], uv_c[~inside], cv2.FM_RANSAC, cfg.ransac_px, 0.999)
            F = F[:3] if F is not None and F.shape[0] >= 3 else None
        if F is not None:
            d = epipolar_distance(F, uv_p, uv_c)
    if F is None:  # no geometric evidence at all: every instance goes
        votes = [(0, 0)] * len(instances)
    else:
        votes = [(int((d[h] >= cfg.epipolar_px).sum()), int(h.sum())) for h in hits]
    removed = [F is None or n < cfg.min_points or dyn > cfg.dynamic_fraction * n for dyn, n in votes]
    mask = dilate(np.logical_or.reduce([m for m, r in zip(instances, removed) if r] or [empty]), cfg.dilate_px)
    outside, moved = np.zeros(len(uv_c), bool), np.zeros(len(uv_c), bool)
    if F is not None:  # without F no match has a verdict
        outside = ~inside
        moved = outside & (d >= cfg.unsegmented_px) if cfg.drop_unsegmented else moved
    return Removal(mask, removed, votes, F, uv_p, uv_c, d, outside, moved)


def points_mask(uv: np.ndarray, shape: tuple[int, int], radius: int) -> np.ndarray:
    """(H, W) bool: disks of ``radius`` pixels around the points ``uv`` (N, 2)."""
    mask = np.zeros(shape, bool)
    if len(uv):
        u = np.clip(np.rint(uv[:, 0]).astype(int), 0, shape[1] - 1)
        v = np.clip(np.rint(uv[:, 1]).astype(int), 0, shape[0] - 1)
        mask[v, u] = True
    return dilate(mask, radius)
