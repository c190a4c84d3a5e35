"""Dense RGB-D odometry: coarse-to-fine Gauss-Newton on SE(3) over photometric + depth residuals.

For a reference frame A and a current frame B, find ``T = T_B_A`` minimising

    E(T) = sum_x  rho_I( r_I(x) ) + lambda_I * rho_D( r_D(x) )
    r_I(x) = I_B(w(x, T)) - I_A(x)
    r_D(x) = D_B(w(x, T)) - [T pi^-1(x, D_A(x))]_z
    w(x, T) = pi(T pi^-1(x, D_A(x)))

(paper A, eq. 5; identity covariance, rho = Huber as in robust DVO-style odometry). Updates
are left-multiplied: ``T <- exp(delta) T``. The sum runs over the valid pixels of A, optionally
restricted by a mask of static pixels: paper A's method reuses this solver with its masks.

With ``affine_brightness`` (off by default: eq. 5 as printed) the photometric residual is
``r_I(x) = I_B(w(x, T)) - (a I_A(x) + b)``, the gain a and bias b of the pair estimated with the
pose (two more unknowns of the same Gauss-Newton step, DSO's affine brightness model): a camera
with automatic exposure changes the brightness of the whole image between frames.

Intensities are in [0, 1]; depth in metres.

References: paper A (depthcluster), sec. 4, eq. 5; Kerl, Sturm, Cremers, "Robust odometry
estimation for RGB-D cameras", ICRA 2013 (DVO); Engel, Koltun, Cremers, "Direct Sparse
Odometry", TPAMI 2018 (affine brightness).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..checks import depth as check_depth, image01, mask as check_mask, pose as check_pose
from ..geometry import PinholeCamera, depth_pyramid, image_pyramid, interpolate, se3_exp


@dataclass
class DenseConfig:
    """Parameters of the dense solver.

    Attributes
    ----------
    levels : pyramid levels (level 0 = full resolution)
    finest_level : last level optimised (0 = full resolution; 1 = half resolution, default:
        about 3x faster, and on fr2/desk_50 and synthetic static_xyz within 1 mm of ATE of
        full resolution)
    iterations : maximum Gauss-Newton iterations per level, level 0 (finest) first; levels past
        the tuple take its last entry
    lambda_depth : lambda_I of eq. 5, weight of the depth residual (metres) against the
        photometric one (intensity in [0, 1]): 1 intensity unit ~ 1 m. Both residuals have a
        comparable noise floor on Kinect data (about 0.01 in intensity, 0.01 m at 2 m), hence 1.
        On the Bonn dev clip the depth term is the reliable one: with the person model's masks
        (dilated 10 px) excluded, frame to frame, ATE 0.350 / 0.281 / 0.109 / 0.074 / 0.079 m at
        lambda 0 / 1 / 10 / 30 / 100 (2026-12-04), but depthcluster at 30 gets 0.236 m against
        0.099 at 1 (its background update reads the photometric residuals); weights from each
        pair's residual spread (1.4826 MAD) instead of lambda and the Huber constants: 0.279 m.
        Not changed: a value picked on the one real dev clip would be tuned to it.
        Why the photometric term is weak there (2026-12-06, same masks, frame to frame, with
        ``affine_brightness``): photometric only 0.323 m, depth only 0.086 m. Started at the true
        relative pose, the photometric minimum lies on average 5.9 mm per frame off along x (std
        14 mm), the depth minimum 1.3 mm: a bias that accumulates, not noise. Not the lens
        distortion (the dataset's published k1, k2, p1, p2 undone on colour and depth: 0.326 m),
        not the registration of depth to colour (shifted by 2 px: 0.317-0.362 m), not vignetting
        (a radial gain of 20-50 % changes nothing), not outliers (Student-t weights, nu = 5, as
        DVO: 0.326 m), not the resolution (full: 0.318 m); leaving out a 10 % image border gives
        0.190 m. Cause not found (candidates: rolling shutter, the 7-11 ms between the colour and
        depth timestamps)
    huber_intensity : Huber threshold of the photometric residual (intensity units)
    huber_depth_m : Huber threshold of the depth residual (metres)
    min_depth_m, max_depth_m : reference pixels used
    min_gradient : minimum intensity-gradient magnitude (per pixel, [0, 1] units) of a reference
        pixel; 0 uses every pixel with valid depth (the depth residual works on flat texture too)
    min_valid_fraction : fewer valid residuals than this fraction of the pixels = failure
    step_tolerance : stop a level when the update norm falls below this
    affine_brightness : estimate a gain and bias of the reference intensities with the pose (see
        the module docstring); False = eq. 5 as printed. Measured on the Bonn dev clip with the
        true poses: at an exposure change the median photometric residual of the static room
        reaches 0.074 (19 grey levels; gain 1.06, bias +0.03), and an affine fit of each pair
        leaves a residual spread (1.4826 MAD) of 0.010-0.013 instead of 0.021-0.031; on TUM
        fr2/desk the median stays below 0.003, on the synthetic scenes below 0.0001 (except
        walking_exposure, built with automatic exposure: ``tables/exposure.md``)
    max_depth_diff_m : a correspondence whose depth in the current frame and transformed reference
        depth differ by more than this (metres) is left out of both terms: two surfaces meet there
        (an occluding or disoccluded one, e.g. a person entering the view or the wall behind one
        who left), so neither residual compares a surface with itself and the Huber weights
        would still let each such pixel pull the pose. 0 = every correspondence (eq. 5 as
        printed, the default); 0.07 is the default ``maxDepthDiff`` of OpenCV's RGB-D odometry,
        which rejects such correspondences the same way (paper A's method uses it, see
        :class:`~dynslam_lite.depthcluster.method.DepthClusterConfig`)
    """

    levels: int = 4
    finest_level: int = 1
    iterations: tuple[int, ...] = (12, 10, 8, 5)
    lambda_depth: float = 1.0
    huber_intensity: float = 0.04
    huber_depth_m: float = 0.04
    min_depth_m: float = 0.3
    max_depth_m: float = 6.0
    min_gradient: float = 0.0
    min_valid_fraction: float = 0.02
    step_tolerance: float = 1e-6
    affine_brightness: bool = False
    max_depth_diff_m: float = 0.0


@dataclass
class DenseResult:
    """Outcome of one frame-pair alignment.

    Attributes
    ----------
    T_cur_ref : (4, 4) estimated reference-to-current transform
    ok : False when the estimate is not trustworthy (too few residuals, non-finite values)
    reason : why it failed ('' when ok)
    valid_pixels : residuals used at the finest level
    cost_history : per level (coarsest first), the cost after each accepted iteration
    brightness : (gain a, bias b) of the reference intensities ((1, 0) without
        ``affine_brightness``)
    """

    T_cur_ref: np.ndarray
    ok: bool = True
    reason: str = ""
    valid_pixels: int = 0
    cost_history: list[list[float]] = field(default_factory=list)
    brightness: tuple[float, float] = (1.0, 0.0)


def _huber_weights(r: np.ndarray, k: float) -> np.ndarray:
    """Huber weights min(1, k / |r|) for k > 0, float32 (NaN where r is NaN)."""
    a = np.abs(r).astype(np.float32, copy=False)
    np.maximum(a, np.float32(k), out=a)  # |r| <= k gives k / k = 1 exactly
    return np.divide(np.float32(k), a, out=a)


def _geometric_jacobian(g_u, g_v, P, cam: PinholeCamera) -> np.ndarray:
    """d/d(delta) of a function sampled at pi(P), whose image gradient is (g_u, g_v).

    Parameters
    ----------
    g_u, g_v : (N,) gradient along columns / rows at the warped positions
    P : (3, N) points in the current camera frame (after the transform)
    Returns
    -------
    (6, N) float32, rows (v, w): translation then rotation. With q = g^T dpi/dP,
    the rotation part is P x q (left perturbation: dP/dw = -[P]x).
    """
    X, Y, Z = P
    iz = 1.0 / Z
    J = np.empty((6, Z.size), np.result_type(g_u, iz))  # rows written in place, no stacking copy
    a, b, c = J[0], J[1], J[2]
    np.multiply(g_u, cam.fx, out=a)
    a *= iz
    np.multiply(g_v, cam.fy, out=b)
    b *= iz
    np.multiply(a, X, out=c)
    c += b * Y
    np.negative(c, out=c)
    c *= iz
    np.multiply(Y, c, out=J[3])
    J[3] -= Z * b
    np.multiply(Z, a, out=J[4])
    J[4] -= X * c
    np.multiply(X, b, out=J[5])
    J[5] -= Y * a
    return J.astype(np.float32, copy=False)


class _Level:
    """Per-level data of the current frame: intensity, depth and their gradients."""

    def __init__(self, gray: np.ndarray, depth: np.ndarray, cam: PinholeCamera):
        self.cam = cam
        self.gray = gray
        self.depth = depth
        self.gu = cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=1) * 0.5  # central differences
        self.gv = cv2.Sobel(gray, cv2.CV_32F, 0, 1, ksize=1) * 0.5
        valid = (depth > 0).astype(np.float32)
        # depth gradients only where all neighbours used are valid
        self.du = cv2.Sobel(depth, cv2.CV_32F, 1, 0, ksize=1) * 0.5
        self.dv = cv2.Sobel(depth, cv2.CV_32F, 0, 1, ksize=1) * 0.5
        cross = cv2.erode(valid, np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8))
        # a depth sample interpolated across an object edge is meaningless: keep the depth
        # residual on locally smooth surfaces (step per pixel < 2 % of depth + 5 mm)
        step = np.maximum(np.abs(self.du), np.abs(self.dv))
        smooth = (step < 0.02 * depth + 0.005).astype(np.float32)
        cross = cv2.erode(cross * smooth, np.ones((3, 3), np.uint8))
        # two 4-channel images (the last channel unused): remap samples 4 channels at once and at
        # the exact position (see geometry.interpolate)
        self.stack = (cv2.merge([gray, self.gu, self.gv, depth]),
                      cv2.merge([self.du, self.dv, cross, np.zeros_like(cross)]))


def align(
    gray_ref: np.ndarray,
    depth_ref: np.ndarray,
    gray_cur: np.ndarray,
    depth_cur: np.ndarray,
    camera: PinholeCamera,
    T_init: np.ndarray | None = None,
    mask_ref: np.ndarray | None = None,
    config: DenseConfig | None = None,
    shared: dict | None = None,
    brightness: tuple[float, float] | None = None,
    validate: bool = True,
) -> DenseResult:
    """Estimate ``T_cur_ref`` by coarse-to-fine Gauss-Newton on eq. 5.

    Parameters
    ----------
    gray_ref, gray_cur : (H, W) float32 intensity in [0, 1]
    depth_ref, depth_cur : (H, W) float32 metres, 0 = invalid
    T_init : (4, 4) initial guess of T_cur_ref (identity when None)
    mask_ref : (H, W) bool, reference pixels allowed in the sums (static background); all if None
    shared : a dict kept by the caller between alignments of the same frame pair (paper A aligns
        each pair several times, with different masks): the pyramids, the current frame's
        gradients and each level's reference points (before the mask) are built once. A caller
        that tracks frame by frame may put the reference frame's ``(image, depth)`` pyramids in
        it as ``"ref_pyramids"`` (the previous pair's current frame, ``shared["pyramids"][2:]``)
    brightness : initial (gain, bias) with ``config.affine_brightness`` ((1, 0) when None)
    validate : False skips the checks of the images (a caller that has checked them and aligns
        the same pair again)
    Returns
    -------
    DenseResult
    """
    if validate:
        image01("gray_ref", gray_ref)
        image01("gray_cur", gray_cur, gray_ref.shape)
        check_depth("depth_ref", depth_ref, gray_ref.shape)
        check_depth("depth_cur", depth_cur, gray_ref.shape)
    if mask_ref is not None:
        check_mask("mask_ref", mask_ref, gray_ref.shape)
    if T_init is not None:
        check_pose("T_init", T_init)
    cfg = config or DenseConfig()
    T = np.eye(4) if T_init is None else np.asarray(T_init, float).copy()
    affine = cfg.affine_brightness
    ab = np.array((1.0, 0.0) if brightness is None else brightness, float)  # gain, bias
    shared = {} if shared is None else shared
    if shared.get("levels", 0) < cfg.levels:
        ref = shared.get("ref_pyramids")
        if ref is None or len(ref[0]) < cfg.levels:
            ref = image_pyramid(gray_ref.astype(np.float32), cfg.levels), depth_pyramid(depth_ref, cfg.levels)
        shared.update(levels=cfg.levels, pyramids=(
            *ref, image_pyramid(gray_cur.astype(np.float32), cfg.levels), depth_pyramid(depth_cur, cfg.levels)))
    gref, dref, gcur, dcur = shared["pyramids"]  # coarser levels unused when this call has fewer
    mref = None
    if mask_ref is not None:
        mref = image_pyramid(mask_ref.astype(np.float32), cfg.levels)
    history: list[list[float]] = []
    valid_pixels = 0
    ones = np.ones(4, np.float32)
    iters = list(cfg.iterations) + [cfg.iterations[-1]] * max(0, cfg.levels - len(cfg.iterations))
    for level in range(cfg.levels - 1, cfg.finest_level - 1, -1):
        cam = camera.scaled(level)
        if ("current", level) not in shared:
            shared["current", level] = _Level(gcur[level], dcur[level], cam)
        cur = shared["current", level]
        z = dref[level]
        key = ("reference", level, cfg.min_depth_m, cfg.max_depth_m, cfg.min_gradient)
        if key not in shared:  # the reference points of the pair, before the mask: built once
            sel = (z > cfg.min_depth_m) & (z < cfg.max_depth_m)
            if cfg.min_gradient > 0:
                g = gref[level]
                mag = np.hypot(cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=1), cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=1)) * 0.5
                sel &= mag >= cfg.min_gradient
            v, u = np.nonzero(sel)
            zs = z[v, u]
            shared[key] = (v, u, np.stack([(u - cam.cx) / cam.fx * zs, (v - cam.cy) / cam.fy * zs, zs]).astype(np.float32),
                           gref[level][v, u])
        v, u, P_ref, I_ref = shared[key]
        if mref is not None:
            keep = np.flatnonzero(mref[level][v, u] > 0.999)  # all fine pixels of the block are static
            P_ref, I_ref = np.take(P_ref, keep, axis=1), np.take(I_ref, keep)
        costs: list[float] = []
        min_valid = max(50, int(cfg.min_valid_fraction * z.size))
        prev_cost = np.inf
        T_prev, ab_prev = T.copy(), ab.copy()
        for _ in range(iters[level] if level < len(iters) else iters[-1]):
            P = T[:3, :3].astype(np.float32) @ P_ref + T[:3, 3:4].astype(np.float32)
            front = P[2] > 1e-3
            with np.errstate(divide="ignore", invalid="ignore"):
                pu = cam.fx * P[0] / P[2] + cam.cx
                pv = cam.fy * P[1] / P[2] + cam.cy
            inside = front & (pu >= 0) & (pu < cam.width - 1) & (pv >= 0) & (pv < cam.height - 1)
            idx = np.flatnonzero(inside)
            if idx.size < min_valid:
                return DenseResult(T_prev, False, f"only {idx.size} pixels overlap at level {level}",
                                   idx.size, history + [costs], tuple(ab_prev))
            s, sd = interpolate(cur.stack, pu[idx], pv[idx], inside=True)  # (I, I_u, I_v, D), (D_u, D_v, smooth, 0)
            if not (np.isfinite(s.sum()) and np.isfinite(sd.sum())):  # a non-finite sample makes the sum non-finite
                finite = np.isfinite(s @ ones) & np.isfinite(sd @ ones)
                idx, s, sd = idx[finite], s[finite], sd[finite]
            I_A = np.take(I_ref, idx)
            Pi = np.take(P, idx, axis=1)
            # the reference intensities, under the pair's gain and bias with affine_brightness
            r_I = s[:, 0] - (np.float32(ab[0]) * I_A + np.float32(ab[1]) if affine else I_A)
            w_I = _huber_weights(r_I, cfg.huber_intensity)
            with_depth = (sd[:, 2] > 0.999) & (s[:, 3] > 0)  # the samples with a depth residual
            n = idx.size
            if cfg.max_depth_diff_m > 0:  # two surfaces meet here: neither residual compares like with like
                apart = (s[:, 3] > 0) & (np.abs(s[:, 3] - Pi[2]) > np.float32(cfg.max_depth_diff_m))
                w_I[apart] = 0.0
                with_depth &= ~apart
                n -= int(np.count_nonzero(apart))
                if n < min_valid:
                    return DenseResult(T_prev, False, f"only {n} pixels of one surface at level {level}",
                                       n, history + [costs], tuple(ab_prev))
            di = np.flatnonzero(with_depth)
            sd, P_d = np.take(sd, di, axis=0), np.take(Pi, di, axis=1)
            r_D = s[di, 3] - P_d[2]
            w_D = _huber_weights(r_D, cfg.huber_depth_m) * np.float32(cfg.lambda_depth)
            cost = float(np.sum(w_I * r_I**2) + np.sum(w_D * r_D**2)) / n
            if not np.isfinite(cost):
                return DenseResult(T_prev, False, "non-finite cost", idx.size, history + [costs], tuple(ab_prev))
            if cost > prev_cost * (1.0 + 1e-7):
                T, ab = T_prev, ab_prev  # the last step made things worse: undo it, finish this level
                break
            costs.append(cost)
            prev_cost = cost
            valid_pixels = n
            # Jacobians only for an accepted pose (a rejected step ends the level)
            J_I = _geometric_jacobian(s[:, 1], s[:, 2], Pi, cam)
            J_D = _geometric_jacobian(sd[:, 0], sd[:, 1], P_d, cam)
            J_D[2] -= 1.0  # minus d(Z')/d(delta): translation (0, 0, 1), rotation (Y, -X, 0)
            J_D[3] -= P_d[1]
            J_D[4] += P_d[0]
            JwI = J_I * w_I
            JwD = J_D * w_D
            H = JwI @ J_I.T + JwD @ J_D.T
            b = JwI @ r_I + JwD @ r_D
            if affine:  # d r_I / d(a, b) = (-I_A, -1): two more rows of the photometric Jacobian
                J_ab = np.stack([-I_A, np.full(idx.size, -1.0, np.float32)])
                JwA = J_ab * w_I
                H6, H = H, np.empty((8, 8))
                H[:6, :6], H[:6, 6:], H[6:, :6], H[6:, 6:] = H6, JwI @ J_ab.T, JwA @ J_I.T, JwA @ J_ab.T
                b = np.concatenate([b, JwA @ r_I])
            try:
                delta = -np.linalg.solve(H.astype(float, copy=False), b.astype(float))
            except np.linalg.LinAlgError:
                return DenseResult(T, False, "singular normal equations", idx.size, history + [costs], tuple(ab))
            T_prev, ab_prev = T, ab
            T = se3_exp(delta[:6]) @ T
            if affine:
                ab = ab + delta[6:]
            if np.linalg.norm(delta) < cfg.step_tolerance:
                break
        history.append(costs)
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(ab))):
        return DenseResult(np.eye(4), False, "non-finite pose", valid_pixels, history)
    return DenseResult(T, True, "", valid_pixels, history, (float(ab[0]), float(ab[1])))
