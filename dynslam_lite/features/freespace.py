"""The free-space test (ours): does a keyframe's depth image say a point was not where it is now?

A keyframe camera that saw *through* the place where a point of the current frame is now (its
depth there lies beyond the point) shows the point was not there: it moved. Paper B's weighted
geometric test (:mod:`dynslam_lite.weightedstatic.geometric`) compares a match with a reference
keyframe's observation of the same map point; this test needs no such observation, only the
reference's depth image, so it also judges points that entered the map a frame or two ago and new
keypoints before they become map points (the frontend's ``screen_new_points``, used by papers B
and C: a carried board, a pushed box, a person the mask source misses).
"""
from __future__ import annotations

import cv2
import numpy as np

from ..geometry import PinholeCamera, backproject, project, transform_points


def nearest_depth(depth: np.ndarray, window: int) -> np.ndarray:
    """(H, W) float32: the nearest valid depth within ``window`` x ``window`` of each pixel
    (inf where none): what :func:`free_space_test` reads in a reference keyframe."""
    d = np.where(depth > 0, depth, np.inf).astype(np.float32)
    return cv2.erode(d, np.ones((window, window), np.uint8), borderType=cv2.BORDER_REPLICATE)


def free_space_test(camera: PinholeCamera, T_ref_cur: np.ndarray, uv_cur: np.ndarray, z_cur: np.ndarray,
                    ref_nearest: np.ndarray) -> np.ndarray:
    """Free-space score of current keypoints against a reference keyframe's depth image (ours).

    The keypoint's 3-D point is moved into the reference camera (depth ``z_r`` there). If the
    reference's nearest depth around that pixel (``ref_nearest``, :func:`nearest_depth`) lies
    beyond it, the reference camera saw through the place where the point is now: the point was
    not there, it moved. Score ``max(0, z_near - z_r) / z_r`` (the relative form of eq. 4's depth
    term; dynamic at ``sigma2``). A reference seeing something nearer (an occluder, a person)
    scores 0: it cannot tell. The window minimum keeps static points on depth edges, whose
    reprojection may land a pixel or two on the background, from scoring. nan: no depth at the
    keypoint, behind or outside the reference camera, or no depth in the window.

    This is paper B's depth comparison ``|z - z'|`` with ``z'`` read from the reference's depth
    image where the reference has no keypoint of the point: a point on a carried board exists in
    the map for a frame or two, so the keyframes that could expose its motion never observed it.
    """
    H, W = ref_nearest.shape
    score = np.full(len(uv_cur), np.nan)
    ok = np.flatnonzero(z_cur > 0)
    X = transform_points(T_ref_cur, backproject(camera, uv_cur[ok, 0], uv_cur[ok, 1], z_cur[ok]))
    u, v = project(camera, X)
    z_r = X[:, 2]
    front = z_r > 0.05
    ui, vi = np.rint(u[front]).astype(np.int64), np.rint(v[front]).astype(np.int64)
    inside = (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
    ok, z_r, ui, vi = ok[front][inside], z_r[front][inside], ui[inside], vi[inside]
    near = ref_nearest[vi, ui]
    score[ok] = np.where(np.isfinite(near), np.maximum(near - z_r, 0.0) / z_r, np.nan)
    return score


def median_over_references(score: np.ndarray) -> np.ndarray:
    """(N,) median of each row's non-nan scores of ``score`` (N, R), rows with at least one:
    ``np.nanmedian(score, axis=1)`` (the mean of the two middle values of an even count, the
    middle one of an odd count) without its masked-array path, several times faster on the few
    columns of a reference set."""
    s = np.sort(score, axis=1)  # nan last
    n = np.count_nonzero(~np.isnan(score), axis=1)
    rows = np.arange(len(s))
    return (s[rows, (n - 1) // 2] + s[rows, n // 2]) / 2
