"""ORB features for the RGB-D frontend: spread over the image, with depth and the virtual right
coordinate of ORB-SLAM2's RGB-D mode.

References: Mur-Artal & Tardos, ORB-SLAM2 (2017), sec. III-A (stereo/RGB-D keypoints
``(u_L, v_L, u_R)`` with ``u_R = u_L - b_f / d``).
"""
from __future__ import annotations

from dataclasses import astuple, dataclass

import cv2
import numpy as np

from ..geometry import sample_nearest


@dataclass
class ORBConfig:
    """ORB extraction (ORB-SLAM2's TUM settings where they exist).

    Attributes
    ----------
    n_features : keypoints kept per frame
    scale_factor, n_levels : image pyramid of the detector
    fast_threshold : FAST corner threshold (grey levels)
    grid_cols, grid_rows : the image is cut into these cells; each keeps its best
        ``n_features / cells`` corners first, so features spread over the image
    min_depth_m, max_depth_m : depth outside this range counts as no depth
    """

    n_features: int = 1000
    scale_factor: float = 1.2
    n_levels: int = 8
    fast_threshold: int = 20
    grid_cols: int = 8
    grid_rows: int = 6
    min_depth_m: float = 0.1
    max_depth_m: float = 8.0


@dataclass
class Features:
    """Keypoints of one frame.

    Attributes
    ----------
    uv : (N, 2) float64, pixel coordinates (column, row)
    octave : (N,) int, pyramid level of detection
    desc : (N, 32) uint8, ORB descriptors
    z : (N,) float64, depth at the keypoint in metres, 0 = none
    response : (N,) float64, corner strength
    """

    uv: np.ndarray
    octave: np.ndarray
    desc: np.ndarray
    z: np.ndarray
    response: np.ndarray

    def __len__(self) -> int:
        return len(self.uv)

    def subset(self, keep: np.ndarray) -> "Features":
        return Features(self.uv[keep], self.octave[keep], self.desc[keep], self.z[keep],
                        self.response[keep])

    def outside(self, mask: np.ndarray | None) -> "Features":
        """The keypoints not on ``mask`` ((H, W) bool, e.g. a semantic mask); all when None."""
        return self if mask is None else self.subset(~sample_nearest(mask, self.uv))

    def inv_sigma2(self, scale_factor: float) -> np.ndarray:
        """(N,) information of a keypoint: 1 / (scale_factor ** octave) ** 2 (ORB-SLAM2)."""
        return scale_factor ** (-2.0 * self.octave)


def _spread(uv: np.ndarray, response: np.ndarray, n: int, shape: tuple[int, int], cols: int, rows: int) -> np.ndarray:
    """Indices of ``n`` keypoints: the best of each grid cell first, then the best remaining."""
    H, W = shape
    cell = (np.minimum(uv[:, 1] * rows // H, rows - 1) * cols
            + np.minimum(uv[:, 0] * cols // W, cols - 1)).astype(int)
    order = np.lexsort((-response, cell))  # by cell, strongest first within a cell
    sorted_cell = cell[order]
    first = np.searchsorted(sorted_cell, sorted_cell, side="left")
    rank = np.empty(len(uv), int)
    rank[order] = np.arange(len(uv)) - first  # rank of each keypoint inside its cell
    # sort by (rank within cell, -response): one per cell, then two per cell, ...
    priority = np.lexsort((-response, rank))
    return np.sort(priority[:n])


def extract(gray: np.ndarray, depth: np.ndarray, config: ORBConfig | None = None,
            exclude: np.ndarray | None = None) -> Features:
    """ORB keypoints and descriptors, spread over the image, with their depth.

    Parameters
    ----------
    gray : (H, W) uint8
    depth : (H, W) float32, metres, 0 = invalid
    config : see :class:`ORBConfig`
    exclude : (H, W) bool or None, keypoints inside are dropped after extraction (semantic
        masks: paper B's "semantic static points" are those outside)
    """
    cfg = config or ORBConfig()
    if gray.ndim != 2 or gray.dtype != np.uint8:
        raise ValueError(f"gray must be (H, W) uint8, got {gray.shape} {gray.dtype}")
    if depth.shape != gray.shape:
        raise ValueError(f"depth {depth.shape} and image {gray.shape} differ in size")
    orb = cv2.ORB_create(nfeatures=2 * cfg.n_features, scaleFactor=cfg.scale_factor,
                         nlevels=cfg.n_levels, fastThreshold=cfg.fast_threshold)
    kps, desc = orb.detectAndCompute(gray, None)
    if not kps:
        return Features(np.zeros((0, 2)), np.zeros(0, int), np.zeros((0, 32), np.uint8),
                        np.zeros(0), np.zeros(0))
    uv = np.array([k.pt for k in kps], float)
    response = np.array([k.response for k in kps], float)
    octave = np.array([k.octave for k in kps], int)
    keep = _spread(uv, response, cfg.n_features, gray.shape, cfg.grid_cols, cfg.grid_rows)
    uv, response, octave, desc = uv[keep], response[keep], octave[keep], desc[keep]
    z = sample_nearest(depth, uv).astype(float)
    z[(z < cfg.min_depth_m) | (z > cfg.max_depth_m)] = 0.0
    return Features(uv, octave, desc, z, response).outside(exclude)


def frame_keypoints(frame, config: ORBConfig | None = None, timer=None, stage: str = "orb") -> Features:
    """:func:`extract` of a :class:`~dynslam_lite.io.Frame` without a mask, made once per frame
    where the frame keeps it (:meth:`~dynslam_lite.io.Frame.derive`: the batch's runs of a
    sequence share it); ``timer`` (a :class:`~dynslam_lite.timing.StageTimer`) is charged the
    extraction's time under ``stage`` when it was kept. The arrays are read-only."""
    cfg = config or ORBConfig()
    return frame.derive(("orb", astuple(cfg)), lambda: extract(frame.gray, frame.depth, cfg), timer, stage)
