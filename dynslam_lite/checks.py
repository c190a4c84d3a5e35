"""Shape, dtype and range checks at the public entry points: a wrong layout stops with a message
naming the argument and what was expected, instead of a silently wrong result."""
from __future__ import annotations

import numpy as np


def _shape(a: np.ndarray) -> str:
    return f"{a.shape} {a.dtype}"


def image01(name: str, a, shape: tuple[int, int] | None = None) -> None:
    """``a`` is an (H, W) float intensity image in [0, 1] (of ``shape`` when given)."""
    a = np.asarray(a)
    if a.ndim != 2 or a.dtype.kind != "f":
        raise ValueError(f"{name} must be an (H, W) float image with values in [0, 1], got {_shape(a)}"
                         + (" (divide an 8-bit image by 255)" if a.dtype == np.uint8 else ""))
    if shape is not None and a.shape != tuple(shape):
        raise ValueError(f"{name} is {a.shape}, expected {tuple(shape)}")
    if a.size and float(a.max()) > 1.0 + 1e-6:
        raise ValueError(f"{name} has values up to {float(a.max()):.4g}; expected [0, 1] (divide by 255?)")


def depth(name: str, a, shape: tuple[int, int] | None = None) -> None:
    """``a`` is an (H, W) float depth image in metres (0 = no depth), of ``shape`` when given."""
    a = np.asarray(a)
    if a.ndim != 2 or a.dtype.kind != "f":
        raise ValueError(f"{name} must be an (H, W) float depth in metres, got {_shape(a)}"
                         + (" (16-bit PNG units: divide by the depth scale)" if a.dtype.kind in "ui" else ""))
    if shape is not None and a.shape != tuple(shape):
        raise ValueError(f"{name} is {a.shape}, expected {tuple(shape)} like the image")


def mask(name: str, a, shape: tuple[int, int]) -> None:
    """``a`` is an (H, W) mask of ``shape`` (bool or 0/1)."""
    a = np.asarray(a)
    if a.shape != tuple(shape):
        raise ValueError(f"{name} is {_shape(a)}, expected an (H, W) mask of shape {tuple(shape)}")


def rgb8(name: str, a) -> None:
    """``a`` is an (H, W, 3) uint8 RGB image."""
    a = np.asarray(a)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8:
        raise ValueError(f"{name} must be an (H, W, 3) uint8 RGB image, got {_shape(a)}")


def pose(name: str, T) -> None:
    """``T`` is a finite (4, 4) rigid transform."""
    T = np.asarray(T)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{name} must be a finite (4, 4) pose, got {T.shape}")


def points(name: str, a, n: int | None = None, dim: int = 2) -> None:
    """``a`` is an (N, dim) array (of ``n`` rows when given)."""
    a = np.asarray(a)
    if a.ndim != 2 or a.shape[1] != dim or (n is not None and len(a) != n):
        raise ValueError(f"{name} must be ({n if n is not None else 'N'}, {dim}), got {a.shape}")
