"""Image operations on masks and depth: morphology, depth discontinuities, instance splitting.

Shared by the mask sources (:mod:`dynslam_lite.masks`, :mod:`dynslam_lite.segmentation`) and the
papers' steps (depthcluster, bgrestore). Masks are ``(H, W) bool``; depth is ``(H, W)`` float
metres with 0 = no depth.
"""
from __future__ import annotations

import cv2
import numpy as np


def disk(r: int) -> np.ndarray:
    """Elliptic structuring element of radius ``r`` pixels."""
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def dilate(mask: np.ndarray, r: int) -> np.ndarray:
    """(H, W) bool mask dilated by a disk of radius ``r`` (unchanged for r <= 0)."""
    return cv2.dilate(mask.astype(np.uint8), disk(r)) > 0 if r > 0 else mask.astype(bool)


def depth_edges(depth: np.ndarray, jump: float = 0.1) -> np.ndarray:
    """(H, W) bool: the far side of every depth discontinuity, i.e. pixels whose 4-neighbour is
    nearer by more than ``jump`` x its depth; missing depth (0) makes no edge."""
    d = depth.astype(np.float32)
    edge = np.zeros(d.shape, bool)
    for axis in (0, 1):
        a = d[1:] if axis == 0 else d[:, 1:]  # each pixel and its up / left neighbour
        b = d[:-1] if axis == 0 else d[:, :-1]
        near = np.minimum(a, b)
        jumps = (near > 0) & (np.abs(a - b) > jump * near)
        far_a, far_b = jumps & (a > b), jumps & (b > a)
        if axis == 0:
            edge[1:] |= far_a
            edge[:-1] |= far_b
        else:
            edge[:, 1:] |= far_a
            edge[:, :-1] |= far_b
    return edge


def split_instances(mask: np.ndarray, min_area: int = 50, depth: np.ndarray | None = None,
                    depth_jump: float = 0.1) -> list[np.ndarray]:
    """Instances of a binary mask: connected components of at least ``min_area`` pixels.

    With ``depth``, the mask is first cut along depth discontinuities (:func:`depth_edges`), so
    two people overlapping in the image at different distances become two instances; each cut
    pixel is then given to the adjacent instance whose mean depth is closest to its own.
    """
    mask = mask.astype(bool)
    core = mask & ~depth_edges(depth, depth_jump) if depth is not None else mask
    # 4-connected after a cut: the one-pixel cut (4-neighbour jumps) leaks diagonally otherwise
    n, cc, stats, _ = cv2.connectedComponentsWithStats(core.astype(np.uint8),
                                                       connectivity=8 if depth is None else 4)
    keep = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= min_area]
    if depth is not None and keep:
        lut = np.zeros(n, np.int32)
        lut[keep] = keep
        cc = lut[cc]  # small components dropped
        mean = np.bincount(cc.ravel(), depth.ravel(), n) / np.maximum(np.bincount(cc.ravel(), None, n), 1)
        pad = np.pad(cc, 1)
        for _ in range(3):  # cuts are one pixel wide; a few rounds fill corners
            ys, xs = np.nonzero(mask & (pad[1:-1, 1:-1] == 0))
            if ys.size == 0:
                break
            nb = np.stack([pad[ys + 1 + dy, xs + 1 + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)], 1)
            cost = np.where(nb > 0, np.abs(depth[ys, xs, None] - mean[nb]), np.inf)
            best = nb[np.arange(len(ys)), np.argmin(cost, axis=1)]
            pad[ys + 1, xs + 1] = best  # 0 where no labelled neighbour yet
        cc = pad[1:-1, 1:-1]
    return [cc == i for i in keep]


def union(masks: list[np.ndarray]) -> np.ndarray | None:
    """(H, W) bool union of instance masks, or None when there are none."""
    if not masks:
        return None
    return np.logical_or.reduce(masks)
