"""Run a method over a sequence: one entry point shared by the CLI, notebooks and tests.

A method is a frame-to-frame tracker: ``track(ref, cur, T_init, timer) -> (T_cur_ref, ok,
reason)``. The runner chains the relative poses into a camera-to-world trajectory (first frame
at the identity), predicts with constant velocity, records failures instead of crashing, and
times every stage.
"""
from __future__ import annotations

import dataclasses
import resource
import time
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .geometry import invert
from .timing import StageTimer
from .io import Frame, RGBDSequence, Trajectory
from .bgrestore import BgRestoreMethod
from .depthcluster import DepthClusterMethod
from .features.method import StaticORBMethod
from .masks import make_mask_source
from .weightedstatic import WeightedStaticMethod
from .odometry.dense import DenseConfig, align
from .odometry.opencv_odometry import OpenCVOdometry, OpenCVOdometryConfig


@dataclass
class RunResult:
    """What a method produced on a sequence.

    Attributes
    ----------
    method : str
    trajectory : Trajectory, camera-to-world at the colour timestamps
    failed_frames : list of (frame index, reason): frames whose tracking failed; their pose
        is the constant-velocity prediction
    stage_ms : per stage, milliseconds of every frame
    frame_ms : (N,) milliseconds per frame, whole pipeline (loading included)
    peak_mem_mib : peak resident memory of the process (MiB)
    params : the parameters used
    """

    method: str
    trajectory: Trajectory
    failed_frames: list[tuple[int, str]] = field(default_factory=list)
    stage_ms: dict[str, list[float]] = field(default_factory=dict)
    frame_ms: list[float] = field(default_factory=list)
    peak_mem_mib: float = 0.0
    params: dict[str, Any] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)

    def stats(self) -> dict[str, Any]:
        """JSON-ready summary: frames, failed_frames, ms_per_frame, stages, peak_mem_mib."""
        return {
            "method": self.method,
            "frames": len(self.trajectory),
            "failed_frames": [{"frame": i, "reason": r} for i, r in self.failed_frames],
            "ms_per_frame": float(np.mean(self.frame_ms)) if self.frame_ms else 0.0,
            "stages": {
                k: {"mean_ms": float(np.mean(v)), "median_ms": float(np.median(v))}
                for k, v in self.stage_ms.items()
            },
            "peak_mem_mib": self.peak_mem_mib,
            "params": self.params,
            **({"extras": self.extras} if self.extras else {}),
        }


class StaticDense:
    """Method ``static-dense``: the dense solver over all valid pixels, no dynamic handling."""

    name = "static-dense"
    config_type = DenseConfig

    def __init__(self, camera, config: DenseConfig):
        self.camera, self.config = camera, config

    def track(self, ref: Frame, cur: Frame, T_init, timer: StageTimer):
        with timer.stage("align"):
            r = align(ref.gray.astype(np.float32) / 255.0, ref.depth,
                      cur.gray.astype(np.float32) / 255.0, cur.depth,
                      self.camera, T_init, None, self.config)
        return r.T_cur_ref, r.ok, r.reason


class OpenCVMethod:
    """Method ``opencv-odometry``: ``cv2.Odometry`` RGB-D, frame to frame."""

    name = "opencv-odometry"
    config_type = OpenCVOdometryConfig

    def __init__(self, camera, config: OpenCVOdometryConfig):
        self.odometry = OpenCVOdometry(camera, config)

    def track(self, ref: Frame, cur: Frame, T_init, timer: StageTimer):
        with timer.stage("align"):
            T, ok = self.odometry.align(ref.gray, ref.depth, cur.gray, cur.depth)
        return T, ok, "" if ok else "cv2.Odometry.compute returned False"


METHODS: dict[str, type] = {
    m.name: m for m in (StaticDense, OpenCVMethod, DepthClusterMethod, StaticORBMethod,
                        WeightedStaticMethod, BgRestoreMethod)
}


def parse_value(text: str) -> Any:
    """A ``--set key=value`` value: int, float, bool, tuple (comma-separated) or string."""
    if "," in text:
        return tuple(parse_value(t) for t in text.split(",") if t)
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return text


def make_config(config_type, overrides: dict[str, Any] | None):
    """Build a config dataclass, rejecting unknown keys with the list of known ones.

    Nested configs are reached with dotted keys, e.g. ``dense.lambda_depth=0.5``.
    """
    config = config_type()
    for key, value in (overrides or {}).items():
        obj, parts = config, key.split(".")
        for i, part in enumerate(parts):
            known = {f.name for f in dataclasses.fields(obj)}
            if part not in known:
                raise ValueError(
                    f"unknown parameter {key!r} for {config_type.__name__}; known at "
                    f"{'.'.join(parts[:i]) or 'top level'}: {', '.join(sorted(known))}"
                )
            if i < len(parts) - 1:
                obj = getattr(obj, part)
                if not dataclasses.is_dataclass(obj):
                    raise ValueError(f"{'.'.join(parts[:i + 1])} is not a group of parameters")
        setattr(obj, parts[-1], value)
    return config


def run_method(
    method: str,
    seq: RGBDSequence,
    params: dict[str, Any] | None = None,
    progress: bool = False,
    masks: str = "none",
    on_frame: Callable[[int], None] | None = None,
) -> RunResult:
    """Run ``method`` over every frame of ``seq``.

    Parameters
    ----------
    method : a key of :data:`METHODS`
    seq : the sequence (or window) to track
    params : overrides of the method's config fields
    progress : show a tqdm progress bar
    masks : semantic mask source for methods that use one (see :mod:`dynslam_lite.masks`)
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}: choose one of {', '.join(sorted(METHODS))}")
    if len(seq) == 0:
        raise ValueError(f"{seq.root}: empty sequence, nothing to track")
    cls = METHODS[method]
    config = make_config(cls.config_type, params)
    if getattr(cls, "uses_masks", False):
        tracker = cls(seq.camera, config, make_mask_source(masks))
    elif masks != "none":
        raise ValueError(f"method {method!r} does not use semantic masks (got --masks {masks})")
    else:
        tracker = cls(seq.camera, config)
    poses = [np.eye(4)]
    failed: list[tuple[int, str]] = []
    stage_ms: dict[str, list[float]] = defaultdict(list)
    frame_ms: list[float] = []
    velocity = np.eye(4)  # T_cur_ref of the last frame pair
    iterator = range(len(seq))
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc=f"{method} {seq.name}", unit="frame")
    ref = None
    for i in iterator:
        timer = StageTimer()
        t0 = time.perf_counter()
        with timer.stage("load"):
            cur = seq[i]
        if ref is not None:
            T, ok, reason = tracker.track(ref, cur, velocity, timer)
            if not ok:
                failed.append((i, reason))
                T = velocity  # constant-velocity prediction keeps the trajectory going
            velocity = T
            poses.append(poses[-1] @ invert(T))
        ref = cur
        frame_ms.append((time.perf_counter() - t0) * 1000.0)
        for k, v in timer.frame.items():
            stage_ms[k].append(v)
        if on_frame:
            on_frame(i)
    if hasattr(tracker, "trajectory"):  # keyframe-based: final poses after bundle adjustment
        poses = list(tracker.trajectory())
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux
    extras = tracker.extras() if hasattr(tracker, "extras") else {}
    return RunResult(
        method, Trajectory(seq.timestamps.copy(), np.stack(poses)), failed, dict(stage_ms),
        frame_ms, peak, {**dataclasses.asdict(config), **({"masks": masks} if masks != "none" else {})},
        extras,
    )
