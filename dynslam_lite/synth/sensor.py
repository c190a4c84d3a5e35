"""Kinect-like degradation of rendered colour and depth.

Depth: axial noise growing with distance (sigma = 1.2 mm + 1.9 mm * (z - 0.4 m)^2, the
Kinect v1 model of Nguyen et al., 3DIMPVT 2012), quantisation in disparity (1/8 pixel of a
580 px x 7.5 cm baseline sensor, steps of about 1 cm at 2 m), then the 1/5000 m of the PNG;
no depth beyond the far range, before the near range, on surfaces the sensor cannot see, at
most depth discontinuities (object edges) and at a few random pixels.
Colour: slight optical blur, additive noise, 8-bit.
"""
from __future__ import annotations

import cv2
import numpy as np

NEAR_M = 0.4
FAR_M = 4.8
DISPARITY_CONSTANT = 580.0 * 0.075 * 8.0  # f [px] * baseline [m] * 8 subpixel steps


def degrade_depth(
    depth: np.ndarray, no_depth: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Kinect-like depth from true depth.

    Parameters
    ----------
    depth : (H, W) float32, true depth in metres (inf = nothing hit)
    no_depth : (H, W) bool, surfaces without depth return
    Returns
    -------
    (H, W) float32 metres, 0 = no depth
    """
    z = np.where(np.isfinite(depth), depth, 0.0).astype(np.float32)
    sigma = 0.0012 + 0.0019 * (z - NEAR_M) ** 2
    noisy = z + sigma * rng.standard_normal(z.shape).astype(np.float32)
    with np.errstate(divide="ignore"):
        disparity = np.round(DISPARITY_CONSTANT / np.maximum(noisy, 1e-3))
        noisy = DISPARITY_CONSTANT / np.maximum(disparity, 1.0)
    # depth discontinuities: relative jump to a 4-neighbour larger than 4 %
    zmax = cv2.dilate(z, np.ones((3, 3), np.uint8))
    zmin = cv2.erode(z, np.ones((3, 3), np.uint8))
    edge = (zmax - zmin) > 0.04 * np.maximum(z, 1e-3)
    edge = cv2.dilate(edge.astype(np.uint8), np.ones((2, 2), np.uint8)).astype(bool)
    drop = edge & (rng.random(z.shape) < 0.75)
    drop |= no_depth | (z < NEAR_M) | (z > FAR_M) | (rng.random(z.shape) < 0.003)
    out = np.where(drop, 0.0, noisy).astype(np.float32)
    return np.round(out * 5000.0).astype(np.float32) / 5000.0


def degrade_rgb(rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(H, W, 3) float [0, 1] -> (H, W, 3) uint8 with blur (sigma 0.6 px) and noise (sigma 1.5)."""
    img = cv2.GaussianBlur(rgb, (0, 0), 0.6) * 255.0
    img = img + 1.5 * rng.standard_normal(img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)
