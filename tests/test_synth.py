import json

import cv2
import numpy as np
import pytest

from dynslam_lite.io import open_sequence
from dynslam_lite.synth import SYNTH_CAMERA, SceneRenderer, generate
from dynslam_lite.synth.raycast import render
from dynslam_lite.synth.sensor import degrade_depth


def test_same_seed_same_bytes(tmp_path):
    a = generate(tmp_path / "a", "walking_xyz", 3, seed=7).path
    b = generate(tmp_path / "b", "walking_xyz", 3, seed=7).path
    c = generate(tmp_path / "c", "walking_xyz", 3, seed=8).path
    for sub in ("rgb", "depth", "masks"):
        fa, fb = sorted((a / sub).iterdir()), sorted((b / sub).iterdir())
        assert [f.read_bytes() for f in fa] == [f.read_bytes() for f in fb]
    assert (a / "groundtruth.txt").read_text() == (b / "groundtruth.txt").read_text()
    assert (a / "rgb.txt").read_text() != (c / "rgb.txt").read_text()


def test_tum_layout_association_and_masks(scene):
    path = scene("walking_xyz", 45, background=True)
    seq = open_sequence(path)
    assert len(seq) == 45  # every colour frame finds its depth frame
    assert seq.camera.fx == SYNTH_CAMERA.fx
    dt = np.abs(seq.depth_timestamps - seq.timestamps)
    assert dt.max() < 0.02 and dt.max() > 0.001  # apart, but associable
    gt_rate = 1 / np.median(np.diff(seq.groundtruth.timestamps))
    assert gt_rate == pytest.approx(100, rel=0.01)
    masks = np.stack([seq[i].mask for i in range(0, 45, 5)])
    assert masks.any(axis=(1, 2)).sum() >= 7  # people in view in most frames
    cover = masks.mean(axis=(1, 2)).max()
    assert 0.05 < cover < 0.8
    # background frames differ from the frame only where something moves (up to sensor noise)
    f = seq[10]
    bg = seq.background(10)
    diff = np.abs(bg.astype(int) - f.rgb.astype(int)).max(axis=2)
    static = ~cv2.dilate(f.mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert np.percentile(diff[static], 99) < 15
    assert np.median(diff[f.mask]) > 20
    assert json.loads((path / "scene.json").read_text())["scene"] == "walking_xyz"


def test_static_scene_has_no_moving_pixels(scene):
    seq = open_sequence(scene("static_xyz", 10))
    assert not any(seq[i].mask.any() for i in range(len(seq)))


def test_depth_noise_grows_with_distance_and_edges_drop():
    r = SceneRenderer("static_xyz", 0)
    _, true_depth, _, no_depth = render(r.camera, r.pose(0.0), r.static, [], r.textures,
                                        np.array([0, 0, 1.0]), r.rays)
    rng = np.random.default_rng(0)
    noisy = degrade_depth(true_depth, no_depth, rng)
    ok = noisy > 0
    err = noisy[ok] - true_depth[ok]
    z = true_depth[ok]
    near = z < np.percentile(z, 20)
    far = z > np.percentile(z, 80)
    assert z[far].mean() > z[near].mean() + 1.0
    assert np.std(err[near]) < np.std(err[far])
    assert np.std(err[near]) < 0.015 and np.abs(np.mean(err[near])) < 0.003
    assert not noisy[no_depth].any()  # glossy screen gives no depth
    assert not ok.all()


def test_unknown_scene_rejected(tmp_path):
    with pytest.raises(ValueError, match="unknown synthetic scene"):
        generate(tmp_path / "x", "dancing_xyz", 2)
