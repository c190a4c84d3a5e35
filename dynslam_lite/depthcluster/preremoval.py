"""Step 2 of paper A: pre-removal of moving objects from the change of depth (sec. 3, sec. 6.1).

The reference depth image A is cut into ``rows x cols`` equal blocks (the paper's k regions).
A block holding a single depth layer says nothing and is ignored; a block holding several layers
contains an object "edge". If only the camera moved, the depth difference across the edge
(far layer minus near layer) is

* unchanged under a translation (paper fig. 4a), or
* scaled by one common factor under a rotation (similar triangles, fig. 4b).

For every edge block, with the current frame B's depth assigned to A's layers:

    e_b   = min(|dB - dA|, |dB - s * dA|)   s = median over edge blocks of dB / dA
    s_d   = clip(e_b / (2 tol_b), 0, 1)      tol_b = depth_tol_m + depth_tol_rel * z_far
    s_f   = clip((TV_b - median TV) / (2 fraction_tol), 0, 1)
    c_b   = 1 - (1 - s_d) * (1 - s_f)        (the weighted dynamic coefficient)

``TV_b`` is half the L1 distance between the layer fractions of the block in A and B: how much
of the block changed layer. The camera motion shifts every edge by a similar few pixels, so its
share is the median over edge blocks; an object moving on its own changes its blocks by more.
The paper does not print its weighting; we combine the two violations as independent evidence
("noisy-or"), so each score alone reaches 0.5 at two tolerances, and together earlier.
Blocks with ``c_b > 0.5`` are dynamic. The layer that changed its mean
depth most between A and B is the moving one (the near layer on ties: moving objects occlude).
The largest connected region of that layer touching the block is removed, as in the paper;
a region larger than ``max_region_fraction`` of the image (a floor or wall sharing the layer) is
cut to the dynamic blocks and their 8 neighbours instead, the failure the paper reports on
sitting_halfsphere.

Measured and not adopted (2026-12-05, depthcluster's defaults otherwise, single runs, ATE RMSE):
on synthetic crowd, frames 122-127, a person passing 1 m from the camera makes the far layer
(the room) change most in the blocks on its outline; the room's region is cut to those blocks,
half the room is removed, the second person is not, and the pose follows that person by
36-52 mm a frame. Two other choices of the layer: (a) always the near layer of the edge, (b) the
other layer of the edge where the chosen layer's region exceeds ``max_region_fraction`` and the
other's does not. Synthetic walking_xyz 0.0294 -> (a) 0.0125 / (b) 0.0172 m, crowd 0.0715 ->
0.0266 / 0.0429, walking_halfsphere 0.0153 -> 0.0135 / 0.0142, static_xyz and TUM fr2/desk
unchanged; but the Bonn dev clip 0.0911 -> 0.1283 / 0.2103, every 2nd frame 0.0826 -> 0.2023 /
0.1764, every 3rd 0.1093 -> 0.1421 / 0.1284. In the real clip the room around the people is
better left out (their blurred outlines, noisier depth), so the synthetic gain does not carry.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from .clustering import DepthClusters, assign


@dataclass
class PreRemovalConfig:
    """Parameters of the block test (the paper's k = rows * cols blocks; 6 x 8 = 48 of 80 x 80
    px at 640 x 480: large enough to hold both sides of a person's edge, small enough to localise).
    """

    rows: int = 6
    cols: int = 8
    min_fraction: float = 0.08
    depth_tol_m: float = 0.05
    depth_tol_rel: float = 0.03
    fraction_tol: float = 0.05
    threshold: float = 0.5
    max_region_fraction: float = 0.25


@dataclass
class PreRemoval:
    """Result of the block test on one frame pair (per-block arrays have length rows * cols).

    Attributes
    ----------
    edge : blocks with at least two depth layers in A
    depth_score, fraction_score, coefficient : s_d, s_f and c_b (0 for non-edge blocks)
    dynamic : blocks with c_b above the threshold
    moving_layer : layer judged to move in each dynamic block (-1 elsewhere)
    scale : the common rotation factor s
    mask : (H, W) bool, reference pixels removed as moving
    """

    edge: np.ndarray
    depth_score: np.ndarray
    fraction_score: np.ndarray
    coefficient: np.ndarray
    dynamic: np.ndarray
    moving_layer: np.ndarray
    scale: float
    mask: np.ndarray
    shape: tuple[int, int]

    def block_slices(self, b: int, rows: int, cols: int) -> tuple[slice, slice]:
        H, W = self.shape
        bh, bw = H // rows, W // cols
        r, c = divmod(b, cols)
        return slice(r * bh, (r + 1) * bh), slice(c * bw, (c + 1) * bw)


@lru_cache(maxsize=4)
def _block_ids(shape: tuple[int, int], rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """Block index of every pixel (H, W) and the pixel count of every block."""
    ids = _per_pixel(np.arange(rows * cols, dtype=np.int64).reshape(rows, cols), shape)
    px = np.bincount(ids.ravel(), minlength=rows * cols).astype(float)
    ids.flags.writeable = px.flags.writeable = False
    return ids, px


@lru_cache(maxsize=16)
def _layer_keys(shape: tuple[int, int], rows: int, cols: int, n: int) -> np.ndarray:
    """``block * (n + 1) + 1`` per pixel, flat: the key of (block, layer) is this plus the layer."""
    keys = (_block_ids(shape, rows, cols)[0] * (n + 1) + 1).ravel()
    keys.flags.writeable = False
    return keys


def _layer_stats(key: np.ndarray, depth: np.ndarray, K: int, n: int):
    """Per (block, layer): pixel count and mean depth, as (K, n) arrays; ``key`` is
    ``block * (n + 1) + labels + 1`` (column 0 of each block: no layer, label -1)."""
    count = np.bincount(key, minlength=K * (n + 1)).reshape(K, n + 1)[:, 1:].astype(float)
    total = np.bincount(key, weights=depth.ravel(), minlength=K * (n + 1)).reshape(K, n + 1)[:, 1:]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return count, mean


def pre_remove(
    clusters_ref: DepthClusters, depth_cur_filled: np.ndarray, config: PreRemovalConfig | None = None
) -> PreRemoval:
    """Blocks whose depth change a camera motion cannot explain, and the regions they touch.

    Parameters
    ----------
    clusters_ref : depth layers of the reference frame A
    depth_cur_filled : (H, W) hole-filled depth of the current frame B (metres)
    """
    cfg = config or PreRemovalConfig()
    shape = clusters_ref.labels.shape
    K, n = cfg.rows * cfg.cols, max(clusters_ref.n, 1)
    block, px = _block_ids(shape, cfg.rows, cfg.cols)
    lab_a = clusters_ref.labels
    lab_b = assign(depth_cur_filled, clusters_ref.centres) if clusters_ref.n else lab_a
    base = _layer_keys(shape, cfg.rows, cfg.cols, n)
    cnt_a, mean_a = _layer_stats(base + lab_a.ravel(), clusters_ref.filled, K, n)
    cnt_b, mean_b = _layer_stats(base + lab_b.ravel(), depth_cur_filled, K, n)
    frac_a, frac_b = cnt_a / px[:, None], cnt_b / px[:, None]
    present = frac_a >= cfg.min_fraction
    edge = present.sum(axis=1) >= 2
    idx = np.arange(n)
    near = np.where(present, idx, n).min(axis=1)
    far = np.where(present, idx, -1).max(axis=1)
    rows_ = np.arange(K)
    e_near, e_far = np.clip(near, 0, n - 1), np.clip(far, 0, n - 1)
    d_a = mean_a[rows_, e_far] - mean_a[rows_, e_near]
    d_b = mean_b[rows_, e_far] - mean_b[rows_, e_near]
    both = edge & (frac_b[rows_, e_near] >= cfg.min_fraction / 2) & (frac_b[rows_, e_far] >= cfg.min_fraction / 2)
    ratio = d_b[both] / d_a[both]
    scale = float(np.median(ratio)) if ratio.size else 1.0
    err = np.minimum(np.abs(d_b - d_a), np.abs(d_b - scale * d_a))
    tol = cfg.depth_tol_m + cfg.depth_tol_rel * mean_a[rows_, e_far]
    depth_score = np.where(both, np.clip(err / (2 * tol), 0, 1), 1.0)  # a vanished layer: violated
    tv = 0.5 * np.abs(frac_b - frac_a).sum(axis=1)
    tv_camera = float(np.median(tv[edge])) if edge.any() else 0.0
    fraction_score = np.clip((tv - tv_camera) / (2 * cfg.fraction_tol), 0, 1)
    coef = np.where(edge, 1 - (1 - depth_score) * (1 - fraction_score), 0.0)
    depth_score = np.where(edge, depth_score, 0.0)
    fraction_score = np.where(edge, fraction_score, 0.0)
    dynamic = coef > cfg.threshold
    # the layer that moved: largest change of mean depth (near layer on ties / missing data)
    ch_near = np.nan_to_num(np.abs(mean_b[rows_, e_near] - mean_a[rows_, e_near]), nan=np.inf)
    ch_far = np.nan_to_num(np.abs(mean_b[rows_, e_far] - mean_a[rows_, e_far]), nan=0.0)
    moving = np.where(dynamic, np.where(ch_far > ch_near, e_far, e_near), -1)
    mask = _remove_regions(lab_a, block, dynamic, moving, cfg)
    return PreRemoval(edge, depth_score, fraction_score, coef, dynamic, moving, scale, mask, shape)


def _per_pixel(values: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(rows, cols) per-block values spread over the (H, W) pixels of the blocks: ``H // rows`` x
    ``W // cols`` pixels each, the last row and column of blocks taking the remainder (the block
    layout; :func:`_block_ids` numbers the blocks with it)."""
    (rows, cols), (H, W) = values.shape, shape
    reps_r = np.full(rows, H // rows)
    reps_r[-1] += H - rows * (H // rows)
    reps_c = np.full(cols, W // cols)
    reps_c[-1] += W - cols * (W // cols)
    return np.repeat(np.repeat(values, reps_r, axis=0), reps_c, axis=1)


def _remove_regions(labels, block, dynamic, moving, cfg: PreRemovalConfig) -> np.ndarray:
    """Union of the largest connected region of the moving layer touching each dynamic block."""
    H, W = labels.shape
    mask = np.zeros((H, W), bool)
    if not dynamic.any():
        return mask
    limit = cfg.max_region_fraction * H * W
    near_dyn = cv2.dilate(dynamic.reshape(cfg.rows, cfg.cols).astype(np.uint8), np.ones((3, 3), np.uint8))
    near_dyn_px = _per_pixel(near_dyn.astype(bool), (H, W))
    px = np.flatnonzero(_per_pixel(dynamic.reshape(cfg.rows, cfg.cols), (H, W)))  # the pixels of the dynamic blocks
    px_block = block.ravel()[px]
    px_layer = moving[px_block]
    for layer in np.unique(moving[dynamic]):
        n_cc, cc = cv2.connectedComponents((labels == layer).astype(np.uint8), connectivity=8)
        area = np.bincount(cc.ravel(), minlength=n_cc)
        # per dynamic block of this layer, the largest component of the layer inside it
        own = px_layer == layer
        comp = cc.ravel()[px[own]]
        inside = comp > 0
        keys = px_block[own][inside] * n_cc + comp[inside]
        uniq = np.flatnonzero(np.bincount(keys))  # the (block, component) pairs present, sorted
        b_of, c_of = np.divmod(uniq, n_cc)
        order = np.lexsort((c_of, -area[c_of], b_of))  # per block: largest first, then lowest id
        first = np.ones(order.size, bool)
        first[1:] = b_of[order][1:] != b_of[order][:-1]
        for c in np.unique(c_of[order][first]):  # the chosen regions (a few)
            region = cc == c
            if area[c] > limit:  # cut to the dynamic blocks' area
                region &= near_dyn_px
            mask |= region
    return mask
