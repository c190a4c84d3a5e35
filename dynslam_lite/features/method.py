"""Method ``static-orb``: the feature frontend with no dynamic handling (our ORB-SLAM2 stand-in).

With ``--masks`` other than ``none`` it drops the keypoints inside the semantic masks and
nothing else: the "masks only" row of paper B's ablation.
"""
from __future__ import annotations

import numpy as np

from ..geometry import invert
from ..imageops import dilate, union
from ..masks import NoMasks
from ..timing import StageTimer
from ..tracking import Labels, Method, Tracked
from .frontend import FeatureTracker, FrontendConfig, TrackedFrame


class FrontendMethod(Method):
    """Adapter from a :class:`FeatureTracker` to the runner's frame-pair interface.

    The runner calls ``track(ref, cur, ...)``; the frontend sees each frame once, in order
    (:meth:`process`), and its keyframe-refined poses replace the chained ones at the end.
    Subclasses change what the frontend sees with :meth:`prepare` (paper C restores the frame)
    and what a frame reports with :meth:`tracked` (paper B labels its dynamic points).
    """

    uses_masks = True
    tracker_type = FeatureTracker

    def __init__(self, camera, config, masks=None):
        self.masks = masks or NoMasks()
        self.tracker = self.tracker_type(camera, config)
        self.n_frames = 0

    def process(self, frame, timer: StageTimer | None = None) -> Tracked:
        """Track one frame (all frames, in order); ``timer`` collects ms per stage.
        ``T_cur_ref`` of the result is left to :meth:`track`."""
        timer = timer or StageTimer()
        with timer.stage("masks"):  # the source's masks of a frame are kept with it (Frame.derive)
            instances = frame.derive(("masks", self.masks.name), lambda: tuple(self.masks(frame)), timer, "masks")
        seen, exclude, T_trial, record = self.prepare(frame, instances, timer)
        tf = self.tracker.process(seen, exclude, timer, T_init=T_trial, refined=T_trial is not None,
                                  unmapped=self.unmapped(record), keypoints=self.keypoints(record))
        self.n_frames += 1
        return self.tracked(frame, tf, record)

    def prepare(self, frame, instances: list[np.ndarray], timer: StageTimer):
        """(frame the frontend tracks, (H, W) bool keypoint exclusion or None, ``T_trial``,
        record for :meth:`tracked`). ``T_trial``: this frame's pose from a trial that already ran
        the frontend's search and refinement on it (the frontend then searches once, in the narrow
        window), or None (it tracks from its prediction). Here the frame as it is, without
        keypoints in the (dilated) masks, and no trial."""
        people = union(instances)
        return frame, None if people is None else dilate(people, self.tracker.config.mask_dilate_px), None, None

    def unmapped(self, record) -> np.ndarray | None:
        """(H, W) bool, pixels of the frame :meth:`prepare` made rather than measured: keypoints there
        are tracked but never become map points. None here."""
        return None

    def keypoints(self, record):
        """The keypoints of the frame :meth:`prepare` returned, before the exclusion, where it extracted
        them from that very image already (the frontend then does not extract them again), or None."""
        return None

    def tracked(self, frame, tf: TrackedFrame, record) -> Tracked:
        """What the runner gets for ``frame``; the detail is the frontend's :class:`TrackedFrame`,
        the labels a new keyframe's keypoints the screening kept out of the map."""
        return Tracked(np.eye(4), tf.ok, tf.reason, tf.keyframe, self.screened_labels(frame, tf, None), tf)

    @staticmethod
    def screened_labels(frame, tf: TrackedFrame, labels: Labels | None) -> Labels | None:
        """``labels`` with a new keyframe's keypoints the frontend's screening kept out of the
        map ('new', scored on their own positions)."""
        if tf.screened is None:
            return labels
        labels = labels or Labels(frame.index)
        labels.point_uv["new"], labels.points["new"] = tf.screened
        return labels

    def track(self, ref, cur, T_init, timer) -> Tracked:
        if self.tracker.T_last is None:
            self.process(ref, timer)
        T_ref = self.tracker.T_last
        out = self.process(cur, timer)
        out.T_cur_ref = self.tracker.T_last @ invert(T_ref)
        return out

    def refined_trajectory(self) -> np.ndarray:
        return self.tracker.trajectory()

    def extras(self) -> dict:
        return {"keyframes": len(self.tracker.keyframes), "map_points": int(self.tracker.map.alive.sum()),
                "support_reverted": self.tracker.reverted}


class StaticORBMethod(FrontendMethod):
    name = "static-orb"
    config_type = FrontendConfig
