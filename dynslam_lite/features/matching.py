"""Descriptor matching of the frontend: search by projection, and plain descriptor matching."""
from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

from .orb import Features


def _unique_best(q: np.ndarray, t: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keep one match per train index (the smallest distance); ties broken by query index."""
    order = np.lexsort((q, d))
    q, t = q[order], t[order]
    _, first = np.unique(t, return_index=True)
    keep = np.sort(first)
    return q[keep], t[keep]


def search_by_projection(uv_proj: np.ndarray, desc: np.ndarray, feats: Features, radius_px: float,
                         scale_factor: float, max_distance: int = 80, ratio: float = 0.9
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Match projected map points to keypoints within a window (ORB-SLAM2's SearchByProjection).

    Parameters
    ----------
    uv_proj : (M, 2) predicted pixel positions of the map points
    desc : (M, 32) uint8 map point descriptors
    feats : the frame's keypoints
    radius_px : window half-size at octave 0; it grows with the keypoint's octave
    max_distance : largest Hamming distance accepted (of 256 bits)
    ratio : best distance must be below ``ratio`` times the second best in the window
    Returns
    -------
    map_idx, kp_idx : (K,) int, one-to-one matches
    """
    if len(uv_proj) == 0 or len(feats) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    r = radius_px * scale_factor ** feats.octave  # (N,)
    # the pairs within the largest window (k-d trees, Chebyshev distance), then each keypoint's own
    pairs = cKDTree(uv_proj).sparse_distance_matrix(cKDTree(feats.uv), float(r.max()) + 1.0, p=np.inf,
                                                    output_type="ndarray")
    pt, kp = pairs["i"], pairs["j"]  # map point, keypoint
    inside = (np.abs(uv_proj[pt, 0] - feats.uv[kp, 0]) <= r[kp]) & (np.abs(uv_proj[pt, 1] - feats.uv[kp, 1]) <= r[kp])
    pt, kp = pt[inside], kp[inside]
    if pt.size == 0:
        return np.zeros(0, int), np.zeros(0, int)
    # the map points with a keypoint in their window (sorted), and each pair's row among them
    counts = np.bincount(pt, minlength=len(uv_proj))
    rows = np.flatnonzero(counts)
    row_of = (np.cumsum(counts > 0) - 1)[pt]
    window = np.zeros((rows.size, len(feats)), np.uint8)
    window[row_of, kp] = 1
    knn = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(desc[rows], feats.desc, k=2, mask=window)
    t, d, d2 = _best_two(knn)
    # the best within max_distance, and below ratio times the second best where there is one
    keep = (d <= max_distance) & ~(d > ratio * d2)
    if not keep.any():
        return np.zeros(0, int), np.zeros(0, int)
    return _unique_best(rows[keep], t[keep], d[keep])


def _best_two(knn) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per query of a k = 2 ``knnMatch``: (train index of the best, its distance, the second
    best's distance); inf where a query has no match or no second one."""
    inf = float("inf")
    best = [(m[0].trainIdx, m[0].distance, m[1].distance if len(m) == 2 else inf) if m else (-1, inf, inf)
            for m in knn]
    if not best:
        return np.zeros(0, int), np.zeros(0), np.zeros(0)
    t, d, d2 = zip(*best)
    return np.array(t), np.array(d), np.array(d2)


def match_descriptors(desc_a: np.ndarray, desc_b: np.ndarray, ratio: float = 0.75,
                      max_distance: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Brute-force Hamming matches with Lowe's ratio test, one-to-one: (idx_a, idx_b)."""
    if len(desc_a) < 2 or len(desc_b) < 2:
        return np.zeros(0, int), np.zeros(0, int)
    knn = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(desc_a, desc_b, k=2)
    good = [(m[0].queryIdx, m[0].trainIdx, m[0].distance) for m in knn
            if len(m) == 2 and m[0].distance < ratio * m[1].distance and m[0].distance <= max_distance]
    if not good:
        return np.zeros(0, int), np.zeros(0, int)
    q, t, d = map(np.array, zip(*good))
    return _unique_best(q, t, d)
