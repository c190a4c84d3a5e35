"""Method ``static-orb``: the feature frontend with no dynamic handling (our ORB-SLAM2 stand-in).

With ``--masks`` other than ``none`` it drops the keypoints inside the semantic masks and
nothing else: the "masks only" row of paper B's ablation.
"""
from __future__ import annotations

import numpy as np

from ..geometry import invert
from ..masks import NoMasks, union
from ..timing import StageTimer
from .frontend import FeatureTracker, FrontendConfig


class FrontendMethod:
    """Adapter from a :class:`FeatureTracker` to the runner's frame-pair interface.

    The runner calls ``track(ref, cur, ...)``; the frontend sees each frame once, in order, and
    its keyframe-refined poses replace the chained ones at the end (``trajectory``).
    """

    uses_masks = True
    tracker_type = FeatureTracker

    def __init__(self, camera, config, masks=None):
        self.masks = masks or NoMasks()
        self.tracker = self.tracker_type(camera, config)
        self.frames = []  # TrackedFrame per frame, for inspection

    def process(self, frame, timer=None):
        """Track one frame (all frames, in order); ``timer`` collects ms per stage."""
        timer = timer or StageTimer()
        with timer.stage("masks"):
            instances = self.masks(frame)
        tf = self.tracker.process(frame, union(instances), timer)
        self.frames.append(tf)
        return tf

    def track(self, ref, cur, T_init, timer):
        if not self.frames:
            self.process(ref, timer)
        T_ref = self.tracker.T_last
        tf = self.process(cur, timer)
        return self.tracker.T_last @ invert(T_ref), tf.ok, tf.reason

    def trajectory(self) -> np.ndarray:
        return self.tracker.trajectory()

    def extras(self) -> dict:
        return {"keyframes": len(self.tracker.keyframes), "map_points": int(self.tracker.map.alive.sum())}


class StaticORBMethod(FrontendMethod):
    name = "static-orb"
    config_type = FrontendConfig
