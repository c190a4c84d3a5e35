"""Paper C, sec. 3: RGB and depth of the removed regions restored from the latest keyframes.

Every keyframe pixel with depth, outside the people of that keyframe, is moved into the
current camera, ``x_c = pi(T_cur_kf pi^-1(u, z))``. A pixel landing at sub-pixel ``(x, y)`` inside
the current hole adds its value to the four pixel centres ``(x', y')`` around it with the overlap
area of the two unit squares as weight (eq. 8),

    w = (min(x, x') + 0.5 - max(x, x') + 0.5) * (min(y, y') + 0.5 - max(y, y') + 0.5)
      = (1 - |x - x'|) (1 - |y - y'|),

and each hole pixel is the weight-normalised sum over all keyframes and landing pixels (eq. 9;
the paper prints the sum, normalising it is what makes it a colour). Depth is restored the same
way with the depth of the moved point in the current camera, not the keyframe's raw value.
Visibility (ours): at each landing pixel only the nearest surface contributes.

Pose (our choice, documented): the paper recovers R, t from the SVD of the fundamental matrix,
which gives t only up to scale and no metric depth for the mapping. With RGB-D we have metric depth
and the tracked keyframe poses, so ``T_cur_kf`` comes from the frontend; notebook 30 shows the
paper's F -> E -> (R, t) route beside it.

Vectorised: the projection of every keyframe pixel is one matrix product, the splat is one
``np.bincount`` per channel over the four corners of every point; a coarse pass on every 8th
pixel first finds the part of each keyframe's blocks that can land in the hole, so only those
are projected at full resolution.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .. import checks
from ..geometry import PinholeCamera, backproject


@dataclass
class KeyframeImage:
    """What a keyframe lends to the restoration.

    Attributes
    ----------
    rgb : (H, W, 3) uint8, restored colour; depth : (H, W) float32 metres, restored depth
    T_w_c : (4, 4) camera-to-world pose
    invalid : (H, W) bool, pixels not to be used (the people of that keyframe, see ``method.py``)
    """

    rgb: np.ndarray
    depth: np.ndarray
    T_w_c: np.ndarray
    invalid: np.ndarray


@dataclass
class Restoration:
    """Result of :func:`restore_from_keyframes`.

    Attributes
    ----------
    rgb, depth : the current frame with the restored hole pixels
    weight : (H, W) float32 summed splat weight per pixel (0 outside the hole)
    filled : (H, W) bool, hole pixels that received weight >= ``min_weight``
    """

    rgb: np.ndarray
    depth: np.ndarray
    weight: np.ndarray
    filled: np.ndarray


def _bbox(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """(row0, row1, col0, col1) bounding ``mask`` (end exclusive), None when it is empty."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    return None if not rows.size else (rows[0], rows[-1] + 1, cols[0], cols[-1] + 1)


def _project(camera: PinholeCamera, kf: KeyframeImage, T_cur_kf: np.ndarray, use: np.ndarray | None = None,
             step: int = 1):
    """Keyframe pixels with depth, outside ``kf.invalid`` (and inside ``use`` where given), every
    ``step``-th row and column, moved into the current camera: (x, y, depth there, u, v)."""
    r0, c0 = 0, 0
    if use is None:
        z = kf.depth[::step, ::step]
        ok = (z > 0) & ~kf.invalid[::step, ::step]
    else:  # only the bounding box of ``use`` is searched (the same pixels, in the same order)
        box = _bbox(use)
        if box is None:
            none = np.zeros(0, np.float32)
            return none, none, none, none.astype(np.int64), none.astype(np.int64)
        r0, r1, c0, c1 = box
        z = kf.depth[r0:r1, c0:c1]
        ok = (z > 0) & ~kf.invalid[r0:r1, c0:c1] & use[r0:r1, c0:c1]
    v, u = np.nonzero(ok)
    z = z[v, u].astype(np.float32)
    v, u = v * step + r0, u * step + c0
    P = backproject(camera, u.astype(np.float32), v.astype(np.float32), z)
    Pc = P @ T_cur_kf[:3, :3].T.astype(np.float32) + T_cur_kf[:3, 3].astype(np.float32)
    front = Pc[:, 2] > 0.05
    Pc, u, v = Pc[front], u[front], v[front]
    x = camera.fx * Pc[:, 0] / Pc[:, 2] + camera.cx
    y = camera.fy * Pc[:, 1] / Pc[:, 2] + camera.cy
    return x, y, Pc[:, 2], u, v


def _candidates(camera, kf, T_cur_kf, reach: np.ndarray, coarse: int = 8) -> np.ndarray | None:
    """(H, W) bool, the keyframe pixels that can land in the hole: a coarse pass moves every
    ``coarse``-th pixel, a block of ``coarse`` x ``coarse`` pixels is kept when its sample lands
    in ``reach`` (the hole widened by a margin), and so are its 8 neighbour blocks. None: no
    sample lands there."""
    H, W = reach.shape
    x, y, _, u, v = _project(camera, kf, T_cur_kf, None, coarse)
    xi, yi = np.rint(x).astype(np.int64), np.rint(y).astype(np.int64)
    hit = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H)
    hit[hit] = reach[yi[hit], xi[hit]]
    if not hit.any():
        return None
    blocks = np.zeros((-(-H // coarse), -(-W // coarse)), np.uint8)
    blocks[v[hit] // coarse, u[hit] // coarse] = 1
    blocks = cv2.dilate(blocks, np.ones((3, 3), np.uint8))
    return np.repeat(np.repeat(blocks, coarse, 0), coarse, 1)[:H, :W].astype(bool)


def splat(x: np.ndarray, y: np.ndarray, values: np.ndarray, hole: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 8-9 accumulation: (sum of w * value (H, W, C), sum of w (H, W)) over the hole pixels.

    ``values`` (N, C). Each point spreads over the 4 pixel centres around (x, y) with the
    unit-square overlap areas; only centres inside ``hole`` receive anything. Points must lie
    in [-1, W) x [-1, H). The sums run on a grid padded by one pixel (centres just outside the
    image take what falls there) with one ``np.bincount`` per channel.
    """
    H, W = hole.shape
    W2 = W + 2
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0).astype(np.float32), (y - y0).astype(np.float32)
    base = (y0.astype(np.int64) + 1) * W2 + x0.astype(np.int64) + 1
    k = np.concatenate([base, base + 1, base + W2, base + W2 + 1])
    w = np.concatenate([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy])

    def grid(weights):
        return np.bincount(k, weights, (H + 2) * W2).reshape(H + 2, W2)[1:-1, 1:-1] * hole

    wsum = grid(w)
    w4 = w.reshape(4, -1)  # the four corners' weights of each point
    acc = np.stack([grid((w4 * values[:, c]).reshape(-1)) for c in range(values.shape[1])], axis=-1)
    return acc, wsum


def restore_from_keyframes(camera: PinholeCamera, rgb: np.ndarray, depth: np.ndarray, hole: np.ndarray,
                           T_w_cur: np.ndarray, keyframes: list[KeyframeImage],
                           min_weight: float = 0.25, depth_tolerance: float = 0.05,
                           reach_px: int = 16) -> Restoration:
    """Fill ``hole`` of the current (rgb, depth) from ``keyframes`` (the paper uses the latest 20).

    Pixels outside the hole are returned unchanged; hole pixels reached by less than
    ``min_weight`` of splat weight keep their value and are not marked filled. Where keyframe
    pixels of several surfaces land on one pixel, only those within ``depth_tolerance``
    (relative) of the nearest are used: the paper has no visibility test, without one a
    foreground edge seen from another keyframe would bleed into the background behind it.
    Only the keyframe pixels near those whose coarse samples land within ``reach_px`` of the
    hole are moved at full resolution (:func:`_candidates`).
    """
    checks.rgb8("rgb", rgb)
    checks.depth("depth", depth, rgb.shape[:2])
    checks.mask("hole", hole, rgb.shape[:2])
    checks.pose("T_w_cur", T_w_cur)
    H, W = hole.shape
    pts = []
    if hole.any():
        T_cur_w = np.linalg.inv(T_w_cur)
        hole8 = hole.astype(np.uint8)
        near_hole = cv2.dilate(hole8, np.ones((3, 3), np.uint8)) > 0
        reach = cv2.dilate(hole8, np.ones((2 * reach_px + 1, 2 * reach_px + 1), np.uint8)) > 0
        for kf in keyframes:
            T = T_cur_w @ kf.T_w_c
            use = _candidates(camera, kf, T, reach)
            if use is None:
                continue
            x, y, zc, u, v = _project(camera, kf, T, use)
            xi, yi = np.rint(x).astype(np.int64), np.rint(y).astype(np.int64)
            land = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H)
            land[land] = near_hole[yi[land], xi[land]]
            k = np.flatnonzero(land)
            vals = np.empty((k.size, 4), np.float32)  # r, g, b, depth in the current camera
            vals[:, :3] = kf.rgb[v[k], u[k]]
            vals[:, 3] = zc[k]
            pts.append((x[k], y[k], yi[k] * W + xi[k], vals))
    if pts:
        x, y, pix, vals = (np.concatenate(a) for a in zip(*pts))
        # visibility: at each landing pixel keep the nearest surface (within depth_tolerance)
        zmin = np.full(H * W, np.inf, np.float32)
        np.minimum.at(zmin, pix, vals[:, 3])
        near = vals[:, 3] <= zmin[pix] * (1.0 + depth_tolerance)
        acc, wsum = splat(x[near], y[near], vals[near], hole)
    else:
        acc, wsum = np.zeros((H, W, 4)), np.zeros((H, W))
    filled = hole & (wsum >= min_weight)
    out_rgb, out_depth = rgb.copy(), depth.copy()
    norm = acc[filled] / wsum[filled, None]
    out_rgb[filled] = np.clip(np.rint(norm[:, :3]), 0, 255).astype(np.uint8)
    out_depth[filled] = norm[:, 3].astype(depth.dtype)
    return Restoration(out_rgb, out_depth, wsum.astype(np.float32), filled)
