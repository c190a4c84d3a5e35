"""Reading TUM RGB-D / Bonn RGB-D Dynamic sequences and writing trajectories.

Layout read (as downloaded): ``rgb.txt``, ``depth.txt``, ``groundtruth.txt`` (optional),
``rgb/*.png`` (8-bit colour), ``depth/*.png`` (16-bit, ``depth_scale`` units per metre,
0 = no depth). Sequences written by :mod:`dynslam_lite.synth` add ``camera.txt``,
``masks.txt`` + ``masks/`` (ground-truth moving-object masks) and optionally ``background/``.

Every problem with the input raises :class:`SequenceError` naming the file and the problem.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np

from .errors import SequenceError
from .geometry import PinholeCamera

# Intrinsics of the public datasets (pinhole, no undistortion), see ../shared/data/README.md.
CAMERA_PRESETS: dict[str, PinholeCamera] = {
    "fr1": PinholeCamera(517.3, 516.5, 318.6, 255.3, name="fr1"),
    "fr2": PinholeCamera(520.9, 521.0, 325.1, 249.7, name="fr2"),
    "fr3": PinholeCamera(535.4, 539.2, 320.1, 247.6, name="fr3"),
    "bonn": PinholeCamera(542.822841, 542.576870, 315.593520, 237.756098, name="bonn"),
}

# Bonn RGB-D Dynamic: the mocap pose Q is of a marker on the sensor; camera pose C = Q T_ros T_m.
BONN_T_ROS = np.array([[-1.0, 0, 0, 0], [0, 0, 1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
BONN_T_M_RAW = np.array(
    [
        [1.0157, 0.1828, -0.2389, 0.0113],
        [0.0009, -0.8431, -0.6413, -0.0098],
        [-0.3009, 0.6147, -0.8085, 0.0111],
        [0, 0, 0, 1],
    ]
)


def bonn_marker_to_camera() -> np.ndarray:
    """(4, 4) ``T_ros @ T_m`` with T_m's 3x3 block replaced by its nearest rotation.

    The published calibration block carries a uniform scale of about 1.059; the nearest
    rotation is ``U V^T`` from its SVD.
    """
    U, _, Vt = np.linalg.svd(BONN_T_M_RAW[:3, :3])
    T_m = BONN_T_M_RAW.copy()
    T_m[:3, :3] = U @ Vt
    return BONN_T_ROS @ T_m


# --------------------------------------------------------------------------- text files


def read_file_list(path: str | Path, min_columns: int = 2) -> list[tuple[float, list[str]]]:
    """Read a TUM text list: ``timestamp value...`` per line, ``#`` comments.

    Tolerates the known header quirk of some TUM files (a header line without ``#``, such as
    ``timestamp tx ty tz qx qy qz qw``) as long as it comes before the first data line.

    Returns
    -------
    list of (timestamp seconds, remaining columns), in file order; timestamps strictly increase.
    Raises
    ------
    SequenceError : missing file, malformed line, too few columns, unsorted or repeated timestamps.
    """
    path = Path(path)
    if not path.is_file():
        raise SequenceError(f"{path}: file not found")
    return parse_file_list(_read_text(path).splitlines(), path, min_columns)


def _read_text(path: Path) -> str:
    """A text list as UTF-8 (ASCII in practice); other encodings are named in the error."""
    raw = path.read_bytes()
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in raw[:4096]:
        raise SequenceError(f"{path}: not a UTF-8 text file (UTF-16, judging by its bytes); "
                            "save it as UTF-8 / ASCII as the TUM tools write it")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise SequenceError(f"{path}: not a UTF-8 text file (byte {exc.start}: {exc.reason})") from None


def parse_file_list(lines, name, min_columns: int = 2) -> list[tuple[float, list[str]]]:
    """:func:`read_file_list` on the lines of a text; ``name`` names it in errors."""
    entries: list[tuple[float, list[str]]] = []
    for lineno, raw in enumerate(lines, start=1):
        line = raw.replace(",", " ").replace("\t", " ").strip()
        if not line or line.startswith("#"):
            continue
        cols = line.split()
        try:
            stamp = float(cols[0])
        except ValueError:
            if not entries and not any(c[0].isdigit() for c in cols):
                continue  # header line without '#', e.g. TUM fr1/xyz groundtruth.txt
            raise SequenceError(
                f"{name}:{lineno}: expected a timestamp in seconds, got {cols[0]!r}"
            ) from None
        if not math.isfinite(stamp):
            raise SequenceError(f"{name}:{lineno}: timestamp {cols[0]!r} is not a finite number")
        if len(cols) < min_columns:
            raise SequenceError(
                f"{name}:{lineno}: expected at least {min_columns} columns, got {len(cols)}"
            )
        if entries and stamp == entries[-1][0]:
            raise SequenceError(f"{name}:{lineno}: timestamp {stamp:.6f} repeated from the line "
                                "before; every line of a TUM list has its own time")
        if entries and stamp < entries[-1][0]:
            raise SequenceError(
                f"{name}:{lineno}: timestamps not increasing ({stamp:.6f} after "
                f"{entries[-1][0]:.6f}); TUM lists are sorted by time"
            )
        entries.append((stamp, cols[1:]))
    return entries


def associate(
    stamps_a: np.ndarray, stamps_b: np.ndarray, max_difference: float = 0.02, offset: float = 0.0
) -> list[tuple[int, int]]:
    """Associate two timestamp lists as TUM's ``associate.py`` does.

    All pairs with ``|a - (b + offset)| < max_difference`` are sorted by that difference
    (ties by a, then b) and taken greedily, each timestamp used at most once.

    Parameters
    ----------
    stamps_a, stamps_b : (N,), (M,) float seconds, increasing
    Returns
    -------
    list of (index into a, index into b), sorted by a.
    """
    a = np.asarray(stamps_a, dtype=float)
    b = np.asarray(stamps_b, dtype=float) + offset
    lo = np.searchsorted(b, a - max_difference, side="left")
    hi = np.searchsorted(b, a + max_difference, side="right")
    counts = hi - lo
    ia = np.repeat(np.arange(len(a)), counts)
    ib = np.concatenate([np.arange(l, h) for l, h in zip(lo, hi)]) if len(a) else np.array([], int)
    ib = ib.astype(int)
    dt = np.abs(a[ia] - b[ib])
    keep = dt < max_difference
    ia, ib, dt = ia[keep], ib[keep], dt[keep]
    order = np.lexsort((b[ib], a[ia], dt))
    used_a = np.zeros(len(a), bool)
    used_b = np.zeros(len(b), bool)
    matches = []
    for k in order:  # greedy over candidate pairs (few per frame), not over pixels
        i, j = ia[k], ib[k]
        if not used_a[i] and not used_b[j]:
            used_a[i] = used_b[j] = True
            matches.append((int(i), int(j)))
    matches.sort()
    return matches


# --------------------------------------------------------------------------- trajectories


@dataclass
class Trajectory:
    """Timestamped camera poses.

    Attributes
    ----------
    timestamps : (N,) float seconds, increasing
    poses : (N, 4, 4) float, camera-to-world ``T_w_c``
    """

    timestamps: np.ndarray
    poses: np.ndarray

    def __post_init__(self):
        self.timestamps = np.asarray(self.timestamps, dtype=float).reshape(-1)
        self.poses = np.asarray(self.poses, dtype=float).reshape(-1, 4, 4)
        if len(self.timestamps) != len(self.poses):
            raise ValueError(
                f"{len(self.timestamps)} timestamps but {len(self.poses)} poses in trajectory"
            )

    def __len__(self) -> int:
        return len(self.timestamps)

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) camera centres in the world frame (metres)."""
        return self.poses[:, :3, 3]

    def nearest(self, t: float) -> np.ndarray:
        """(4, 4) pose whose timestamp is nearest to ``t`` seconds."""
        return self.poses[int(np.argmin(np.abs(self.timestamps - t)))]


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (x, y, z, w) -> (N, 3, 3) rotations; normalises."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
        ],
        axis=1,
    ).reshape(-1, 3, 3)


def _matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations -> (N, 4) unit quaternions (x, y, z, w) with w >= 0."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(R).as_quat()
    q[q[:, 3] < 0] *= -1
    return q


def read_trajectory(path: str | Path) -> Trajectory:
    """Read a TUM trajectory file ``timestamp tx ty tz qx qy qz qw`` (camera-to-world)."""
    path = Path(path)
    if not path.is_file():
        raise SequenceError(f"{path}: file not found")
    return parse_trajectory(_read_text(path), path)


def read_groundtruth(path: str | Path, bonn: bool | None = None) -> Trajectory:
    """A ground-truth trajectory as camera-to-world poses: Bonn RGB-D Dynamic files (the marker's
    pose; ``bonn`` None = when the folder name says bonn) are converted to the camera frame."""
    path = Path(path)
    gt = read_trajectory(path)
    if bonn or (bonn is None and is_bonn(path.parent)):
        gt = Trajectory(gt.timestamps, gt.poses @ bonn_marker_to_camera())
    return gt


def parse_trajectory(text: str, name) -> Trajectory:
    """:func:`read_trajectory` on the text of a file; ``name`` names it in errors."""
    entries = parse_file_list(text.splitlines(), name, min_columns=8)
    if not entries:
        raise SequenceError(f"{name}: no poses in trajectory file")
    try:
        values = np.array([[float(v) for v in cols[:7]] for _, cols in entries])
    except ValueError as exc:
        raise SequenceError(f"{name}: non-numeric pose value ({exc})") from None
    bad = ~np.all(np.isfinite(values), axis=1)
    if bad.any():
        raise SequenceError(f"{name}: non-finite pose values at timestamp {entries[int(np.argmax(bad))][0]:.6f}")
    qn = np.linalg.norm(values[:, 3:7], axis=1)
    if np.any(np.abs(qn - 1.0) > 0.1):
        k = int(np.argmax(np.abs(qn - 1.0) > 0.1))
        raise SequenceError(f"{name}: pose at timestamp {entries[k][0]:.6f} has quaternion norm {qn[k]:.3g}, "
                            "not a rotation (expected qx qy qz qw of norm 1)")
    poses = np.tile(np.eye(4), (len(values), 1, 1))
    poses[:, :3, :3] = _quat_to_matrix(values[:, 3:7])
    poses[:, :3, 3] = values[:, :3]
    return Trajectory(np.array([e[0] for e in entries]), poses)


def format_trajectory(traj: Trajectory) -> str:
    """TUM text of a trajectory: ``timestamp tx ty tz qx qy qz qw`` per line."""
    q = _matrix_to_quat(traj.poses[:, :3, :3]) if len(traj) else np.zeros((0, 4))
    lines = ["# timestamp tx ty tz qx qy qz qw  (camera-to-world, metres)"]
    for t, p, qq in zip(traj.timestamps, traj.positions, q):
        lines.append(
            f"{t:.6f} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {qq[0]:.6f} {qq[1]:.6f} {qq[2]:.6f} {qq[3]:.6f}"
        )
    return "\n".join(lines) + "\n"


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write a text file so that readers see the old content or the new, never half of it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_trajectory(path: str | Path, traj: Trajectory) -> None:
    """Write a TUM trajectory file (camera-to-world, colour timestamps), atomically."""
    atomic_write_text(path, format_trajectory(traj))


# --------------------------------------------------------------------------- sequences


@dataclass
class Frame:
    """One associated RGB-D frame.

    Attributes
    ----------
    index : int, position in the sequence window
    timestamp : float seconds (colour timestamp)
    rgb : (H, W, 3) uint8, RGB order
    depth : (H, W) float32, metres, 0 = no depth
    mask : (H, W) bool or None, ground-truth moving objects (synthetic sequences only)
    instances : (H, W) uint8 or None, ground-truth object instance ids (0 = no object)
    classes : {instance id: class name} of ``instances`` ('person', 'chair', 'board', ...)
    derived : what :meth:`derive` keeps, or None (the default: nothing kept). Not copied by
        ``dataclasses.replace``: a frame with other pixels (a restored image) starts without it
    """

    index: int
    timestamp: float
    rgb: np.ndarray
    depth: np.ndarray
    mask: np.ndarray | None = None
    instances: np.ndarray | None = None
    classes: dict[int, str] | None = None
    derived: Derived | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def gray(self) -> np.ndarray:
        """(H, W) uint8 intensity."""
        return cv2.cvtColor(self.rgb, cv2.COLOR_RGB2GRAY)

    def derive(self, key: tuple, make: Callable[[], Any], timer=None, stage: str = "") -> Any:
        """``make()``, made once per frame where the frame keeps what is derived from it
        (``derived``: :class:`KeptSequence`, whose frames the batch's runs of a sequence share,
        while its budget lasts) and each time otherwise. ``make`` must be a function of the
        sequence's frames and of what ``key`` names (settings, mask source, the other frame),
        never of a run's state. A value made by an earlier call charges ``timer`` (a
        :class:`~dynslam_lite.timing.StageTimer`) the milliseconds its making took under
        ``stage``, so a run's ms/frame is what the method costs on its own. The value is shared:
        its arrays are made read-only."""
        if self.derived is not None and key in self.derived:
            value, ms = self.derived[key]
            if timer is not None:
                timer.add(stage, ms)
            return value
        t = time.perf_counter()
        value = _read_only(make())
        if self.derived is not None:
            self.derived.keep(key, value, (time.perf_counter() - t) * 1000.0)
        return value


class Derived(dict):
    """What runs derived from one kept frame, {key: (value, ms to make)}; the frames of a
    sequence share one byte budget (``budget[0]``: bytes left), past which nothing more is kept."""

    def __init__(self, budget: list[int]):
        super().__init__()
        self.budget = budget

    def keep(self, key: tuple, value: Any, ms: float) -> None:
        size = _nbytes(value)
        if size <= self.budget[0]:
            self.budget[0] -= size
            self[key] = (value, ms)


def _arrays(value: Any):
    """The arrays in ``value`` (an array, or lists, tuples and objects holding them)."""
    if isinstance(value, np.ndarray):
        yield value
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _arrays(v)
    elif hasattr(value, "__dict__"):
        for v in vars(value).values():
            yield from _arrays(v)


def _nbytes(value: Any) -> int:
    return sum(a.nbytes for a in _arrays(value))


def _read_only(value: Any) -> Any:
    for a in _arrays(value):
        a.setflags(write=False)
    return value


def camera_from_name(name: str) -> PinholeCamera:
    """Camera preset by name (fr1, fr2, fr3, bonn)."""
    key = name.strip().lower()
    if key not in CAMERA_PRESETS:
        raise SequenceError(
            f"unknown camera {name!r}: choose one of {', '.join(sorted(CAMERA_PRESETS))}"
        )
    return CAMERA_PRESETS[key]


def read_camera_file(path: Path) -> PinholeCamera:
    """Read ``camera.txt``: ``fx fy cx cy width height depth_scale`` on one line."""
    entries = [
        ln.split() for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")
    ]
    try:
        fx, fy, cx, cy, w, h, s = (float(v) for v in entries[0][:7])
    except (IndexError, ValueError):
        raise SequenceError(
            f"{path}: expected 'fx fy cx cy width height depth_scale' on one line"
        ) from None
    return PinholeCamera(fx, fy, cx, cy, int(w), int(h), s, name="file")


def guess_camera(root: Path) -> PinholeCamera:
    """Camera of a sequence folder: ``camera.txt`` if present, else from the folder name."""
    if (root / "camera.txt").is_file():
        return read_camera_file(root / "camera.txt")
    name = root.resolve().name.lower()
    for token, preset in (("freiburg1", "fr1"), ("freiburg2", "fr2"), ("freiburg3", "fr3"),
                          ("fr1", "fr1"), ("fr2", "fr2"), ("fr3", "fr3"), ("bonn", "bonn")):
        if token in name:
            return CAMERA_PRESETS[preset]
    raise SequenceError(
        f"{root}: unknown camera: the folder name names no dataset (freiburg1/2/3, bonn) and "
        f"there is no camera.txt; pass --camera with one of {', '.join(sorted(CAMERA_PRESETS))}"
    )


def is_bonn(root: Path) -> bool:
    """True for Bonn RGB-D Dynamic folders (``rgbd_bonn_*``), whose ground truth needs conversion."""
    return "bonn" in root.resolve().name.lower()


@dataclass
class RGBDSequence:
    """A TUM-layout RGB-D sequence read lazily: images are loaded when a frame is asked for.

    Build with :func:`open_sequence`. Index it (``seq[i]``) to get a :class:`Frame`.

    Attributes
    ----------
    root : Path
    camera : PinholeCamera
    rgb_files, depth_files : list[Path], associated colour / depth images
    timestamps : (N,) float, colour timestamps of the associated frames
    depth_timestamps : (N,) float
    groundtruth : Trajectory or None, camera-to-world (Bonn converted to the camera frame)
    mask_files : list[Path or None] or None, ground-truth moving-object masks (synthetic)
    instance_files : list[Path or None] or None, ground-truth instance ids (synthetic)
    classes : {instance id: class} of the instance images, or None
    moving_ids : per frame, the instance ids that move, or None
    exposure : (N, 2) float, per frame the gain and bias of the image brightness
        (``exposure.txt`` of a synthetic scene with automatic exposure), or None
    """

    root: Path
    camera: PinholeCamera
    rgb_files: list[Path]
    depth_files: list[Path]
    timestamps: np.ndarray
    depth_timestamps: np.ndarray
    groundtruth: Trajectory | None = None
    mask_files: list[Path | None] | None = None
    background_files: list[Path | None] | None = None
    name: str = field(default="")
    instance_files: list[Path | None] | None = None
    classes: dict[int, str] | None = None
    moving_ids: list[list[int]] | None = None
    exposure: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.timestamps)

    def __getitem__(self, i: int) -> Frame:
        if not -len(self) <= i < len(self):
            raise IndexError(f"frame {i} out of range for {len(self)} frames")
        i = i % len(self)
        rgb = load_rgb(self.rgb_files[i])
        depth = load_depth(self.depth_files[i], self.camera.depth_scale)
        if rgb.shape[:2] != depth.shape:
            raise SequenceError(
                f"{self.depth_files[i]}: depth size {depth.shape[1]}x{depth.shape[0]} differs from "
                f"colour size {rgb.shape[1]}x{rgb.shape[0]} of {self.rgb_files[i]}"
            )
        if rgb.shape[:2] != (self.camera.height, self.camera.width):
            raise SequenceError(
                f"{self.rgb_files[i]}: image size {rgb.shape[1]}x{rgb.shape[0]} differs from the "
                f"camera's {self.camera.width}x{self.camera.height}"
            )
        mask = None
        if self.mask_files is not None and self.mask_files[i] is not None:
            mask = load_mask(self.mask_files[i])
        instances = None
        if self.instance_files is not None and self.instance_files[i] is not None:
            instances = cv2.imread(str(self.instance_files[i]), cv2.IMREAD_UNCHANGED)
            if instances is None or instances.shape != depth.shape:
                raise SequenceError(f"{self.instance_files[i]}: unreadable instance image or wrong size")
        return Frame(i, float(self.timestamps[i]), rgb, depth, mask, instances, self.classes)

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def background(self, i: int) -> np.ndarray | None:
        """(H, W, 3) uint8 RGB of frame i rendered without moving objects (synthetic only)."""
        if self.background_files is None or self.background_files[i] is None:
            return None
        return load_rgb(self.background_files[i])

    def background_depth(self, i: int) -> np.ndarray | None:
        """(H, W) float32 metres of frame i without moving objects (synthetic, ``background_depth/``)."""
        if self.background_files is None or self.background_files[i] is None:
            return None
        path = self.background_files[i].parent.parent / "background_depth" / self.background_files[i].name
        return load_depth(path, self.camera.depth_scale) if path.is_file() else None

    def window(self, start: int = 0, count: int | None = None, step: int = 1) -> "RGBDSequence":
        """Sub-sequence of ``count`` frames from ``start`` (all remaining when None), every
        ``step``-th frame (3 turns a 30 Hz recording into 10 Hz: larger motion between frames)."""
        if start < 0 or start >= len(self):
            raise SequenceError(f"{self.root}: start frame {start} outside 0..{len(self) - 1}")
        if count is not None and count <= 0:
            raise SequenceError(f"{self.root}: frame count must be positive, got {count}")
        if step < 1:
            raise SequenceError(f"{self.root}: frame step must be 1 or more, got {step}")
        stop = len(self) if count is None else min(len(self), start + int(count) * step)
        sl = slice(start, stop, step)
        return RGBDSequence(
            self.root, self.camera, self.rgb_files[sl], self.depth_files[sl],
            self.timestamps[sl], self.depth_timestamps[sl], self.groundtruth,
            None if self.mask_files is None else self.mask_files[sl],
            None if self.background_files is None else self.background_files[sl],
            self.name,
            None if self.instance_files is None else self.instance_files[sl], self.classes,
            None if self.moving_ids is None else self.moving_ids[sl],
            None if self.exposure is None else self.exposure[sl],
        )


class KeptSequence(RGBDSequence):
    """A sequence whose frames stay in memory once read, read-only, up to ``budget_bytes``
    (the first frames read; the rest are decoded each time), with what runs derive from them
    (:meth:`Frame.derive`: ORB keypoints, masks, depth layers, paper A's pre-removal, paper C's
    removal) up to ``derived_bytes``. The batch keeps the last sequence a worker tracked, so the
    runs of one sequence decode its PNGs and derive those once per worker."""

    def __init__(self, seq: RGBDSequence, budget_bytes: int = 1 << 30, derived_bytes: int = 1 << 30):
        super().__init__(**{f.name: getattr(seq, f.name) for f in fields(seq)})
        self.budget_bytes = budget_bytes
        self.derived_left = [derived_bytes]  # shared by the frames' Derived
        self._kept: dict[int, Frame] = {}
        self._bytes = 0

    def __getitem__(self, i: int) -> Frame:
        if -len(self) <= i < len(self) and i % len(self) in self._kept:
            return self._kept[i % len(self)]
        frame = super().__getitem__(i)
        pixels = (frame.rgb, frame.depth, frame.mask, frame.instances)
        size = _nbytes(pixels)
        if self._bytes + size <= self.budget_bytes:
            _read_only(pixels)  # shared by every run: a method must not write into it
            frame.derived = Derived(self.derived_left)  # and what the runs derive from it
            self._kept[i % len(self)] = frame
            self._bytes += size
        return frame


def load_rgb(path: Path) -> np.ndarray:
    """Colour PNG -> (H, W, 3) uint8 RGB."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SequenceError(f"{path}: cannot read image (missing or not a valid image file)")
    if img.dtype != np.uint8:
        raise SequenceError(f"{path}: colour image must be 8-bit, got {img.dtype}")
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def load_depth(path: Path, depth_scale: float) -> np.ndarray:
    """16-bit depth PNG -> (H, W) float32 metres, 0 = no depth."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SequenceError(f"{path}: cannot read depth image (missing or not a valid image file)")
    if img.ndim != 2 or img.dtype != np.uint16:
        raise SequenceError(
            f"{path}: depth must be a single-channel 16-bit PNG ({depth_scale:g} units per metre), "
            f"got {img.dtype} with {1 if img.ndim == 2 else img.shape[2]} channel(s)"
        )
    return img.astype(np.float32) / np.float32(depth_scale)


def load_mask(path: Path) -> np.ndarray:
    """8-bit mask PNG (255 = moving) -> (H, W) bool."""
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise SequenceError(f"{path}: cannot read mask image")
    return img > 127


def _per_frame_values(path: Path, stamps: list[float], columns: int) -> np.ndarray:
    """(len(stamps), columns) floats of a ``timestamp value...`` list, one row per colour timestamp."""
    rows = {}
    for t, cols in read_file_list(path, columns + 1):
        try:
            rows[round(t, 6)] = [float(c) for c in cols[:columns]]
        except ValueError:
            raise SequenceError(f"{path}: expected {columns} numbers after the timestamp {t:.6f}, got "
                                f"{' '.join(cols[:columns])!r}") from None
    missing = [t for t in stamps if round(t, 6) not in rows]
    if missing:
        raise SequenceError(f"{path}: no row for {len(missing)} colour frame(s), first at {missing[0]:.6f}")
    return np.array([rows[round(t, 6)] for t in stamps], float).reshape(len(stamps), columns)


def open_sequence(
    root: str | Path,
    camera: str | PinholeCamera | None = None,
    start: int = 0,
    count: int | None = None,
    max_difference: float = 0.02,
    step: int = 1,
) -> RGBDSequence:
    """Open a TUM / Bonn sequence folder as downloaded.

    Parameters
    ----------
    root : folder with ``rgb.txt`` and ``depth.txt``
    camera : preset name (fr1, fr2, fr3, bonn), a PinholeCamera, or None to guess
        (``camera.txt`` in the folder, else the folder name)
    start, count, step : frame window over the associated frames (every ``step``-th frame)
    max_difference : seconds, colour-depth association tolerance (TUM: 0.02)

    Ground truth (``groundtruth.txt``), when present, is read as camera-to-world; for Bonn
    folders it is converted from the marker frame to the camera frame.
    """
    root = Path(root)
    if not root.is_dir():
        raise SequenceError(f"{root}: sequence folder not found")
    rgb_list = read_file_list(root / "rgb.txt")
    if not rgb_list:
        raise SequenceError(f"{root / 'rgb.txt'}: lists no colour images (empty sequence)")
    depth_path = root / "depth.txt"
    if not depth_path.is_file():
        raise SequenceError(
            f"{depth_path}: file not found: this folder has no depth; the methods need RGB-D input"
        )
    depth_list = read_file_list(depth_path)
    if not depth_list:
        raise SequenceError(f"{depth_path}: lists no depth images: the sequence has no depth")
    cam = camera if isinstance(camera, PinholeCamera) else (
        camera_from_name(camera) if camera else guess_camera(root)
    )
    ta = np.array([e[0] for e in rgb_list])
    tb = np.array([e[0] for e in depth_list])
    matches = associate(ta, tb, max_difference)
    if not matches:
        raise SequenceError(
            f"{root}: no colour image has a depth image within {max_difference} s; "
            "check that rgb.txt and depth.txt belong to the same recording"
        )
    rgb_files = [root / rgb_list[i][1][0] for i, _ in matches]
    depth_files = [root / depth_list[j][1][0] for _, j in matches]
    for listed, files in (("rgb.txt", rgb_files), ("depth.txt", depth_files)):
        missing = [f for f in files if not f.is_file()]
        if missing:
            raise SequenceError(f"{root / listed}: {len(missing)} listed image(s) missing, first "
                                f"{missing[0]}")
    gt = None
    if (root / "groundtruth.txt").is_file():
        gt = read_groundtruth(root / "groundtruth.txt", is_bonn(root))
    masks = None
    if (root / "masks.txt").is_file():
        mlist = {round(t, 6): root / cols[0] for t, cols in read_file_list(root / "masks.txt")}
        masks = [mlist.get(round(float(ta[i]), 6)) for i, _ in matches]
    instances = classes = moving = None
    if (root / "instances.json").is_file():  # synthetic: object instances and which move
        try:
            info = json.loads((root / "instances.json").read_text(encoding="utf-8"))
            classes = {int(k): str(v) for k, v in info["classes"].items()}
            moving_by_t = {round(float(t), 6): list(ids) for t, ids in info["moving"].items()}
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise SequenceError(f"{root / 'instances.json'}: not an instance list ({exc})") from None
        instances = [root / "instances" / f"{ta[i]:.6f}.png" for i, _ in matches]
        moving = [moving_by_t.get(round(float(ta[i]), 6), []) for i, _ in matches]
    backgrounds = None
    if (root / "background.txt").is_file():
        blist = {round(t, 6): root / cols[0] for t, cols in read_file_list(root / "background.txt")}
        backgrounds = [blist.get(round(float(ta[i]), 6)) for i, _ in matches]
    exposure = None
    if (root / "exposure.txt").is_file():  # synthetic: a camera with automatic exposure
        exposure = _per_frame_values(root / "exposure.txt", [float(ta[i]) for i, _ in matches], 2)
    seq = RGBDSequence(
        root, cam, rgb_files, depth_files,
        np.array([ta[i] for i, _ in matches]), np.array([tb[j] for _, j in matches]),
        gt, masks, backgrounds, root.resolve().name, instances, classes, moving, exposure,
    )
    return seq.window(start, count, step) if (start or count is not None or step != 1) else seq
