"""Rigid-body and pinhole-camera geometry: SE(3)/so(3), projection, warping, pyramids.

Pure maths: nothing here reads files or plots.

Conventions
-----------
- Poses are (4, 4) homogeneous matrices named after their frames: ``T_a_b`` maps points
  expressed in frame b into frame a (``p_a = T_a_b @ p_b``). Trajectories are ``T_w_c``
  (camera-to-world), as in TUM files.
- Twists are ``xi = (v, w)``: translation part first (metres), rotation part second (radians),
  shape (6,). ``exp(xi)`` is the SE(3) exponential; updates are left-multiplied:
  ``T <- exp(delta) @ T``.
- Images are (H, W[, C]); points are (N, 3); depth is float32 metres with 0 = invalid.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

_EPS = 1e-10


def hat(w: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix of a 3-vector: ``hat(w) @ x == cross(w, x)``.

    Parameters
    ----------
    w : (3,) or (N, 3) float
    Returns
    -------
    (3, 3) or (N, 3, 3) float
    """
    w = np.asarray(w, dtype=float)
    H = np.zeros(w.shape + (3,))
    H[..., 0, 1], H[..., 0, 2] = -w[..., 2], w[..., 1]
    H[..., 1, 0], H[..., 1, 2] = w[..., 2], -w[..., 0]
    H[..., 2, 0], H[..., 2, 1] = -w[..., 1], w[..., 0]
    return H


def _so3_exp_and_jacobian(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``exp(hat(w))`` and left Jacobian V of SO(3) for a rotation vector (3,), sharing
    the angle, ``hat(w)`` and its sine and cosine (second-order Taylor expansions near 0)."""
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w)
    K = hat(w)
    if theta < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K, np.eye(3) + 0.5 * K + K @ K / 6.0
    sin, one_cos = np.sin(theta), 1.0 - np.cos(theta)
    return (np.eye(3) + sin / theta * K + one_cos / theta**2 * K @ K,
            np.eye(3) + one_cos / theta**2 * K + (theta - sin) / theta**3 * K @ K)


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: rotation vector (3,) radians -> rotation matrix (3, 3)."""
    return _so3_exp_and_jacobian(w)[0]


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) -> rotation vector (3,) radians, angle in [0, pi]."""
    R = np.asarray(R, dtype=float)
    cos = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    theta = np.arccos(cos)
    if theta < 1e-8:
        return 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if np.pi - theta < 1e-5:  # near pi: axis from the symmetric part
        B = (R + np.eye(3)) / 2.0
        axis = np.sqrt(np.clip(np.diag(B), 0.0, None))
        k = int(np.argmax(axis))
        axis = B[k] / axis[k]  # signs relative to the largest component
        axis /= np.linalg.norm(axis)
        return theta * axis
    return theta / (2.0 * np.sin(theta)) * np.array(
        [R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]
    )


def _left_jacobian(w: np.ndarray) -> np.ndarray:
    """Left Jacobian V of SO(3), so that the SE(3) translation is ``V @ v``."""
    return _so3_exp_and_jacobian(w)[1]


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """SE(3) exponential of a twist ``xi = (v, w)`` (6,) -> (4, 4) pose ``[exp(w) | V(w) v]``."""
    xi = np.asarray(xi, dtype=float).reshape(6)
    T = np.eye(4)
    R, V = _so3_exp_and_jacobian(xi[3:])
    T[:3, :3] = R
    T[:3, 3] = V @ xi[:3]
    return T


def se3_log(T: np.ndarray) -> np.ndarray:
    """SE(3) logarithm: (4, 4) pose -> twist ``(v, w)`` (6,)."""
    T = np.asarray(T, dtype=float)
    w = so3_log(T[:3, :3])
    v = np.linalg.solve(_left_jacobian(w), T[:3, 3])
    return np.concatenate([v, w])


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (4, 4) or a stack (N, 4, 4), without a general inverse."""
    T = np.asarray(T, dtype=float)
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    Ti = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    Ti[..., :3, :3] = Rt
    Ti[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    Ti[..., 3, 3] = 1.0
    return Ti


def normalize_pose(T: np.ndarray) -> np.ndarray:
    """Nearest rigid transform: the rotation block projected onto SO(3) (SVD).

    Products of many poses lose orthonormality by rounding; an algorithm that chains poses
    (motion models) calls this to keep ``invert`` exact.
    """
    U, _, Vt = np.linalg.svd(T[:3, :3])
    out = np.array(T, dtype=float)
    out[:3, :3] = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    out[3] = (0.0, 0.0, 0.0, 1.0)
    return out


def compose(*Ts: np.ndarray) -> np.ndarray:
    """Product ``Ts[0] @ Ts[1] @ ...`` of poses (each (4, 4) or broadcastable stacks)."""
    out = np.asarray(Ts[0], dtype=float)
    for T in Ts[1:]:
        out = out @ np.asarray(T, dtype=float)
    return out


def transform_points(T_a_b: np.ndarray, p_b: np.ndarray) -> np.ndarray:
    """Apply a pose to points: (4, 4), (N, 3) in frame b -> (N, 3) in frame a."""
    p_b = np.asarray(p_b)
    return p_b @ T_a_b[:3, :3].T + T_a_b[:3, 3]


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle of a rotation matrix (3, 3) in degrees."""
    return float(np.degrees(np.linalg.norm(so3_log(R))))


# --------------------------------------------------------------------------- camera


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics of a depth-registered RGB-D camera (no distortion).

    Attributes
    ----------
    fx, fy, cx, cy : float, pixels
    width, height : int, pixels
    depth_scale : float, stored depth units per metre (5000 for TUM and Bonn PNGs)
    name : str, preset name or 'custom'
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int = 640
    height: int = 480
    depth_scale: float = 5000.0
    name: str = "custom"

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled(self, level: int) -> "PinholeCamera":
        """Intrinsics of pyramid level ``level`` (each level halves the resolution).

        Coarse pixel i covers fine pixels 2i and 2i + 1 (2x2 block averaging), so
        ``c' = (c + 0.5) / 2 - 0.5``.
        """
        cam = self
        for _ in range(level):
            cam = PinholeCamera(
                cam.fx / 2.0, cam.fy / 2.0, (cam.cx + 0.5) / 2.0 - 0.5, (cam.cy + 0.5) / 2.0 - 0.5,
                cam.width // 2, cam.height // 2, cam.depth_scale, cam.name,
            )
        return cam


def backproject(camera: PinholeCamera, u: np.ndarray, v: np.ndarray, z: np.ndarray) -> np.ndarray:
    """pi^-1: pixels and depth -> camera-frame points.

    Parameters
    ----------
    u, v : (N,) float, pixel coordinates (column, row)
    z : (N,) float, depth in metres
    Returns
    -------
    (N, 3) float, points in the camera frame (metres)
    """
    x = (u - camera.cx) / camera.fx * z
    y = (v - camera.cy) / camera.fy * z
    return np.stack([x, y, z], axis=-1)


def project(camera: PinholeCamera, p_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """pi: camera-frame points (N, 3) -> pixel coordinates ``(u, v)``, each (N,).

    Points with z <= 0 give non-finite coordinates; callers test ``z > 0``.
    """
    z = p_c[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = camera.fx * p_c[:, 0] / z + camera.cx
        v = camera.fy * p_c[:, 1] / z + camera.cy
    return u, v


def depth_to_points(camera: PinholeCamera, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Back-project every valid depth pixel.

    Parameters
    ----------
    depth : (H, W) float32, metres, 0 = invalid
    Returns
    -------
    points : (N, 3) float, camera frame
    index : (N,) int, flat pixel index ``v * W + u`` of each point
    """
    H, W = depth.shape
    index = np.flatnonzero(depth.reshape(-1) > 0)
    v, u = np.divmod(index, W)
    return backproject(camera, u.astype(float), v.astype(float), depth.reshape(-1)[index]), index


@lru_cache(maxsize=8)
def _normalised_grid(H: int, W: int, fx: float, fy: float, cx: float, cy: float):
    """(x/z, y/z) of every pixel, float32, read-only (the same for every frame of a camera)."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float32)
    xn, yn = (u - cx) / fx, (v - cy) / fy
    xn.flags.writeable = yn.flags.writeable = False
    return xn, yn


def warp_coordinates(
    camera: PinholeCamera, depth_ref: np.ndarray, T_cur_ref: np.ndarray,
    pixels: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """w(x, xi): where each reference pixel lands in the current frame.

    Parameters
    ----------
    depth_ref : (H, W) float32, metres, 0 = invalid
    T_cur_ref : (4, 4), reference-to-current camera transform
    pixels : optional (u, v) integer columns and rows of some pixels; ``depth_ref`` then holds
        their depths (same shape) and only they are warped (same arithmetic as the whole image)
    Returns
    -------
    map_u, map_v : float32 (shape of ``depth_ref``), pixel coordinates in the current image
        (NaN where invalid)
    z_cur : float32, depth of the transformed point in the current frame (NaN where invalid)
    """
    shape = depth_ref.shape if pixels is None else (camera.height, camera.width)
    xn, yn = _normalised_grid(*shape, camera.fx, camera.fy, camera.cx, camera.cy)
    if pixels is not None:
        xn, yn = xn[pixels[1], pixels[0]], yn[pixels[1], pixels[0]]
    z = depth_ref.astype(np.float32, copy=False)
    x = xn * z
    y = yn * z
    R = T_cur_ref[:3, :3].astype(np.float32)
    t = T_cur_ref[:3, 3].astype(np.float32)

    def row(i: int) -> np.ndarray:  # R[i, 0] x + R[i, 1] y + R[i, 2] z + t[i], in place
        out = R[i, 0] * x
        out += R[i, 1] * y
        out += R[i, 2] * z
        out += t[i]
        return out

    X, Y, Z = row(0), row(1), row(2)
    invalid = ~((z > 0) & (Z > 1e-6))
    with np.errstate(divide="ignore", invalid="ignore"):
        X *= np.float32(camera.fx)
        X /= Z
        X += np.float32(camera.cx)
        Y *= np.float32(camera.fy)
        Y /= Z
        Y += np.float32(camera.cy)
    for a in (X, Y, Z):
        np.copyto(a, np.float32(np.nan), where=invalid)
    return X, Y, Z


def warp_image(
    camera: PinholeCamera, image_cur: np.ndarray, depth_ref: np.ndarray, T_cur_ref: np.ndarray
) -> np.ndarray:
    """Synthesise the reference view from the current image: ``I_cur(w(x, xi))``.

    Parameters
    ----------
    image_cur : (H, W[, C]) image of the current frame
    depth_ref : (H, W) float32 metres, depth of the reference frame
    T_cur_ref : (4, 4)
    Returns
    -------
    (H, W[, C]) float32, NaN where the warp leaves the image or depth is invalid
    """
    mu, mv, _ = warp_coordinates(camera, depth_ref, T_cur_ref)
    mu, mv = np.nan_to_num(mu, nan=-1.0), np.nan_to_num(mv, nan=-1.0)
    out = interpolate(image_cur.astype(np.float32), mu.reshape(-1), mv.reshape(-1))
    return out.reshape(depth_ref.shape + image_cur.shape[2:])


def sample_nearest(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Values of ``image`` at the nearest pixel of each of the (N, 2) points ``uv``, which are
    clipped to the image."""
    col = np.clip(np.rint(uv[:, 0]).astype(int), 0, image.shape[1] - 1)
    row = np.clip(np.rint(uv[:, 1]).astype(int), 0, image.shape[0] - 1)
    return image[row, col]


def _exact_parts(image: np.ndarray) -> list[np.ndarray]:
    """``image`` as images of 1, 3 or 4 channels, the counts OpenCV's ``remap`` interpolates at
    the exact sub-pixel position (measured on OpenCV 5.0: float images of 2 or more than 4
    channels are sampled at positions rounded to 1/32 pixel, errors up to 0.02 of the range)."""
    C = 1 if image.ndim == 2 else image.shape[2]
    if C in (1, 3, 4):
        return [image]
    sizes = [4] * (C // 4) + {0: [], 1: [1], 2: [1, 1], 3: [3]}[C % 4]
    ends = np.cumsum(sizes)
    return [np.ascontiguousarray(image[..., e - k:e]) for k, e in zip(sizes, ends)]


def interpolate(image, u: np.ndarray, v: np.ndarray, wrap: bool = False, inside: bool = False):
    """Bilinear samples of an image at scattered sub-pixel positions, with ``cv2.remap``.

    Parameters
    ----------
    image : (H, W) or (H, W, C) float32; or a tuple of such images of one size, sampled with the
        same maps (images of 1, 3 or 4 channels are sampled without a copy, see :func:`_exact_parts`)
    u, v : (N,) float, column / row coordinates (pixel centres at integers)
    wrap : tile the image (textures) instead of returning NaN outside ``[0, W-1] x [0, H-1]``
    inside : the caller has checked that every position lies in ``[0, W-1] x [0, H-1]`` (no NaN
        marking needed)
    Returns
    -------
    (N,) or (N, C) float32; a tuple of them for a tuple of images
    """
    images = image if isinstance(image, tuple) else (image,)
    n = u.size
    cols = 1024  # remap maps are limited to 32767 rows: lay the N samples out as a block
    rows = max(1, -(-n // cols))
    mu, mv = np.empty(rows * cols, np.float32), np.empty(rows * cols, np.float32)
    mu[:n], mv[:n] = u, v
    mu[n:] = mv[n:] = -1.0
    mu, mv = mu.reshape(rows, cols), mv.reshape(rows, cols)
    # replicate, then mark outside samples: a constant NaN border would leak into samples
    # lying exactly on the last row or column (NaN * 0 weight)
    border = cv2.BORDER_WRAP if wrap else cv2.BORDER_REPLICATE
    H, W = images[0].shape[:2]
    outside = None if wrap or inside else ~((u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1))
    samples = []
    for img in images:
        parts = [cv2.remap(p, mu, mv, cv2.INTER_LINEAR, borderMode=border).reshape((rows * cols,) + p.shape[2:])[:n]
                 for p in _exact_parts(img)]
        out = parts[0] if len(parts) == 1 else np.column_stack(parts)
        if outside is not None:
            out = out.astype(np.float32, copy=False)
            out[outside] = np.nan
        samples.append(out)
    return tuple(samples) if isinstance(image, tuple) else samples[0]


def image_pyramid(image: np.ndarray, levels: int) -> list[np.ndarray]:
    """Pyramid by 2x2 block averaging (``cv2.INTER_AREA``); level 0 is the input.

    Block averaging puts coarse pixel i at fine coordinate 2i + 0.5, the convention of
    :meth:`PinholeCamera.scaled` and :func:`depth_pyramid`.
    """
    pyr = [image]
    for _ in range(levels - 1):
        H, W = pyr[-1].shape[:2]
        pyr.append(cv2.resize(pyr[-1], (W // 2, H // 2), interpolation=cv2.INTER_AREA))
    return pyr


def depth_pyramid(depth: np.ndarray, levels: int) -> list[np.ndarray]:
    """Depth pyramid that averages only valid (non-zero) depths of each 2x2 block.

    Plain smoothing would blend valid depth with the zeros of missing pixels. Here each coarse
    pixel is the mean of the valid depths in its 2x2 block, or 0 when none is valid.
    """
    pyr = [depth.astype(np.float32)]
    for _ in range(levels - 1):
        d = pyr[-1]
        H, W = d.shape
        d = d[: H - H % 2, : W - W % 2]
        q = (d[0::2, 0::2], d[0::2, 1::2], d[1::2, 0::2], d[1::2, 1::2])  # the 4 pixels of each block
        total = (q[0] + q[1]) + (q[2] + q[3])
        valid = sum((x > 0).astype(np.float64) for x in q)
        with np.errstate(divide="ignore", invalid="ignore"):
            pyr.append(np.where(valid > 0, total / np.maximum(valid, 1), 0.0).astype(np.float32))
    return pyr


# --------------------------------------------------------------------------- epipolar geometry


def fundamental_from_pose(camera: PinholeCamera, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(3, 3) F with ``p_cur^T F p_ref = 0`` for ``T_cur_ref = [R | t]``: K^-T [t]x R K^-1."""
    Kinv = np.linalg.inv(camera.K)
    return Kinv.T @ hat(t) @ R @ Kinv


def epipolar_distance(F: np.ndarray, uv_ref: np.ndarray, uv_cur: np.ndarray) -> np.ndarray:
    """(N,) pixel distance of p_cur from its epipolar line F p_ref (paper C, eq. 3)."""
    p1 = np.column_stack([uv_ref, np.ones(len(uv_ref))])
    p2 = np.column_stack([uv_cur, np.ones(len(uv_cur))])
    line = p1 @ F.T  # (A, B, C) per point
    return np.abs(np.sum(p2 * line, axis=1)) / np.maximum(np.hypot(line[:, 0], line[:, 1]), 1e-12)
