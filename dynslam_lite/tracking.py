"""The interface between a method and the runner (:func:`dynslam_lite.pipeline.run_method`).

A method tracks frame pairs in order: ``track(ref, cur, T_init, timer) -> Tracked``. What it
returns per pair is typed here: the relative pose, whether it can be trusted, and optionally its
moving/dynamic verdicts (:class:`Labels`, which the runner scores against ground truth: methods
never see the truth) and a method-specific record of the frame (``detail``, kept by the runner
for the frames a notebook or test asks for).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from .io import Frame
from .timing import StageTimer


@dataclass
class Labels:
    """A method's moving / dynamic verdicts on one frame.

    Attributes
    ----------
    frame : index of the frame they refer to (the reference or the current frame of the pair)
    masks : name -> (H, W) bool, pixels judged moving
    uv : (N, 2) float pixel positions of the keypoints judged in ``points``, or None
    points : name -> (N,) bool, keypoints judged dynamic
    point_uv : name -> (M, 2) positions of a set of ``points`` judged on other keypoints than ``uv``
    """

    frame: int
    masks: dict[str, np.ndarray] = field(default_factory=dict)
    uv: np.ndarray | None = None
    points: dict[str, np.ndarray] = field(default_factory=dict)
    point_uv: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class Tracked:
    """One frame pair tracked.

    Attributes
    ----------
    T_cur_ref : (4, 4) pose of the reference camera in the current camera (x_cur = T x_ref)
    ok, reason : whether the estimate can be trusted; why not
    keyframe : the current frame became a keyframe (keyframe-based methods)
    labels : moving / dynamic verdicts, scored by the runner on data with ground truth
    detail : a method-specific record of the pair (e.g. paper C's restoration)
    """

    T_cur_ref: np.ndarray
    ok: bool = True
    reason: str = ""
    keyframe: bool = False
    labels: Labels | None = None
    detail: Any = None


class Method:
    """Base of every method. Subclasses set ``name`` and ``config_type`` and implement
    :meth:`track`; ``uses_masks`` methods are built with a semantic mask source as third argument.
    """

    name: ClassVar[str]
    config_type: ClassVar[type]
    uses_masks: ClassVar[bool] = False

    def track(self, ref: Frame, cur: Frame, T_init: np.ndarray, timer: StageTimer) -> Tracked:
        """Pose of ``cur`` relative to ``ref`` (consecutive frames, in order), starting at
        ``T_init`` (the constant-velocity prediction of ``T_cur_ref``)."""
        raise NotImplementedError

    def refined_trajectory(self) -> np.ndarray | None:
        """(N, 4, 4) camera-to-world poses refined after tracking (keyframe methods), or None
        to keep the chained frame-to-frame poses."""
        return None

    def extras(self) -> dict[str, Any]:
        """Method-specific statistics of the run (JSON-ready), e.g. keyframe counts."""
        return {}
