"""OpenCV's RGB-D odometry (``cv2.Odometry``, OpenCV 5.x) as a frame-to-frame peer method.

Called as OpenCV's documentation shows it by default: ``OdometryType_RGB_DEPTH`` with
``OdometryAlgoType_COMMON``, depth in metres and the default ``cv2.OdometrySettings`` (the
values of :class:`OpenCVOdometryConfig`). ``algorithm="fast"`` is OpenCV's FAST variant (a
labelled run of the registry, :data:`dynslam_lite.experiments.OPENCV_FAST`). Notes on OpenCV 5.0's Python binding, measured here:

- FAST divides the depth by 5000 internally (the TUM scale): it is given depth and the metric
  settings in TUM units (metres * 5000) and returns metres. Given metres it returns translations
  5000 times too small, and COMMON given TUM units fails on every pair.
- COMMON gives a zero translation, or fails, on pairs whose depth has values beyond
  ``max_depth`` (fr2/desk, up to 10 m: every pair); depth outside [min_depth, max_depth] is
  therefore set to 0 (invalid) before the call, for both algorithms, which is what the settings mean.
- ``compute(src, dst)`` returns ``Rt`` with ``Rt * src = dst``: it maps points of the
  reference (src) camera frame into the current (dst) one, i.e. ``T_cur_ref`` (checked against
  ground truth in the tests).
- With several threads its sums are reduced in a varying order and results differ from run to
  run (ATE on fr2/desk_50 between 3 and 10 cm); one thread makes it repeatable.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import ConfigError
from ..geometry import PinholeCamera

OPENCV_DEPTH_UNITS_PER_M = 5000.0
ALGORITHMS = {"common": cv2.OdometryAlgoType_COMMON, "fast": cv2.OdometryAlgoType_FAST}


@dataclass
class OpenCVOdometryConfig:
    """``cv2.OdometrySettings``; the defaults are OpenCV's own.

    Attributes
    ----------
    algorithm : 'common' (OpenCV's default) or 'fast'
    min_depth_m, max_depth_m : depth range used (metres)
    max_depth_diff_m : ICP correspondence distance (metres)
    max_translation_m, max_rotation_deg : larger frame-to-frame motion = failure
    iterations : iterations per pyramid level (finest first, as OpenCV orders them)
    """

    algorithm: str = "common"
    min_depth_m: float = 0.0
    max_depth_m: float = 4.0
    max_depth_diff_m: float = 0.07
    max_translation_m: float = 0.15
    max_rotation_deg: float = 15.0
    iterations: tuple[int, ...] = (7, 7, 7, 10)


class OpenCVOdometry:
    """Frame-to-frame ``cv2.Odometry`` (RGB_DEPTH; COMMON in metres, or FAST in TUM units)."""

    def __init__(self, camera: PinholeCamera, config: OpenCVOdometryConfig | None = None):
        self.config = cfg = config or OpenCVOdometryConfig()
        if cfg.algorithm not in ALGORITHMS:
            raise ConfigError(f"opencv-odometry algorithm {cfg.algorithm!r}: choose one of {', '.join(ALGORITHMS)}")
        # FAST works in TUM depth units (see the module notes), COMMON in metres
        self.units = OPENCV_DEPTH_UNITS_PER_M if cfg.algorithm == "fast" else 1.0
        s = cv2.OdometrySettings()
        s.setCameraMatrix(camera.K.astype(np.float32))
        k = self.units
        s.setMinDepth(cfg.min_depth_m * k)  # settings are in the same units as the depth
        s.setMaxDepth(cfg.max_depth_m * k)
        s.setMaxDepthDiff(cfg.max_depth_diff_m * k)
        s.setMaxTranslation(cfg.max_translation_m * k)
        s.setMaxRotation(cfg.max_rotation_deg)
        s.setIterCounts(np.array(cfg.iterations, np.int32).reshape(-1, 1))
        self._odometry = cv2.Odometry(cv2.OdometryType_RGB_DEPTH, s, ALGORITHMS[cfg.algorithm])

    def _depth(self, depth: np.ndarray) -> np.ndarray:
        """Depth in OpenCV's units, 0 outside the configured range (see the module notes)."""
        cfg = self.config
        d = depth.astype(np.float32)
        return np.where((d >= cfg.min_depth_m) & (d <= cfg.max_depth_m), d * np.float32(self.units), np.float32(0))

    def align(self, gray_ref, depth_ref, gray_cur, depth_cur) -> tuple[np.ndarray, bool]:
        """Estimate ``T_cur_ref``.

        Parameters
        ----------
        gray_ref, gray_cur : (H, W) uint8
        depth_ref, depth_cur : (H, W) float32 metres, 0 = invalid
        Returns
        -------
        T_cur_ref : (4, 4); ok : bool (False = OpenCV reported failure)
        """
        src = cv2.OdometryFrame(depth=self._depth(depth_ref), image=gray_ref)
        dst = cv2.OdometryFrame(depth=self._depth(depth_cur), image=gray_cur)
        threads = cv2.getNumThreads()
        cv2.setNumThreads(1)  # deterministic reductions
        try:
            self._odometry.prepareFrames(src, dst)
            ok, Rt = self._odometry.compute(src, dst)
        finally:
            cv2.setNumThreads(threads)
        Rt = np.asarray(Rt, float)
        if not ok or not np.all(np.isfinite(Rt)):
            return np.eye(4), False
        return Rt, True
