"""OpenCV's RGB-D odometry (``cv2.Odometry``, OpenCV 5.x) as a frame-to-frame peer method.

Notes on OpenCV 5.0's Python binding, measured on TUM fr2/desk:
- ``OdometryAlgoType_COMMON`` returns False on every real frame pair tried here; ``FAST``
  works, so FAST is used.
- The depth given to ``OdometryFrame`` is divided by 5000 internally (the TUM scale), so depth
  is passed in TUM units (metres * 5000) and the returned translation is in metres. Passing
  metres gives translations 5000 times too small.
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

from ..geometry import PinholeCamera

OPENCV_DEPTH_UNITS_PER_M = 5000.0


@dataclass
class OpenCVOdometryConfig:
    """Settings passed to ``cv2.OdometrySettings``.

    Attributes
    ----------
    min_depth_m, max_depth_m : depth range used (metres)
    max_depth_diff_m : ICP correspondence distance (metres)
    max_translation_m, max_rotation_deg : larger frame-to-frame motion = failure
    iterations : iterations per pyramid level (finest first, as OpenCV orders them)
    """

    min_depth_m: float = 0.3
    max_depth_m: float = 6.0
    max_depth_diff_m: float = 0.07
    max_translation_m: float = 0.3
    max_rotation_deg: float = 30.0
    iterations: tuple[int, ...] = (7, 7, 7, 10)


class OpenCVOdometry:
    """Frame-to-frame ``cv2.Odometry`` (RGB_DEPTH, FAST) with TUM-unit depth."""

    def __init__(self, camera: PinholeCamera, config: OpenCVOdometryConfig | None = None):
        self.config = cfg = config or OpenCVOdometryConfig()
        s = cv2.OdometrySettings()
        s.setCameraMatrix(camera.K.astype(np.float32))
        k = OPENCV_DEPTH_UNITS_PER_M
        s.setMinDepth(cfg.min_depth_m * k)  # settings are in the same units as the depth
        s.setMaxDepth(cfg.max_depth_m * k)
        s.setMaxDepthDiff(cfg.max_depth_diff_m * k)
        s.setMaxTranslation(cfg.max_translation_m * k)
        s.setMaxRotation(cfg.max_rotation_deg)
        s.setIterCounts(np.array(cfg.iterations, np.int32).reshape(-1, 1))
        self._odometry = cv2.Odometry(cv2.OdometryType_RGB_DEPTH, s, cv2.OdometryAlgoType_FAST)

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
        k = np.float32(OPENCV_DEPTH_UNITS_PER_M)
        src = cv2.OdometryFrame(depth=depth_ref.astype(np.float32) * k, image=gray_ref)
        dst = cv2.OdometryFrame(depth=depth_cur.astype(np.float32) * k, image=gray_cur)
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
