"""Mask sources: oracle (exact and degraded), files, none, and their errors."""
import cv2
import numpy as np
import pytest

from dynslam_lite.evaluation import MaskScores
from dynslam_lite.io import Frame, SequenceError, open_sequence
from dynslam_lite.imageops import split_instances
from dynslam_lite.errors import ConfigError
from dynslam_lite.masks import MISSED, FileMasks, NearMissed, make_mask_source


def _frame(mask, index=0, t=100.0):
    H, W = mask.shape
    return Frame(index, t, np.zeros((H, W, 3), np.uint8), np.ones((H, W), np.float32), mask)


def _two_people():
    m = np.zeros((120, 160), bool)
    m[10:60, 10:40] = True
    m[50:110, 100:140] = True
    return m


def test_oracle_gives_ground_truth_instances():
    inst = make_mask_source("oracle")(_frame(_two_people()))
    assert len(inst) == 2
    assert np.array_equal(np.logical_or.reduce(inst), _two_people())


def test_degraded_oracle_is_deterministic_and_close(scene):
    seq = open_sequence(scene("walking_xyz", 12))
    src = make_mask_source("oracle:degraded")
    frames = [seq[i] for i in range(12)]
    a = [src(f) for f in frames]
    b = [src(f) for f in frames]
    assert all(len(x) == len(y) and all(np.array_equal(p, q) for p, q in zip(x, y)) for x, y in zip(a, b))
    union = np.stack([np.logical_or.reduce(x) if x else np.zeros_like(f.mask) for x, f in zip(a, frames)])
    s = MaskScores.of(union, np.stack([f.mask for f in frames]))
    assert 0.6 < s.iou < 0.99, s  # spoiled, but still a usable segmentation


def test_file_masks_by_timestamp(tmp_path):
    ids = np.zeros((120, 160), np.uint8)
    ids[10:60, 10:40] = 1
    ids[50:110, 100:140] = 2
    cv2.imwrite(str(tmp_path / "100.000000.png"), ids)
    cv2.imwrite(str(tmp_path / "200.000000.png"), _two_people().astype(np.uint8) * 255)
    src = FileMasks(tmp_path)
    assert len(src(_frame(_two_people(), t=100.01))) == 2
    assert len(src(_frame(_two_people(), t=200.0))) == 2  # binary -> components
    assert src(_frame(_two_people(), t=150.0)) == []  # no file within 0.02 s


def test_mask_source_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown mask source"):
        make_mask_source("yolo")
    with pytest.raises(SequenceError, match="not found"):
        make_mask_source(f"files:{tmp_path / 'nope'}")
    (tmp_path / "frame1.png").write_bytes(b"")
    with pytest.raises(SequenceError, match="not a timestamp"):
        FileMasks(tmp_path)
    with pytest.raises(SequenceError, match="ground-truth masks"):
        make_mask_source("oracle")(Frame(0, 0.0, np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), np.float32)))


def test_split_instances_drops_specks():
    m = _two_people()
    m[0, 159] = True
    assert len(split_instances(m)) == 2


def test_missed_oracle_loses_the_near_people_in_12_of_every_36_frames():
    """``oracle:missed``: an instance covering more than 5 % of the image is missed in frames
    24-35, 60-71, ...; a small (far) one never."""
    m = np.zeros((120, 160), bool)
    m[:, :40] = True  # 25 % of the image: near
    m[10:20, 100:110] = True  # 0.5 %: far
    src = make_mask_source("oracle:missed")
    for index, near in ((0, True), (23, True), (24, False), (35, False), (36, True), (60, False), (72, True)):
        inst = src(_frame(m, index))
        assert len(inst) == 1 + near and inst[-1].sum() == 100, index
    # the ranges the objects table prints
    assert MISSED.near_miss_ranges(150) == [(24, 35), (60, 71), (96, 107), (132, 143)]
    assert MISSED.near_miss_ranges(30) == [(24, 29)] and MISSED.near_miss_ranges(24) == []


def test_missed_person_model_drops_the_near_instances_in_the_frames_the_missed_oracle_does():
    """``person:missed`` is the person model's masks with the rule of ``oracle:missed``: any
    source's instances over 5 % of the image are dropped in frames 24-35 of every 36, the rest
    pass unchanged."""
    near = np.zeros((120, 160), bool)
    near[:, :40] = True
    far = np.zeros((120, 160), bool)
    far[10:20, 100:110] = True
    wrapped = NearMissed(lambda frame: [near, far], MISSED, "test:missed")
    oracle = make_mask_source("oracle:missed")
    for index in range(0, 80):
        inst = wrapped(_frame(near | far, index))
        assert [m.sum() for m in inst] == [m.sum() for m in oracle(_frame(near | far, index))], index
        assert (len(inst) == 1) == (index % 36 >= 24) and inst[-1] is far
    for spec, inner in (("person:missed", "person"), ("person:landscape:missed", "person:landscape")):
        src = make_mask_source(spec)
        assert isinstance(src, NearMissed) and src.name == spec and src.inner.name == inner
    for spec in ("person:square:missed", "none:missed", "oracle:all:missed"):
        with pytest.raises(ConfigError, match="unknown mask source"):
            make_mask_source(spec)
