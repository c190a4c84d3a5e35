import numpy as np
import pytest

from dynslam_lite import geometry as g


@pytest.mark.parametrize("seed", range(5))
def test_se3_exp_log_round_trip(seed):
    rng = np.random.default_rng(seed)
    xi = np.concatenate([rng.normal(0, 0.5, 3), rng.normal(0, 0.8, 3)])
    T = g.se3_exp(xi)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.allclose(g.se3_log(T), xi, atol=1e-9)


def test_so3_hand_computed_and_near_pi():
    R = g.so3_exp([0, 0, np.pi / 2])
    assert np.allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    w = np.array([0.3, -0.4, 0.5])
    w = w / np.linalg.norm(w) * (np.pi - 1e-7)
    assert np.allclose(g.so3_exp(g.so3_log(g.so3_exp(w))), g.so3_exp(w), atol=1e-6)
    assert np.allclose(g.so3_log(np.eye(3)), 0)


def test_pure_translation_and_inverse():
    T = g.se3_exp([1.0, 2.0, 3.0, 0, 0, 0])
    assert np.allclose(T[:3, 3], [1, 2, 3])
    rng = np.random.default_rng(1)
    Ts = np.stack([g.se3_exp(rng.normal(size=6)) for _ in range(4)])
    assert np.allclose(g.invert(Ts) @ Ts, np.eye(4), atol=1e-12)
    assert np.allclose(g.compose(Ts[0], Ts[1], Ts[2]), Ts[0] @ Ts[1] @ Ts[2])


def test_project_backproject_identity():
    cam = g.PinholeCamera(500.0, 510.0, 320.0, 240.0)
    rng = np.random.default_rng(2)
    u, v, z = rng.uniform(0, 640, 50), rng.uniform(0, 480, 50), rng.uniform(0.5, 5, 50)
    uu, vv = g.project(cam, g.backproject(cam, u, v, z))
    assert np.allclose(uu, u) and np.allclose(vv, v)


def test_identity_intrinsics_constant_depth_gives_exact_grid():
    cam = g.PinholeCamera(1.0, 1.0, 0.0, 0.0, 4, 3)
    pts, idx = g.depth_to_points(cam, np.full((3, 4), 2.0, np.float32))
    v, u = np.divmod(idx, 4)
    assert np.allclose(pts, np.stack([2.0 * u, 2.0 * v, np.full(12, 2.0)], 1))


def test_warp_of_plane_shifts_by_fx_t_over_z():
    """A fronto-parallel plane at 2 m, camera moved 0.1 m along x: image shifts fx*0.1/2 px."""
    cam = g.PinholeCamera(500.0, 500.0, 319.5, 239.5)
    depth = np.full((480, 640), 2.0, np.float32)
    T_cur_ref = g.se3_exp([-0.1, 0, 0, 0, 0, 0])  # current camera 0.1 m to the right
    mu, mv, z = g.warp_coordinates(cam, depth, T_cur_ref)
    u = np.arange(640, dtype=np.float32)[None, :]
    assert np.allclose(mu, u - 25.0, atol=1e-3)
    assert np.allclose(mv, np.arange(480)[:, None], atol=1e-3)
    assert np.allclose(z, 2.0)
    img = np.tile(np.arange(640, dtype=np.float32), (480, 1))
    warped = g.warp_image(cam, img, depth, T_cur_ref)
    assert np.allclose(warped[:, 100:600], img[:, 100:600] - 25.0, atol=1e-2)
    assert np.isnan(warped[:, 0]).all()  # lands outside the current image


def test_pyramid_intrinsics_match_block_averaging():
    cam = g.PinholeCamera(500.0, 500.0, 321.3, 239.8)
    p = np.array([[0.3, -0.2, 2.0]])
    u0, v0 = g.project(cam, p)
    u1, v1 = g.project(cam.scaled(1), p)
    assert np.allclose(u1, (u0 + 0.5) / 2 - 0.5) and np.allclose(v1, (v0 + 0.5) / 2 - 0.5)
    img = np.arange(16, dtype=np.float32).reshape(4, 4)
    assert np.allclose(g.image_pyramid(img, 2)[1], [[2.5, 4.5], [10.5, 12.5]])
    d = np.array([[1, 0, 2, 2], [0, 0, 2, 2], [0, 0, 3, 0], [0, 0, 0, 0]], np.float32)
    assert np.allclose(g.depth_pyramid(d, 2)[1], [[1, 2], [0, 3]])  # zeros are not averaged in


def test_interpolate_is_bilinear():
    img = np.array([[0, 1], [2, 3]], np.float32)
    out = g.interpolate(img, np.array([0.5, 0.25]), np.array([0.5, 0.0]))
    assert np.allclose(out, [1.5, 0.25], atol=1e-3)


@pytest.mark.parametrize("channels", [1, 2, 3, 4, 5, 7, 8])
def test_interpolate_samples_every_channel_count_at_the_exact_position(channels):
    # cv2.remap rounds the position to 1/32 pixel for float images of 2 or > 4 channels (errors
    # up to ~0.02 here); interpolate must give the exact bilinear value for every count
    rng = np.random.default_rng(channels)
    img = rng.random((30, 40, channels)).astype(np.float32)
    u, v = rng.uniform(0, 39, 2000), rng.uniform(0, 29, 2000)
    u0, v0 = np.floor(u).astype(int), np.floor(v).astype(int)
    u1, v1 = np.minimum(u0 + 1, 39), np.minimum(v0 + 1, 29)
    fu, fv = (u - u0)[:, None], (v - v0)[:, None]
    I = img.astype(float)
    exact = (I[v0, u0] * (1 - fu) * (1 - fv) + I[v0, u1] * fu * (1 - fv)
             + I[v1, u0] * (1 - fu) * fv + I[v1, u1] * fu * fv)
    out = g.interpolate(img, u, v)
    assert out.shape == (2000, channels)
    assert np.abs(out - exact).max() < 1e-5
    halves = g.interpolate((img[..., :1].copy(), img[..., 1:].copy()), u, v) if channels > 1 else None
    if halves is not None:  # a tuple of images: the same samples, one array per image
        assert np.array_equal(np.column_stack(halves), out)
