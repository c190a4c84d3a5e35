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
``np.bincount`` per channel over the four corners of every point, into the hole's pixels only; a
coarse pass on every 4th pixel (back-projected once per keyframe, ``KeyframeImage.cache``) first
finds the part of each keyframe's blocks that can land in the hole, so only those are projected at
full resolution.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

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
    cache : what the restoration computes once per keyframe, whatever its pose (the coarse
        samples back-projected); ``dataclasses.replace`` with a refined pose shares it
    """

    rgb: np.ndarray
    depth: np.ndarray
    T_w_c: np.ndarray
    invalid: np.ndarray
    cache: dict = field(default_factory=dict, repr=False, compare=False)


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
    ``step``-th row and column, moved into the current camera: (x, y, depth there, flat index
    ``v * W + u`` of the keyframe pixel), in row-major order of the keyframe pixels."""
    if use is None:  # the same samples at every pose: back-projected once per keyframe
        key = ("samples", step, camera)
        if key not in kf.cache:
            kf.cache[key] = _backproject(camera, kf, None, step)
        P, index = kf.cache[key]
    else:
        P, index = _backproject(camera, kf, use, step)
    Pc = P @ T_cur_kf[:3, :3].T.astype(np.float32)
    Pc += T_cur_kf[:3, 3].astype(np.float32)
    front = Pc[:, 2] > 0.05
    if not front.all():
        Pc, index = np.compress(front, Pc, axis=0), np.compress(front, index)
    x = camera.fx * Pc[:, 0] / Pc[:, 2] + camera.cx
    y = camera.fy * Pc[:, 1] / Pc[:, 2] + camera.cy
    return x, y, Pc[:, 2], index


def _backproject(camera: PinholeCamera, kf: KeyframeImage, use: np.ndarray | None, step: int):
    """The keyframe pixels of :func:`_project` in the keyframe's camera: (P (N, 3) float32, flat
    index ``v * W + u``)."""
    H, W = kf.depth.shape
    r0 = 0
    if use is None:
        z = kf.depth[::step, ::step]
        ok = (z > 0) & ~kf.invalid[::step, ::step]
    else:  # only the rows of ``use`` are searched (the same pixels, in the same order)
        rows = np.flatnonzero(use.any(axis=1))
        if not rows.size:
            return np.zeros((0, 3), np.float32), np.zeros(0, np.int64)
        r0, r1 = rows[0], rows[-1] + 1
        z = kf.depth[r0:r1]
        ok = (z > 0) & ~kf.invalid[r0:r1] & use[r0:r1]
    w = ok.shape[1]
    flat = np.flatnonzero(ok)
    z = np.take(np.ascontiguousarray(z).ravel(), flat).astype(np.float32, copy=False)
    v, u = np.divmod(flat, w)
    v, u = v * step + r0, u * step
    # pi^-1 as in geometry.backproject, its per-column and per-row factors looked up
    P = np.empty((flat.size, 3), np.float32)
    P[:, 0] = _ray_factor(W, camera.cx, camera.fx)[u] * z
    P[:, 1] = _ray_factor(H, camera.cy, camera.fy)[v] * z
    P[:, 2] = z
    return P, v * W + u


@lru_cache(maxsize=8)
def _ray_factor(n: int, c: float, f: float) -> np.ndarray:
    """``(i - c) / f`` for the pixel coordinates i = 0..n-1, float32 (read-only)."""
    out = (np.arange(n, dtype=np.float32) - c) / f
    out.flags.writeable = False
    return out


def _candidates(camera, kf, T_cur_kf, reach: np.ndarray, coarse: int = 4) -> np.ndarray | None:
    """(H, W) bool, the keyframe pixels that can land in the hole: a coarse pass moves every
    ``coarse``-th pixel, a block of ``coarse`` x ``coarse`` pixels is kept when its sample lands
    in ``reach`` (the hole widened by a margin), and so are its 8 neighbour blocks. None: no
    sample lands there."""
    H, W = reach.shape
    x, y, _, index = _project(camera, kf, T_cur_kf, None, coarse)
    xi, yi = np.rint(x).astype(np.int64), np.rint(y).astype(np.int64)
    hit = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H)
    hit[hit] = reach[yi[hit], xi[hit]]
    if not hit.any():
        return None
    v, u = np.divmod(index[hit], W)
    blocks = np.zeros((-(-H // coarse), -(-W // coarse)), np.uint8)
    blocks[v // coarse, u // coarse] = 1
    blocks = cv2.dilate(blocks, np.ones((3, 3), np.uint8))
    size = (blocks.shape[1] * coarse, blocks.shape[0] * coarse)  # each block back to its pixels
    return cv2.resize(blocks, size, interpolation=cv2.INTER_NEAREST)[:H, :W].view(bool)


def splat(x: np.ndarray, y: np.ndarray, values: np.ndarray, hole: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 8-9 accumulation: (sum of w * value (H, W, C), sum of w (H, W)) over the hole pixels.

    ``values`` (N, C). Each point spreads over the 4 pixel centres around (x, y) with the
    unit-square overlap areas; only centres inside ``hole`` receive anything.
    """
    H, W = hole.shape
    acc, wsum = np.zeros((H, W, values.shape[1])), np.zeros((H, W))
    box = _bbox(hole)
    if box is not None:
        r0, r1, c0, c1 = box
        crop = hole[r0:r1, c0:c1]
        a, w = _splat_hole(x, y, values.T, box, crop)
        acc[r0:r1, c0:c1][crop], wsum[r0:r1, c0:c1][crop] = a.T, w
    return acc, wsum


def _splat_hole(x, y, values, box, crop):
    """The sums of :func:`splat` over the hole pixels ``crop`` of ``box`` (row0, row1, col0, col1):
    (acc (C, n), wsum (n,)) for the n pixels of ``crop`` in row-major order; ``values`` (C, N),
    channels first.

    One ``np.bincount`` per channel over the four corners of every point; a lookup table sends
    every pixel centre outside the hole to one extra bin, which is dropped (each hole pixel sums
    the same terms in the same order as a sum over the whole box). Points whose four centres
    all lie outside the box are left out.
    """
    r0, r1, c0, c1 = box
    W2 = c1 - c0 + 2  # the box padded by one pixel
    inside = _touches_box(x, y, box)
    if not inside.all():
        x, y, values = np.compress(inside, x), np.compress(inside, y), np.compress(inside, values, axis=1)
    x0, y0 = np.floor(x), np.floor(y)
    xl, yl = x0.astype(np.int64) - (c0 - 1), y0.astype(np.int64) - (r0 - 1)  # padded-box coordinates
    fx, fy = (x - x0).astype(np.float32), (y - y0).astype(np.float32)
    n = int(np.count_nonzero(crop))
    lut = np.full((r1 - r0 + 2, W2), n, np.int64)
    lut[1:-1, 1:-1][crop] = np.arange(n)
    lut = lut.ravel()
    base = yl * W2 + xl
    # the four corners of each point (top left, top right, bottom left, bottom right): their
    # bins and weights, corner by corner
    k = lut[base[None, :] + np.array([[0], [1], [W2], [W2 + 1]])].reshape(-1)
    gx, gy = 1 - fx, 1 - fy
    w4 = np.empty((4, fx.size), np.float32)
    np.multiply(gx, gy, out=w4[0])
    np.multiply(fx, gy, out=w4[1])
    np.multiply(gx, fy, out=w4[2])
    np.multiply(fx, fy, out=w4[3])
    wt = w4.reshape(-1)
    acc = np.empty((len(values), n))
    wc = np.empty(w4.shape)  # one buffer for the channels: each product rounded to float32, then summed in float64
    for c, channel in enumerate(values):
        np.multiply(w4, channel, out=wc, dtype=np.float32)
        acc[c] = np.bincount(k, wc.reshape(-1), n + 1)[:n]
    return acc, np.bincount(k, wt, n + 1)[:n]


def _touches_box(x, y, box) -> np.ndarray:
    """Points some of whose four surrounding pixel centres lie in ``box`` (row0, row1, col0, col1)."""
    r0, r1, c0, c1 = box
    return (x >= c0 - 1) & (x < c1) & (y >= r0 - 1) & (y < r1)


def restore_from_keyframes(camera: PinholeCamera, rgb: np.ndarray, depth: np.ndarray, hole: np.ndarray,
                           T_w_cur: np.ndarray, keyframes: list[KeyframeImage],
                           min_weight: float = 0.25, depth_tolerance: float = 0.05,
                           reach_px: int = 8, views: int | None = None) -> Restoration:
    """Fill ``hole`` of the current (rgb, depth) from ``keyframes`` (the paper uses the latest 20),
    given oldest first.

    Pixels outside the hole are returned unchanged; hole pixels reached by less than
    ``min_weight`` of splat weight keep their value and are not marked filled. Where keyframe
    pixels of several surfaces land on one pixel, only those within ``depth_tolerance``
    (relative) of the nearest are used: the paper has no visibility test, without one a
    foreground edge seen from another keyframe would bleed into the background behind it.
    Only the keyframe pixels near those whose coarse samples land within ``reach_px`` of the
    hole are moved at full resolution (:func:`_candidates`).

    ``views`` (ours): each hole pixel takes the newest ``views`` keyframes that reach it, and the
    keyframes stop once every hole pixel has them (None: every keyframe, eq. 9 as printed).
    """
    checks.rgb8("rgb", rgb)
    checks.depth("depth", depth, rgb.shape[:2])
    checks.mask("hole", hole, rgb.shape[:2])
    checks.pose("T_w_cur", T_w_cur)
    H, W = hole.shape
    box = _bbox(hole)
    pts = []
    if box is not None:
        T_cur_w = np.linalg.inv(T_w_cur)
        near_hole = cv2.dilate(hole.astype(np.uint8), np.ones((3, 3), np.uint8)).ravel() > 0
        wanting = hole.astype(np.uint8)  # hole pixels that still take views
        count = np.zeros(H * W, np.uint8)  # keyframes that reached each pixel
        widen = np.ones((2 * reach_px + 1, 2 * reach_px + 1), np.uint8)
        reach = cv2.dilate(wanting, widen) > 0
        for kf in keyframes[::-1]:  # newest first
            T = T_cur_w @ kf.T_w_c
            use = _candidates(camera, kf, T, reach)
            if use is None:
                continue
            x, y, zc, index = _project(camera, kf, T, use)
            xi, yi = np.rint(x).astype(np.int64), np.rint(y).astype(np.int64)
            land = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H)
            pix = np.where(land, yi * W + xi, 0)
            land &= near_hole[pix]
            if views is not None:
                land &= count[pix] < views
            k = np.flatnonzero(land)
            vals = np.empty((4, k.size), np.float32)  # r, g, b, depth in the current camera
            vals[:3] = np.take(kf.rgb.reshape(-1, 3), index[k], axis=0).T
            vals[3] = zc[k]
            pts.append((x[k], y[k], pix[k], vals))
            if views is not None:
                count[pix[k]] += 1  # once per pixel, however many points land there
                wanting = (hole & (count.reshape(H, W) < views)).astype(np.uint8)
                if not wanting.any():
                    break
                reach = cv2.dilate(wanting, widen) > 0
    out_rgb, out_depth = rgb.copy(), depth.copy()
    wsum = np.zeros((H, W), np.float32)
    filled = np.zeros((H, W), bool)
    if pts:
        x, y, pix = (np.concatenate(a) for a in list(zip(*pts))[:3])
        vals = np.concatenate([p[3] for p in pts], axis=1)
        # visibility: at each landing pixel keep the nearest surface (within depth_tolerance)
        zmin = np.full(H * W, np.inf, np.float32)
        np.minimum.at(zmin, pix, vals[3])
        near = (vals[3] <= zmin[pix] * (1.0 + depth_tolerance)) & _touches_box(x, y, box)
        if not near.all():  # np.compress: a few times faster than boolean indexing here
            x, y, vals = np.compress(near, x), np.compress(near, y), np.compress(near, vals, axis=1)
        r0, r1, c0, c1 = box
        crop = hole[r0:r1, c0:c1]
        acc, ws = _splat_hole(x, y, vals, box, crop)
        wsum[r0:r1, c0:c1][crop] = ws  # the hole pixels, row-major
        ok = ws >= min_weight
        done = filled[r0:r1, c0:c1]
        done[crop] = ok
        ws = np.compress(ok, ws)
        for c in range(4):  # channel by channel: boolean assignment of rows is slow
            norm = np.compress(ok, acc[c]) / ws
            if c < 3:
                np.clip(np.rint(norm, out=norm), 0, 255, out=norm)
                out_rgb[r0:r1, c0:c1, c][done] = norm
            else:
                out_depth[r0:r1, c0:c1][done] = norm
    return Restoration(out_rgb, out_depth, wsum, filled)
