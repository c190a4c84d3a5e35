import itertools

import cv2
import numpy as np
import pytest

from conftest import BONN_CROWD, FR1_GT, need
from dynslam_lite.geometry import se3_exp
from dynslam_lite.io import (SequenceError, Trajectory, associate, bonn_marker_to_camera,
                             open_sequence, read_file_list, read_trajectory, write_trajectory)


def _tum_associate(a, b, max_difference=0.02):
    """TUM associate.py, literally: all pairs, sorted, taken greedily."""
    first, second = list(a), list(b)
    pairs = sorted((abs(x - y), x, y) for x in first for y in second if abs(x - y) < max_difference)
    out = []
    for _, x, y in pairs:
        if x in first and y in second:
            first.remove(x)
            second.remove(y)
            out.append((x, y))
    return sorted(out)


@pytest.mark.parametrize("seed", range(4))
def test_association_matches_tum_associate(seed):
    rng = np.random.default_rng(seed)
    a = np.sort(rng.uniform(0, 5, 120))
    b = np.sort(rng.uniform(0, 5, 110))
    ours = [(a[i], b[j]) for i, j in associate(a, b)]
    assert ours == _tum_associate(a, b)


def _write_sequence(root, n=3, depth_dtype=np.uint16, size=(64, 48), depth_size=None):
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    rgb_lines, depth_lines = ["# color images"], ["# depth maps"]
    for i in range(n):
        t = 10.0 + i / 30
        cv2.imwrite(str(root / "rgb" / f"{t:.6f}.png"), np.full(size[::-1] + (3,), 100, np.uint8))
        dsize = depth_size or size
        cv2.imwrite(str(root / "depth" / f"{t + 0.005:.6f}.png"), np.full(dsize[::-1], 5000 if depth_dtype == np.uint16 else 50, depth_dtype))
        rgb_lines.append(f"{t:.6f} rgb/{t:.6f}.png")
        depth_lines.append(f"{t + 0.005:.6f} depth/{t + 0.005:.6f}.png")
    (root / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (root / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    (root / "camera.txt").write_text(f"100 100 32 24 {size[0]} {size[1]} 5000\n")
    return root


def test_every_nth_frame(tmp_path):
    """A stride keeps every n-th associated frame, colour and depth together, counted as taken."""
    root = _write_sequence(tmp_path / "s", n=7)
    seq = open_sequence(root)
    third = open_sequence(root, step=3)
    assert len(third) == 3 and list(third.timestamps) == list(seq.timestamps[::3])
    assert list(third.depth_files) == list(seq.depth_files[::3])
    assert list(seq.window(1, 2, 2).timestamps) == [seq.timestamps[1], seq.timestamps[3]]
    assert len(open_sequence(root, start=2, count=10, step=2)) == 3  # frames 2, 4, 6
    with pytest.raises(SequenceError, match="frame step must be 1 or more, got 0"):
        open_sequence(root, step=0)


def test_exposure_list_is_read_per_frame_and_windowed(tmp_path):
    """A synthetic scene's exposure.txt: gain and bias per colour frame, sliced with the frames."""
    root = _write_sequence(tmp_path / "s", n=4)
    (root / "exposure.txt").write_text("# timestamp gain bias\n" + "".join(
        f"{10.0 + i / 30:.6f} {1 + i / 10} {-i / 100}\n" for i in range(4)))
    seq = open_sequence(root)
    assert np.allclose(seq.exposure, [[1.0, 0.0], [1.1, -0.01], [1.2, -0.02], [1.3, -0.03]])
    assert np.allclose(open_sequence(root, start=1, step=2).exposure, [[1.1, -0.01], [1.3, -0.03]])
    assert open_sequence(_write_sequence(tmp_path / "plain")).exposure is None


def test_reads_valid_sequence_lazily(tmp_path):
    seq = open_sequence(_write_sequence(tmp_path / "s", n=5))
    assert len(seq) == 5 and seq.window(1, 2).timestamps[0] == pytest.approx(10 + 1 / 30)
    f = seq[2]
    assert f.rgb.shape == (48, 64, 3) and f.depth.dtype == np.float32 and np.allclose(f.depth, 1.0)


@pytest.mark.parametrize("breakage, message", [
    (lambda r: (r / "rgb.txt").unlink(), "rgb.txt: file not found"),
    (lambda r: (r / "rgb.txt").write_text("# nothing\n"), "empty sequence"),
    (lambda r: (r / "rgb.txt").write_text("10.0 rgb/a.png\nabc rgb/b.png\n"), "rgb.txt:2: expected a timestamp"),
    (lambda r: (r / "rgb.txt").write_text("10.0\n"), "rgb.txt:1: expected at least 2 columns"),
    (lambda r: (r / "rgb.txt").write_text("10.1 rgb/a.png\n10.0 rgb/b.png\n"), "rgb.txt:2: timestamps not increasing"),
    (lambda r: (r / "depth.txt").unlink(), "has no depth"),
    (lambda r: (r / "depth.txt").write_text("# none\n"), "the sequence has no depth"),
    (lambda r: (r / "depth.txt").write_text("99.0 depth/x.png\n"), "no colour image has a depth image"),
    (lambda r: (r / "camera.txt").unlink(), "unknown camera"),
    (lambda r: (r / "rgb.txt").write_text("10.0 rgb/a.png\nnan rgb/b.png\n"), "rgb.txt:2: timestamp 'nan' is not a finite"),
    (lambda r: (r / "rgb.txt").write_text("10.0 rgb/a.png\n10.0 rgb/b.png\n"), "rgb.txt:2: timestamp 10.000000 repeated"),
    (lambda r: (r / "rgb.txt").write_bytes((r / "rgb.txt").read_text().encode("utf-16")), "rgb.txt: not a UTF-8 text file \\(UTF-16"),
    (lambda r: sorted((r / "depth").iterdir())[1].unlink(), "depth.txt: 1 listed image\\(s\\) missing, first .*depth/"),
    (lambda r: (r / "exposure.txt").write_text("10.000000 1.0 0.0\n10.033333 1.1\n"), "exposure.txt:2: expected at least 3 columns"),
    (lambda r: (r / "exposure.txt").write_text("10.000000 1.0 0.0\n10.033333 1.1 x\n"), "exposure.txt: expected 2 numbers after the timestamp 10.033333"),
    (lambda r: (r / "exposure.txt").write_text("10.000000 1.0 0.0\n"), "exposure.txt: no row for 2 colour frame\\(s\\), first at 10.033333"),
])
def test_bad_input_is_named(tmp_path, breakage, message):
    root = _write_sequence(tmp_path / "seq")
    breakage(root)
    with pytest.raises(SequenceError, match=message):
        open_sequence(root)


def test_bad_images_are_named(tmp_path):
    root = _write_sequence(tmp_path / "a")
    first_rgb = sorted((root / "rgb").iterdir())[0]
    first_rgb.write_bytes(b"not a png")
    with pytest.raises(SequenceError, match=f"{first_rgb.name}: cannot read image"):
        open_sequence(root)[0]
    root = _write_sequence(tmp_path / "b", depth_dtype=np.uint8)
    with pytest.raises(SequenceError, match="depth must be a single-channel 16-bit PNG"):
        open_sequence(root)[0]
    root = _write_sequence(tmp_path / "c", depth_size=(32, 24))
    with pytest.raises(SequenceError, match="differs from colour size"):
        open_sequence(root)[0]


def test_unknown_camera_preset(tmp_path):
    with pytest.raises(SequenceError, match="unknown camera 'kinect9'"):
        open_sequence(_write_sequence(tmp_path / "s"), camera="kinect9")


def test_header_quirk_of_tum_fr1():
    traj = read_trajectory(need(FR1_GT))
    assert len(traj) == 3000 and traj.timestamps[0] == pytest.approx(1305031098.6659)


def test_header_quirk_constructed(tmp_path):
    p = tmp_path / "groundtruth.txt"
    p.write_text("# gt\ntimestamp tx ty tz qx qy qz qw\n1.0 0 0 0 0 0 0 1\n")
    assert len(read_file_list(p, 8)) == 1


def test_trajectory_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    poses = np.stack([se3_exp(rng.normal(size=6)) for _ in range(5)])
    traj = Trajectory(100 + np.arange(5) / 30, poses)
    write_trajectory(tmp_path / "t.txt", traj)
    back = read_trajectory(tmp_path / "t.txt")
    assert np.allclose(back.poses, poses, atol=2e-6) and np.allclose(back.timestamps, traj.timestamps)


def test_bonn_conversion_is_rigid_and_applied():
    T = bonn_marker_to_camera()
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    seq = open_sequence(need(BONN_CROWD))
    raw = read_trajectory(BONN_CROWD / "groundtruth.txt")
    assert seq.camera.name == "bonn"
    assert np.allclose(seq.groundtruth.poses, raw.poses @ T)


def test_kept_frames_share_what_runs_derive_and_runs_on_them_equal_fresh_ones(scene):
    """The batch's runs of a sequence share each kept frame's ORB keypoints, masks, depth layers,
    paper A's pre-removal and paper C's removal (Frame.derive): runs with other settings on the same kept frames must still equal
    runs on freshly read frames, and a frame with other pixels must not inherit them."""
    from dataclasses import replace

    from dynslam_lite.io import KeptSequence
    from dynslam_lite.pipeline import run_method

    path = scene("walking_carry", 12)
    kept = KeptSequence(open_sequence(path))
    runs = [("bgrestore", {"frontend.orb.n_features": 600}, "oracle"), ("bgrestore", None, "oracle"),
            ("bgrestore", {"removal.frame_gap": 2}, "oracle"), ("bgrestore", {"restore": False}, "oracle"),
            ("weightedstatic", None, "oracle:all"), ("depthcluster", {"max_edge_run": 4}, "none"),
            ("depthcluster", {"preremoval.threshold": 0.2}, "none"), ("depthcluster", None, "none")]
    for method, params, masks in runs:
        shared = run_method(method, kept, params, masks=masks).trajectory.poses
        fresh = run_method(method, open_sequence(path), params, masks=masks).trajectory.poses
        assert np.array_equal(shared, fresh), (method, params, masks)
    frame = kept[3]
    assert {k[0] for k in frame.derived} == {"orb", "masks", "depth_layers", "removal", "preremoval"}
    assert len([k for k in frame.derived if k[0] == "orb"]) == 2  # one per ORB setting
    assert 0 < kept.derived_left[0] < 1 << 30  # what is kept counts against the budget
    tight = KeptSequence(open_sequence(path), derived_bytes=150_000)  # room for two keypoint sets only
    assert np.array_equal(run_method("bgrestore", tight, masks="oracle").trajectory.poses,
                          run_method("bgrestore", open_sequence(path), masks="oracle").trajectory.poses)
    assert 0 < sum(len(f.derived) for f in tight._kept.values()) < len(tight) and tight.derived_left[0] >= 0
    assert replace(frame, rgb=frame.rgb[::-1].copy()).derived is None
    assert open_sequence(path)[3].derived is None  # nothing kept outside KeptSequence
    # what is kept of a pair is kept per pair: the same current frame against another reference
    from dynslam_lite.depthcluster import DepthClusterConfig, DepthClusterMethod
    from dynslam_lite.timing import StageTimer

    for ref in (1, 2, 0):
        pre = [DepthClusterMethod(seq.camera, DepthClusterConfig()).track(seq[ref], seq[5], np.eye(4), StageTimer())
               .labels.masks["preremoval"] for seq in (kept, open_sequence(path))]
        assert np.array_equal(*pre), ref


def test_a_reused_derived_value_charges_its_making_time_to_the_run_that_reuses_it(scene):
    """Frame.derive: the first run makes the value (its own stage times it), a later run on the
    kept frame gets the same object and is charged the milliseconds the making took, so ms/frame
    stays what a method costs alone; a frame that keeps nothing makes the value each time."""
    import time

    from dynslam_lite.io import KeptSequence
    from dynslam_lite.timing import StageTimer

    calls = []

    def make():
        calls.append(1)
        time.sleep(0.03)
        return np.arange(4.0)

    frame = KeptSequence(open_sequence(scene("static_xyz", 4)))[1]
    first, again = StageTimer(), StageTimer()
    value = frame.derive(("test",), make, first, "stage")
    assert first.frame.get("stage", 0.0) == 0.0 and len(calls) == 1
    assert frame.derive(("test",), make, again, "stage") is value and len(calls) == 1
    assert 30.0 <= again.frame["stage"] < 1000.0  # the making's time, not the lookup's
    assert not value.flags.writeable  # shared between runs: read-only
    plain = open_sequence(scene("static_xyz", 4))[1]
    other = StageTimer()
    plain.derive(("test",), make, other, "stage")
    plain.derive(("test",), make, other, "stage")
    assert len(calls) == 3 and other.frame.get("stage", 0.0) == 0.0
