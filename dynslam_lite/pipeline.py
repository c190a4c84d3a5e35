"""Run a method over a sequence: one entry point shared by the CLI, notebooks and tests.

A method (:class:`dynslam_lite.tracking.Method`) tracks frame pairs: ``track(ref, cur, T_init,
timer) -> Tracked``. The runner chains the relative poses into a camera-to-world trajectory
(first frame at the identity), predicts with constant velocity, records failures instead of
crashing, times every stage, scores the method's moving/dynamic verdicts against the ground-truth
masks where the sequence has them, and returns every frame's outputs in :class:`RunResult`.
"""
from __future__ import annotations

import dataclasses
import math
import resource
import time
import typing
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any, Callable, Collection

import numpy as np

from .errors import ConfigError, SequenceError
from .evaluation import MaskScores, confusion
from .geometry import invert, sample_nearest
from .timing import StageTimer
from .io import Frame, RGBDSequence, Trajectory
from .tracking import Labels, Method, Tracked
from .bgrestore import BgRestoreMethod
from .depthcluster import DepthClusterMethod
from .features.method import StaticORBMethod
from .masks import make_mask_source
from .weightedstatic import WeightedStaticMethod
from .odometry.dense import DenseConfig, align
from .odometry.opencv_odometry import OpenCVOdometry, OpenCVOdometryConfig


@dataclass
class FrameOutput:
    """What the runner recorded for one frame.

    Attributes
    ----------
    index, timestamp : the frame
    ok, reason : tracking of the pair ending at this frame (the first frame is always ok)
    keyframe : the frame became a keyframe (keyframe-based methods)
    ms : wall-clock milliseconds of the frame, loading included
    stages : milliseconds per stage
    detail : the method's record of the pair ending here (see :class:`Tracked`), kept only for
        the frames asked for with ``run_method(..., keep=...)``
    """

    index: int
    timestamp: float
    ok: bool = True
    reason: str = ""
    keyframe: bool = False
    ms: float = 0.0
    stages: dict[str, float] = field(default_factory=dict)
    detail: Any = None


@dataclass
class RunResult:
    """What a method produced on a sequence.

    Attributes
    ----------
    method : str
    trajectory : Trajectory, camera-to-world at the colour timestamps
    frames : one :class:`FrameOutput` per frame
    peak_mem_mib : peak resident memory of the process (MiB)
    params : the parameters used
    extras : the method's own statistics (:meth:`Method.extras`)
    scores : the method's verdicts against ground truth, pooled over the frames that have it:
        'pixels/NAME' (moving-pixel masks) and 'points/NAME' (dynamic keypoints), see :class:`Labels`
    scored_points : keypoints scored in the 'points/...' sets judged on ``Labels.uv``
    """

    method: str
    trajectory: Trajectory
    frames: list[FrameOutput] = field(default_factory=list)
    peak_mem_mib: float = 0.0
    params: dict[str, Any] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)
    scores: dict[str, MaskScores] = field(default_factory=dict)
    scored_points: int = 0

    @property
    def failed_frames(self) -> list[tuple[int, str]]:
        """(frame index, reason) of every frame whose tracking failed; its pose is the
        constant-velocity prediction."""
        return [(f.index, f.reason) for f in self.frames if not f.ok]

    @property
    def frame_ms(self) -> list[float]:
        return [f.ms for f in self.frames]

    @property
    def stage_ms(self) -> dict[str, list[float]]:
        """Per stage, milliseconds of every frame that ran it."""
        out: dict[str, list[float]] = defaultdict(list)
        for f in self.frames:
            for k, v in f.stages.items():
                out[k].append(v)
        return dict(out)

    def stats(self) -> dict[str, Any]:
        """JSON-ready summary: frames, failed_frames, ms_per_frame, stages, peak_mem_mib."""
        return {
            "method": self.method,
            "frames": len(self.trajectory),
            "failed_frames": [{"frame": i, "reason": r} for i, r in self.failed_frames],
            "ms_per_frame": float(np.mean(self.frame_ms)) if self.frames else 0.0,
            "stages": {
                k: {"mean_ms": float(np.mean(v)), "median_ms": float(np.median(v))}
                for k, v in self.stage_ms.items()
            },
            "peak_mem_mib": self.peak_mem_mib,
            "params": self.params,
            **({"extras": self.extras} if self.extras else {}),
            **({"scores": {k: dataclasses.asdict(v) for k, v in self.scores.items()}} if self.scores else {}),
        }


class _Scorer:
    """Pools a method's :class:`Labels` against the ground-truth masks of the frames."""

    def __init__(self):
        self.counts: dict[str, np.ndarray] = {}
        self.points = 0

    def add(self, labels: Labels, frame: Frame) -> None:
        if frame.mask is None:
            return
        for name, mask in labels.masks.items():
            self._add(f"pixels/{name}", confusion(mask, frame.mask))
        shared = None  # the truth at the shared keypoints, sampled once
        if labels.uv is not None and any(name not in labels.point_uv for name in labels.points):
            self.points += len(labels.uv)
            shared = sample_nearest(frame.mask, labels.uv)
        for name, dynamic in labels.points.items():
            truth = sample_nearest(frame.mask, labels.point_uv[name]) if name in labels.point_uv else shared
            self._add(f"points/{name}", confusion(dynamic, truth))

    def _add(self, key: str, c: np.ndarray) -> None:
        self.counts[key] = self.counts.get(key, 0) + c

    def scores(self) -> dict[str, MaskScores]:
        return {k: MaskScores.from_counts(*map(int, c)) for k, c in self.counts.items()}


class StaticDense(Method):
    """Method ``static-dense``: the dense solver over all valid pixels, no dynamic handling."""

    name = "static-dense"
    config_type = DenseConfig

    def __init__(self, camera, config: DenseConfig):
        self.camera, self.config = camera, config

    def track(self, ref: Frame, cur: Frame, T_init, timer: StageTimer) -> Tracked:
        with timer.stage("align"):
            r = align(ref.gray.astype(np.float32) / 255.0, ref.depth,
                      cur.gray.astype(np.float32) / 255.0, cur.depth,
                      self.camera, T_init, None, self.config)
        return Tracked(r.T_cur_ref, r.ok, r.reason)


class OpenCVMethod(Method):
    """Method ``opencv-odometry``: ``cv2.Odometry`` RGB-D, frame to frame."""

    name = "opencv-odometry"
    config_type = OpenCVOdometryConfig

    def __init__(self, camera, config: OpenCVOdometryConfig):
        self.odometry = OpenCVOdometry(camera, config)

    def track(self, ref: Frame, cur: Frame, T_init, timer: StageTimer) -> Tracked:
        with timer.stage("align"):
            T, ok = self.odometry.align(ref.gray, ref.depth, cur.gray, cur.depth)
        return Tracked(T, ok, "" if ok else "cv2.Odometry.compute returned False")


METHODS: dict[str, type[Method]] = {
    m.name: m for m in (StaticDense, OpenCVMethod, DepthClusterMethod, StaticORBMethod,
                        WeightedStaticMethod, BgRestoreMethod)
}


def parse_value(text: str) -> Any:
    """A ``--set key=value`` value: int, float, bool, tuple (comma-separated) or string; the
    config field's type decides what is accepted (:func:`make_config`)."""
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


# parameters that count or size something: at least 1; fractions and ratios: at most 1
_AT_LEAST_ONE = {"levels", "n_features", "n_levels", "grid_cols", "grid_rows", "rows", "cols", "keyframes",
                 "frame_gap", "reference_keyframes", "local_map_keyframes", "ba_window", "lm_iterations",
                 "keyframe_max_gap", "max_clusters", "scale_factor", "region_td", "screen_references",
                 "free_space_window"}


def _coerce(key: str, value: Any, hint, default: Any) -> Any:
    """``value`` as the type of the config field ``key`` (``hint``), range-checked, or ConfigError."""
    name = key.rsplit(".", 1)[-1]
    kind = getattr(hint, "__name__", str(hint))

    def bad(expected: str) -> ConfigError:
        return ConfigError(f"--set {key}={value!r}: expected {expected} (default {default!r})")

    if hint is bool:
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if hint in (int, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad(f"a number ({kind})")
        if hint is int and value != int(value):
            raise bad("an integer")
        value = hint(value)
        if not math.isfinite(value) or value < 0:
            raise bad(f"a finite non-negative {kind}")
        if name in _AT_LEAST_ONE and value < 1:
            raise bad(f"a {kind} of at least 1")
        if {"fraction", "ratio"} & set(name.split("_")) and value > 1:  # words: not "iterations"
            raise bad(f"a {kind} between 0 and 1")
        return value
    if typing.get_origin(hint) is tuple:
        items = value if isinstance(value, tuple) else (value,)
        if not items or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in items):
            raise bad("positive integers separated by commas")
        return tuple(items)
    if hint is str:
        return str(value)
    raise bad(kind)


def make_config(config_type, overrides: dict[str, Any] | None):
    """Build a config dataclass from ``overrides`` (``--set`` values), each checked against the
    field's type and range; unknown keys are rejected with the list of known ones.

    Nested configs are reached with dotted keys, e.g. ``dense.lambda_depth=0.5``.
    """
    config = config_type()
    for key, value in (overrides or {}).items():
        obj, parts = config, key.split(".")
        for i, part in enumerate(parts):
            known = {f.name for f in dataclasses.fields(obj)}
            if part not in known:
                raise ConfigError(
                    f"unknown parameter {key!r} for {config_type.__name__}; known at "
                    f"{'.'.join(parts[:i]) or 'top level'}: {', '.join(sorted(known))}"
                )
            if i < len(parts) - 1:
                obj = getattr(obj, part)
                if not dataclasses.is_dataclass(obj):
                    raise ConfigError(f"{'.'.join(parts[:i + 1])} is not a group of parameters")
        hint = typing.get_type_hints(type(obj))[parts[-1]]
        default = getattr(obj, parts[-1])
        if dataclasses.is_dataclass(hint):
            fields = ", ".join(f"{key}.{f.name}" for f in dataclasses.fields(hint))
            raise ConfigError(f"--set {key}={value!r}: {key} is a group of parameters; set one of {fields}")
        setattr(obj, parts[-1], _coerce(key, value, hint, default))
    return config


# a sequence whose depth has fewer valid pixels than this over its first frames (or the whole
# run) cannot be tracked by any method here: stopped with an error instead of a trajectory of guesses
MIN_VALID_DEPTH = 0.01
DEPTH_CHECK_FRAMES = 10


def run_method(
    method: str,
    seq: RGBDSequence,
    params: dict[str, Any] | None = None,
    progress: bool = False,
    masks: str = "none",
    on_frame: Callable[[int], None] | None = None,
    keep: Collection[int] | None = None,
) -> RunResult:
    """Run ``method`` over every frame of ``seq``.

    Parameters
    ----------
    method : a key of :data:`METHODS`
    seq : the sequence (or window) to track
    params : overrides of the method's config fields
    progress : show a tqdm progress bar
    masks : semantic mask source for methods that use one (see :mod:`dynslam_lite.masks`)
    on_frame : called with each frame index after it is tracked
    keep : frame indices whose ``detail`` (the method's record of the pair ending there) is
        kept in ``RunResult.frames``
    """
    steps = track_frames(method, seq, params, masks, keep)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(seq), desc=f"{method} {seq.name}", unit="frame")
    try:
        while True:
            out = next(steps)
            if bar is not None:
                bar.update()
            if on_frame:
                on_frame(out.index)
    except StopIteration as done:
        return done.value
    finally:
        if bar is not None:
            bar.close()


def track_frames(
    method: str,
    seq: RGBDSequence,
    params: dict[str, Any] | None = None,
    masks: str = "none",
    keep: Collection[int] | None = None,
) -> typing.Generator[FrameOutput, None, RunResult]:
    """:func:`run_method` one frame at a time: yields each frame's :class:`FrameOutput` as it is
    tracked and returns the :class:`RunResult` (``StopIteration.value``). ``bench`` steps several
    methods frame by frame in turn, so that each frame's times of all methods are taken in the
    same second of a shared machine. The method and its parameters are checked here, before the
    first frame is asked for."""
    if method not in METHODS:
        raise ConfigError(f"unknown method {method!r}: choose one of {', '.join(sorted(METHODS))}")
    if len(seq) < 2:
        raise SequenceError(f"{seq.root}: {len(seq)} frame(s): tracking needs at least 2")
    cls = METHODS[method]
    config = make_config(cls.config_type, params)
    if cls.uses_masks:
        tracker = cls(seq.camera, config, make_mask_source(masks))
    elif masks != "none":
        raise ConfigError(f"method {method!r} does not use semantic masks (got --masks {masks})")
    else:
        tracker = cls(seq.camera, config)
    return _track(method, seq, tracker, config, masks, set(keep or ()))


def _track(method: str, seq: RGBDSequence, tracker: Method, config, masks: str,
           keep: set[int]) -> typing.Generator[FrameOutput, None, RunResult]:
    """The frame loop of :func:`track_frames`."""
    poses = [np.eye(4)]
    frames: list[FrameOutput] = []
    scorer = _Scorer()
    velocity = np.eye(4)  # T_cur_ref of the last frame pair
    ref = None
    valid_depth = 0.0  # sum over frames of the valid-depth fraction
    for i in range(len(seq)):
        timer = StageTimer()
        t0 = time.perf_counter()
        with timer.stage("load"):
            cur = seq[i]
        valid_depth += np.count_nonzero(cur.depth) / cur.depth.size
        if i + 1 in (min(DEPTH_CHECK_FRAMES, len(seq)), len(seq)) and valid_depth / (i + 1) < MIN_VALID_DEPTH:
            raise SequenceError(f"{seq.depth_files[i].parent}: {100 * valid_depth / (i + 1):.2f} % of the depth "
                                f"pixels of frames 0-{i} are valid (need {100 * MIN_VALID_DEPTH:g} %): no usable depth")
        out = FrameOutput(i, float(seq.timestamps[i]))
        if ref is not None:
            tr = tracker.track(ref, cur, velocity, timer)
            T = tr.T_cur_ref
            if not tr.ok:
                out.ok, out.reason = False, tr.reason
                T = velocity  # constant-velocity prediction keeps the trajectory going
            velocity = T
            poses.append(poses[-1] @ invert(T))
            out.keyframe = tr.keyframe
            if tr.labels is not None:
                scorer.add(tr.labels, ref if tr.labels.frame == ref.index else cur)
            if i in keep:
                out.detail = tr.detail
        ref = cur
        out.ms = (time.perf_counter() - t0) * 1000.0
        out.stages = dict(timer.frame)
        frames.append(out)
        yield out
    refined = tracker.refined_trajectory()
    if refined is not None:  # keyframe-based: final poses after bundle adjustment
        poses = list(refined)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux
    return RunResult(
        method, Trajectory(seq.timestamps.copy(), np.stack(poses)), frames, peak,
        {**dataclasses.asdict(config), **({"masks": masks} if masks != "none" else {})},
        tracker.extras(), scorer.scores(), scorer.points,
    )
