"""Semantic mask sources: per frame, instance masks of the dynamic classes (people).

Papers B and C take instance masks from a segmentation network (YOLOv5s-seg, Mask R-CNN). Here
a source is chosen by a spec string (``--masks`` on the command line, ``masks`` in notebooks):

* ``none`` — no masks;
* ``oracle`` — the synthetic ground truth of the person class (what a person detector gives,
  the papers' dynamic class), moving or standing still, split into instances (connected
  components); ``oracle:degraded`` imitates a real network: dilated or eroded outlines, dropped
  frames, false blobs (deterministic per seed and frame); ``oracle:missed`` the ground truth
  except that every person covering more than 5 % of the image is missed in 12 frames of every 36
  (frames 24-35, 60-71, ...: a detector losing the people close to the camera, cut by the image
  border or blurred, for a while); ``oracle:all`` — every object instance
  of the synthetic ground truth, people, carried and pushed objects and furniture alike (what an
  instance segmenter such as paper C's Mask R-CNN gives); ``oracle:moving`` — the ground truth
  of every object that moves in the frame, whatever its class (no method can know this: the run
  with it bounds what any handling of moving objects can reach on a scene);
* ``files:DIR`` — PNG masks computed elsewhere (e.g. YOLOv5-seg or Mask R-CNN run on your
  machine), one per colour frame, named by its timestamp as in TUM's ``rgb/`` folder
  (``1311868164.363181.png``; the nearest within 0.02 s is used). 8- or 16-bit, 0 = background,
  each instance a distinct non-zero value; a 0/255 binary mask is split into connected
  components. A frame without a file has no masks;
* ``person`` — the bundled MediaPipe Selfie Segmentation model run with OpenCV
  (:mod:`dynslam_lite.segmentation`), a stand-in for the papers' networks; ``person:landscape``
  uses its 256x144 variant; ``person:missed`` (``person:landscape:missed``) the model's masks with
  the near people missed as ``oracle:missed`` misses them (real data: the detector's failure
  where people crowd, on a clip with true poses);
* ``onnx:PATH`` — a YOLOv5-seg / YOLOv8-seg ONNX export of your own, person class only.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .errors import ConfigError
from .imageops import disk, split_instances
from .io import Frame, SequenceError


class NoMasks:
    name = "none"

    def __call__(self, frame: Frame) -> list[np.ndarray]:
        return []


@dataclass
class Degradation:
    """How ``oracle:degraded`` spoils the ground truth, per instance and frame (and which frames
    ``oracle:missed`` and ``person:missed`` miss the near people in, :class:`NearMissed`).

    Attributes
    ----------
    max_dilate_px, max_erode_px : each instance dilated or eroded by a random radius up to these
    drop_rate : probability that an instance is missed in a frame
    false_blob_rate : probability of a false elliptic blob in a frame
    seed : of the random draws (with the frame index)
    near_fraction, near_miss_frames, near_miss_period (:class:`NearMissed`) : instances covering
        more than ``near_fraction`` of the image are missed in the last ``near_miss_frames`` frames
        of every ``near_miss_period`` (0 frames: never)
    """

    max_dilate_px: int = 6
    max_erode_px: int = 4
    drop_rate: float = 0.1
    false_blob_rate: float = 0.1
    seed: int = 0
    near_fraction: float = 0.05
    near_miss_frames: int = 0
    near_miss_period: int = 36

    def misses_near(self, index: int) -> bool:
        """Whether frame ``index`` loses the instances covering more than ``near_fraction``."""
        return bool(self.near_miss_frames) and index % self.near_miss_period >= self.near_miss_period - self.near_miss_frames

    def near_miss_ranges(self, n_frames: int) -> list[tuple[int, int]]:
        """(first, last) frame of every run of frames in ``range(n_frames)`` that misses the near instances."""
        runs: list[list[int]] = []
        for i in filter(self.misses_near, range(n_frames)):
            if runs and runs[-1][1] == i - 1:
                runs[-1][1] = i
            else:
                runs.append([i, i])
        return [(a, b) for a, b in runs]


MISSED = Degradation(max_dilate_px=0, max_erode_px=0, drop_rate=0.0, false_blob_rate=0.0,
                     near_miss_frames=12)  # oracle:missed


class OracleMasks:
    """Ground-truth person masks of a synthetic sequence, optionally degraded."""

    def __init__(self, degradation: Degradation | None = None, name: str | None = None):
        self.degradation = degradation
        self.name = name or ("oracle:degraded" if degradation else "oracle")

    def __call__(self, frame: Frame) -> list[np.ndarray]:
        if frame.mask is None:
            raise SequenceError("masks 'oracle' need ground-truth masks (masks/ of a synthetic "
                                f"sequence); frame {frame.index} has none")
        if frame.instances is not None:  # the person class, moving or not
            people = [k for k, c in frame.classes.items() if c == "person"]
            inst = split_instances(np.isin(frame.instances, people))
        else:  # sequences written before instances: every moving object was a person
            inst = split_instances(frame.mask)
        d = self.degradation
        if d is None:
            return inst
        rng = np.random.default_rng([d.seed, frame.index])
        out = []
        for m in inst:
            if rng.random() < d.drop_rate:
                continue
            k = int(rng.integers(-d.max_erode_px, d.max_dilate_px + 1))
            op = cv2.dilate if k > 0 else cv2.erode
            m = op(m.astype(np.uint8), disk(abs(k))).astype(bool) if k else m
            if m.any():
                out.append(m)
        if rng.random() < d.false_blob_rate:
            H, W = frame.mask.shape
            blob = np.zeros((H, W), np.uint8)
            c = (int(rng.integers(0, W)), int(rng.integers(0, H)))
            cv2.ellipse(blob, c, (int(rng.integers(15, 60)), int(rng.integers(15, 60))), 0, 0, 360, 1, -1)
            out.append(blob.astype(bool))
        return out


class NearMissed:
    """Another source's masks, with every instance covering more than ``near_fraction`` of the
    image dropped in the frames ``degradation.misses_near`` names (``oracle:missed``,
    ``person:missed``): a detector losing the people close to the camera for a while."""

    def __init__(self, inner, degradation: Degradation, name: str):
        self.inner, self.degradation, self.name = inner, degradation, name

    def __call__(self, frame: Frame) -> list[np.ndarray]:
        inst = self.inner(frame)
        if self.degradation.misses_near(frame.index):
            inst = [m for m in inst if m.mean() <= self.degradation.near_fraction]
        return inst


class AllObjectMasks:
    """Every ground-truth object instance of a synthetic sequence (``oracle:all``), each one
    instance whatever its class; at least ``min_area`` pixels."""

    name = "oracle:all"

    def __init__(self, min_area: int = 50):
        self.min_area = min_area

    def __call__(self, frame: Frame) -> list[np.ndarray]:
        if frame.instances is None:
            raise SequenceError("masks 'oracle:all' need ground-truth instances (instances/ of a "
                                f"synthetic sequence); frame {frame.index} has none")
        ids, counts = np.unique(frame.instances, return_counts=True)
        return [frame.instances == k for k, n in zip(ids, counts) if k and n >= self.min_area]


class MovingMasks:
    """The ground-truth masks of the objects moving in each frame (``oracle:moving``), one
    instance per object where the sequence has instances, else connected components."""

    name = "oracle:moving"

    def __call__(self, frame: Frame) -> list[np.ndarray]:
        if frame.mask is None:
            raise SequenceError("masks 'oracle:moving' need ground-truth masks (masks/ of a synthetic "
                                f"sequence); frame {frame.index} has none")
        if frame.instances is None:
            return split_instances(frame.mask)
        ids = np.unique(frame.instances[frame.mask])
        rest = frame.mask & (frame.instances == 0)  # moving pixels of no instance, if any
        return [(frame.instances == k) & frame.mask for k in ids if k] + (split_instances(rest) if rest.any() else [])


class FileMasks:
    """Instance masks from PNG files named by timestamp (see the module docstring)."""

    def __init__(self, folder: str | Path, max_dt: float = 0.02):
        self.folder = Path(folder)
        self.name = f"files:{folder}"
        if not self.folder.is_dir():
            raise SequenceError(f"{self.folder}: mask folder not found")
        files = sorted(self.folder.glob("*.png"))
        stamps = []
        for f in files:
            try:
                stamps.append(float(f.stem))
            except ValueError:
                raise SequenceError(f"{f}: mask file name is not a timestamp (expected e.g. "
                                    "1311868164.363181.png)") from None
        if not files:
            raise SequenceError(f"{self.folder}: no PNG masks in the folder")
        order = np.argsort(stamps)
        self.stamps = np.asarray(stamps)[order]
        self.files = [files[i] for i in order]
        self.max_dt = max_dt

    def __call__(self, frame: Frame) -> list[np.ndarray]:
        j = int(np.argmin(np.abs(self.stamps - frame.timestamp)))
        if abs(self.stamps[j] - frame.timestamp) > self.max_dt:
            return []
        path = self.files[j]
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise SequenceError(f"{path}: unreadable PNG mask")
        if img.ndim == 3:
            raise SequenceError(f"{path}: mask must be single-channel (instance ids), got {img.shape[2]} channels")
        if img.shape != frame.depth.shape:
            raise SequenceError(f"{path}: mask is {img.shape[1]}x{img.shape[0]}, frame is "
                                f"{frame.depth.shape[1]}x{frame.depth.shape[0]}")
        ids = np.unique(img[img > 0])
        if ids.size == 1 and ids[0] == 255:  # binary: split into components
            return split_instances(img > 0)
        return [img == i for i in ids]


SOURCES = ("none, oracle, oracle:degraded, oracle:missed, oracle:all, oracle:moving, files:DIR, person, "
           "person:landscape, person:missed, person:landscape:missed or onnx:PATH")


def make_mask_source(spec: str):
    """A mask source from its spec (see the module docstring)."""
    kind, _, arg = spec.partition(":")
    if kind == "none" and not arg:
        return NoMasks()
    if kind == "oracle" and arg in ("", "degraded"):
        return OracleMasks(Degradation() if arg else None)
    if spec.endswith(":missed") and spec[: -len(":missed")] in ("oracle", "person", "person:landscape"):
        return NearMissed(make_mask_source(spec[: -len(":missed")]), MISSED, spec)
    if kind == "oracle" and arg == "all":
        return AllObjectMasks()
    if kind == "oracle" and arg == "moving":
        return MovingMasks()
    if kind == "files" and arg:
        return FileMasks(arg)
    if kind == "person" and arg in ("", "square", "landscape"):
        from .segmentation import PersonMasks
        return PersonMasks(arg or "square")
    if kind == "onnx" and arg:
        from .segmentation import YoloSegMasks
        return YoloSegMasks(arg)
    raise ConfigError(f"unknown mask source {spec!r}: use {SOURCES}")
