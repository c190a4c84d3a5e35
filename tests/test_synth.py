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


def test_background_scene_reuses_the_plain_frames_byte_for_byte(tmp_path):
    from dynslam_lite.synth import ensure_scene

    plain = ensure_scene(tmp_path / "shared", "walking_xyz", 3, seed=7)
    copied = ensure_scene(tmp_path / "shared", "walking_xyz", 3, seed=7, background=True)
    rendered = ensure_scene(tmp_path / "alone", "walking_xyz", 3, seed=7, background=True)
    assert copied != plain and copied.name == rendered.name
    for sub in ("rgb", "depth", "masks", "instances", "background", "background_depth"):
        fa, fb = sorted((copied / sub).iterdir()), sorted((rendered / sub).iterdir())
        assert len(fa) == 3 and [f.read_bytes() for f in fa] == [f.read_bytes() for f in fb]
    for name in ("rgb.txt", "depth.txt", "groundtruth.txt", "instances.json", "scene.json"):
        assert (copied / name).read_text() == (rendered / name).read_text()


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
    _, true_depth, _, no_depth, _ = render(r.camera, r.pose(0.0), r.static, [], r.textures,
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


def _classes_at(r: SceneRenderer, s: float):
    """(instance image, {id: class}, moving ids) of a noise-free render at time s."""
    _, _, moving, inst = r.frame(int(s * 30), s)
    return inst, r.classes, set(r.moving_ids(s)), moving


def test_carried_objects_are_instances_of_their_own_class_that_move_with_their_carrier():
    r = SceneRenderer("walking_carry", 0)
    inst, classes, moving, mask = _classes_at(r, 1.0)
    board = [k for k, c in classes.items() if c == "board"]
    box = [k for k, c in classes.items() if c == "box" and k in moving]
    assert len(board) == 1 and len(box) == 1 and board[0] in moving
    assert (inst == board[0]).mean() > 0.01  # the board is in view, not painted as a person
    assert np.array_equal(mask, np.isin(inst, sorted(moving)))  # moving mask = moving instances


def test_pushed_box_moves_only_while_pushed_and_a_person_stands_still():
    r = SceneRenderer("walking_push", 0)
    box = next(k for k in r.mover_ids)
    assert r.classes[box] == "box"
    assert box not in r.moving_ids(0.5) and box in r.moving_ids(2.0) and box not in r.moving_ids(4.5)
    standing = r.person_ids[1]
    assert standing not in r.moving_ids(2.0) and standing in r.moving_ids(0.5)
    inst, _, moving, mask = _classes_at(r, 2.0)
    assert (inst == standing).any() and not mask[inst == standing].any()  # in view, not moving
    # the box is large in view: a tenth of the image or more while it is pushed
    assert mask[inst == box].all() and (inst == box).mean() > 0.1


def test_crowd_fills_over_half_the_image_and_oracle_masks_are_people_only(tmp_path):
    from dynslam_lite.masks import make_mask_source

    r = SceneRenderer("crowd", 0)
    cover = []
    for s in np.arange(0.0, 5.0, 0.25):
        inst, classes, _, _ = _classes_at(r, s)
        cover.append(np.isin(inst, r.person_ids).mean())
    assert max(cover) > 0.5 and min(cover) > 0.02, np.round(cover, 2)  # over half, never empty
    seq = open_sequence(generate(tmp_path / "carry", "walking_carry", 3, 0).path)
    f = seq[2]
    people = np.isin(f.instances, [k for k, c in f.classes.items() if c == "person"])
    oracle = np.logical_or.reduce(make_mask_source("oracle")(f))
    board = np.isin(f.instances, [k for k, c in f.classes.items() if c == "board"])
    # what a person detector gives: the people (components of 50 px and more), not the board
    assert not (oracle & ~people).any() and oracle.sum() > 0.98 * people.sum() and board.sum() > 1000
    every = make_mask_source("oracle:all")(f)
    classes_seen = {f.classes[int(f.instances[m][0])] for m in every}
    assert {"person", "board", "table"} <= classes_seen


def test_oracle_moving_masks_are_the_moving_objects_one_per_instance(tmp_path):
    """``oracle:moving``: every object moving in the frame (the carried board and box, the
    walking people), each its own instance, and nothing that stands still."""
    from dynslam_lite.masks import make_mask_source

    f = open_sequence(generate(tmp_path / "carry", "walking_carry", 3, 0).path)[2]
    moving = make_mask_source("oracle:moving")(f)
    union = np.logical_or.reduce(moving)
    assert (union == f.mask).all()
    ids = [set(np.unique(f.instances[m])) for m in moving]
    assert all(len(s) == 1 for s in ids) and len(moving) == len(np.unique(f.instances[f.mask]))
    assert {f.classes[s.pop()] for s in ids} >= {"person", "board"}


def test_exposure_scene_is_walking_xyz_under_the_gain_and_bias_it_writes(scene):
    """walking_exposure: the frames of walking_xyz (depth and masks byte for byte) with the image
    brightness changed every 10-13 frames by the gain and bias of its exposure.txt; the schedule
    of a frame does not depend on the frame count."""
    from dynslam_lite.synth.generator import exposure_schedule

    exp, plain = open_sequence(scene("walking_exposure", 57)), open_sequence(scene("walking_xyz", 150))
    table = np.loadtxt(exp.root / "exposure.txt")
    assert np.allclose(table[:, 0], exp.timestamps)
    assert np.array_equal(exp.exposure, table[:, 1:3]) and plain.exposure is None
    assert np.array_equal(exp.window(10, 5, 2).exposure, table[10:20:2, 1:3])  # windowed with the frames
    gain, bias = table[:, 1], table[:, 2]
    changes = np.flatnonzero(np.diff(gain)) + 1
    assert gain[0] == 1.0 and bias[0] == 0.0 and len(changes) >= 4 and np.all(np.diff(changes) >= 10)
    assert np.all(np.abs(np.log(gain[changes]) - np.log(gain[changes - 1])) >= 0.04 - 1e-6)
    short, long = exposure_schedule("walking_exposure", 0, 20), exposure_schedule("walking_exposure", 0, 57)
    assert np.array_equal(short[0], long[0][:20]) and np.array_equal(short[1], long[1][:20])
    assert np.allclose(long[0], gain, atol=1e-6) and np.allclose(long[1], bias, atol=1e-6)
    assert np.all(exposure_schedule("walking_xyz", 0, 57)[0] == 1.0)
    for i in (0, int(changes[0]), 56):
        a, b = exp[i], plain[i]
        assert np.array_equal(a.depth, b.depth) and np.array_equal(a.mask, b.mask)
        x, y = b.rgb.astype(float).ravel() / 255, a.rgb.astype(float).ravel() / 255
        ok = (y > 0.02) & (y < 0.98)  # not clipped
        g, c = np.polyfit(x[ok], y[ok], 1)
        assert abs(g - gain[i]) < 0.01 and abs(c - bias[i]) < 0.005, (i, g, c, gain[i], bias[i])
