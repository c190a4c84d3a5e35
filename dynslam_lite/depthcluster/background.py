"""Step 4 of paper A: background update from the residuals of the estimated pose (sec. 5, fig. 6).

With the current estimate T = T_B_A, frame B is warped into A; pixels of A whose photometric
residual ``r_I = I_B(w(x, T)) - I_A(x)`` is an outlier are moving (or occluded by something
moving in B) and leave the static background. The threshold adapts to the residual noise of the
pixels still considered static:

    tau = max(tau_min, k * 1.4826 * MAD(r_I over static pixels))

(1.4826 * MAD is a robust standard deviation; k = 3 flags about 0.3 % of Gaussian inliers).
Isolated outliers from image noise and sub-pixel misalignment of strong edges are removed by a
3 x 3 morphological opening, and the rest dilated to cover the blurred outline of the object.
The paper uses the photometric residual only; ``depth_outliers`` adds the depth residual
``r_D = D_B(w(x, T)) - [T pi^-1(x)]_z`` with a tolerance growing with depth, for uniformly
coloured people in front of uniformly coloured walls (off by default, as printed).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..geometry import PinholeCamera, interpolate, warp_coordinates
from ..imageops import dilate
from .clustering import grow_to_components


@dataclass
class OutlierConfig:
    """Parameters of the outlier test (intensities in [0, 1], depth in metres)."""

    k_sigma: float = 3.0
    tau_min: float = 0.06
    depth_outliers: bool = False
    depth_tol_m: float = 0.05
    depth_tol_rel: float = 0.03
    open_px: int = 3
    dilate_px: int = 7
    grow: bool = True
    grow_min_overlap: float = 0.2
    grow_max_area_fraction: float = 0.15


def residuals(
    gray_ref: np.ndarray, depth_ref: np.ndarray, gray_cur: np.ndarray, depth_cur: np.ndarray,
    camera: PinholeCamera, T_cur_ref: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Photometric and depth residual images on the reference pixels (NaN where undefined).

    Parameters
    ----------
    gray_ref, gray_cur : (H, W) float32 in [0, 1]
    depth_ref, depth_cur : (H, W) float32 metres
    Returns
    -------
    r_I, r_D : (H, W) float32
    """
    mu, mv, z = warp_coordinates(camera, depth_ref, T_cur_ref)
    u, v = np.nan_to_num(mu, nan=-1.0).ravel(), np.nan_to_num(mv, nan=-1.0).ravel()
    s = interpolate(np.dstack([gray_cur, depth_cur]).astype(np.float32), u, v)
    r_i = (s[:, 0] - gray_ref.ravel()).reshape(gray_ref.shape)
    d = s[:, 1].reshape(z.shape)
    r_d = np.where(d > 0, d - z, np.nan).astype(np.float32)
    return r_i.astype(np.float32), r_d


def outliers(
    r_i: np.ndarray, r_d: np.ndarray, depth_ref: np.ndarray, static: np.ndarray,
    config: OutlierConfig | None = None, components=None,
) -> tuple[np.ndarray, float]:
    """Moving pixels of the reference frame from the residual images.

    Parameters
    ----------
    r_i, r_d : residual images from :func:`residuals`
    static : (H, W) bool, pixels currently believed static (the MAD is taken over them)
    components : optional ``(components, areas)`` of :func:`.clustering.layer_components`: a
        region of one depth layer mostly made of outliers is taken whole (``grow``), the
        paper's "largest connected region of the same depth" applied to the update as well
    Returns
    -------
    mask : (H, W) bool, outliers after opening and dilation
    tau : the photometric threshold used
    """
    cfg = config or OutlierConfig()
    a = np.abs(r_i)
    ok = np.isfinite(a) & static
    if ok.sum() < 100:
        return np.zeros(r_i.shape, bool), float("nan")
    mad = float(np.median(np.abs(r_i[ok] - np.median(r_i[ok]))))
    tau = max(cfg.tau_min, cfg.k_sigma * 1.4826 * mad)
    out = np.isfinite(a) & (a > tau)
    if cfg.depth_outliers:
        tol = cfg.depth_tol_m + cfg.depth_tol_rel * depth_ref
        out |= np.isfinite(r_d) & (np.abs(r_d) > tol)
    m = out.astype(np.uint8)
    if cfg.open_px:
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, np.ones((cfg.open_px, cfg.open_px), np.uint8))
    m = m.astype(bool)
    if cfg.grow and components is not None:
        comp, areas = components
        m = grow_to_components(m, comp, areas, cfg.grow_min_overlap, cfg.grow_max_area_fraction * m.size)
    m = dilate(m, cfg.dilate_px)
    return m, tau
