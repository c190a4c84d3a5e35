"""Paper B, sec. 3.2: the weighted geometric constraint, beside the plain epipolar test.

For a keypoint p2 of the current frame matched to a point seen at p1 (depth z1) in a reference
keyframe, with the relative pose ``T_cur_ref = [R | t]``:

* epipolar plane normal, current camera frame: ``n = t x (R K^-1 p1)``; the ray ``K^-1 p2``
  of a static point lies in that plane, so ``|cos(n, K^-1 p2)|`` is 0 for it. For rays near
  the optical axis ``|cos| ~ d / f`` with d the pixel distance to the epipolar line.
* predicted depth ``z' = (R z1 K^-1 p1 + t)_z`` against the measured depth z at p2.

``delta = alpha * |cos| + beta * |z - z'| / z'``; ``alpha = sigma2 / sigma1, beta = 1`` when
``|cos| > sigma1`` (far from the epipolar line: dynamic without the depth test), else
``alpha = 0, beta = 1``; dynamic when ``delta >= sigma2``.

Units (our choice, the paper gives no values): the paper adds a cosine to a depth difference in
metres and sets alpha = 1. We make the depth term unitless (relative to the predicted depth, as
the sensor's noise grows with depth) and set alpha = sigma2 / sigma1, which makes the paper's
statement "beyond sigma1 the point is dynamic without computing the depth difference" exact.

* ``sigma1 = 0.005`` ~ 2.7 px from the epipolar line at f = 535 px: about twice the keypoint
  noise at octave 0 plus the pose error of the robust first estimate.
* ``sigma2 = 0.05``: a 5 % depth change (5 cm at 1 m, 20 cm at 4 m), several times the
  structured-light noise (~0.15 % x z / m) so that corners on depth edges, whose depth pixel can
  jump between foreground and background, do not all turn dynamic.

A point moving along its epipolar line keeps ``|cos| ~ 0`` and passes the plain epipolar test;
when its depth changes the depth term catches it, but one moving parallel to the image plane and
to the camera's translation (a board carried across the view while the camera pans) keeps its
depth too, and eq. 4 cannot see it.

A variant (``along_line``, off by default: the method is eq. 4 as printed): an RGB-D reference
observation knows *where* on the epipolar line the point must reappear,
``p' = K (R z1 K^-1 p1 + t)``, so the off-line term can use the angle between the rays to p' and
to p2 (``sin`` of it, as ``|cos|`` is) instead of the distance to the line alone. It equals the
paper's term for motion across the line, also sees motion along it, and needs no baseline; where
the reference has no depth the paper's term is used. Measured on walking_carry (notebook 20):
with the true poses it flags almost every keypoint of the carried board against the latest
keyframe, where eq. 4 flags under half; with the poses the method estimates, whose error against
the reference is of the same size as the board's motion between keyframes, it raises as many
false alarms as it finds, and ATE got worse (0.013 -> 0.019 m on walking_carry, 0.021 -> 0.023 m
on the Bonn dev clip), so it stays off.

Why the test finds few of the carried board's matches (measured on walking_carry, oracle masks,
150 frames): the board's keypoints become map points at a keyframe and are matched in the next
one or two frames, so their only reference is a keyframe 1-2 frames back. Against it, with the
ground-truth relative pose, they sit 4.6 px (median, octave-scaled) from where a static point
would reappear, static matches 0.5 px; with the pose the method estimates, 0.7 px. Where the
static matches are far (the room behind, 3-4 m) they fix the pose only up to the
translation/rotation ambiguity of a small baseline, and the near board (1.5-2 m) pins that
direction: the estimated pose absorbs the board's motion between the two frames, and no test
against it (eq. 4 or the along-line variant) can see it. Thresholds on the reprojection error
against the references give recall 0.72 at precision 0.56 with the true poses, 0.14 at 0.20 with
the estimated ones. Hence the free-space test (ours,
:func:`dynslam_lite.features.freespace.free_space_test`): references that never observed the
point, older keyframes with a longer baseline, test it by their depth images.

The pushed box of walking_push is the other case (measured 2026-12-04, oracle masks): it stands
still for 1 s, so its points are old map points when it starts to move, and 151 of the 352
matched verdicts on it that the truth calls moving fall in the first three frames of the push
(30-32), of which the test flags 2. There the pose takes the box along: all 62 of the box's
matches at frame 31 are inliers, and the frame-to-frame error of the first pose is 26 mm at frame
31 and 21 mm at frame 32 against 1-4 mm before. Judged at that pose the box has hardly moved (the
along-line angle's median 0.002, the static matches' 0.0015), so no threshold on eq. 4, the
along-line variant, the free-space scores or the chi2 separates it. The cure is not in the first
pose alone: with PnP-RANSAC's consensus at 1.5 px instead of 3 px the first pose at frame 31 is
8 mm off, but the joint optimisation over pose and weights takes the final pose back to 25 mm with
every box match an inlier; a consensus of keypoints of octave <= 2 only, or ORB-SLAM2's pose
optimisation, follow the box too (push recall 0.61-0.63 in every variant, single runs).

Why no test of frame 31 alone can do better (measured 2026-12-05, oracle masks): the matches do
not prefer the true pose. Under a truncated quadratic (MSAC, each chi2 capped at the gate), the
true pose costs 721 and the pose that follows the box 480: the room is 3-4 m away and a 27 mm
translation, turned partly into a rotation, moves its points by a fraction of a pixel (median
chi2 0.52 at the true pose), while the box's 61 matches sit 3-4 px off the true pose (median chi2
13). A second hypothesis started from the constant-velocity prediction (4.8 mm off) and scored
by the same cost loses for the same reason (MSAC instead of RANSAC's inlier count: unchanged
verdicts at frames 30-39). Only a motion prior tighter than about 1.5 mm per frame would outweigh
the box, far below what a hand-held camera keeps to. And the 57 box matches of frame 30 count
as moving in the truth, but the box has moved 1.3 mm then (the push starts 2.5 ms before that
frame): below the depth noise, so no test could see them.

Where the other verdicts on the box are lost (the default run, both tests pooled: recall 0.60,
0.68 without frames 30-31): at the keyframes 36, 46 and 56 the screening keeps 57-79 of the box's
new keypoints out of the map and lets 23-34 in. The free-space test sees a point in front of what
a reference saw there; a point of the box's face where the face was in the reference (the box
moves along its face) is not in front of anything. Those points are matched in the next frame
(37, 47, 57: 20-30 misses each), where their only observer is the keyframe one frame back.
Their motion there (18 mm a frame, 2 m away, partly in depth) stays under the thresholds: against
that keyframe their median along-line angle is 0.002-0.011 and depth change 0.004-0.006.
Appearance would see them (measured 2026-12-08, not built): the ORB descriptor at the candidate
against one computed in the latest reference keyframe's image at its reprojection, where that
image's depth agrees: 80 of the 115 box keypoints let in differ by 60 bits or more, but so do 287 of
4925 static candidates. Even if every later miss of those points vanished with them, the pooled
recall would reach 0.79 at precision 0.57: frames 30-32 hold the rest.

References: paper B (weightedstatic), sec. 3.2, eq. 4; paper C eq. 3 for the plain epipolar
distance.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import checks
from ..geometry import PinholeCamera, backproject


@dataclass
class GeometricConfig:
    """Parameters of the weighted geometric test.

    Attributes
    ----------
    sigma1 : |cos(n, K^-1 p2)| above this = off the epipolar plane (alpha on)
    sigma2 : delta at or above this = dynamic
    reference_keyframes : keyframes sharing most points with the frame used as references (5)
    min_baseline_m : a reference closer than this gives no epipolar plane (alpha off)
    along_line : off-line term = angle to the predicted point p' (variant), False = distance to
        the epipolar line (eq. 4, the default)
    free_space : a reference keyframe that has no observation of the point tests it by its depth
        image (:func:`~dynslam_lite.features.freespace.free_space_test`, window
        ``frontend.free_space_window``; ours, False = such a reference gives no verdict)
    """

    sigma1: float = 0.005
    sigma2: float = 0.05
    reference_keyframes: int = 5
    min_baseline_m: float = 0.01
    along_line: bool = False
    free_space: bool = True


def rays(camera: PinholeCamera, uv: np.ndarray) -> np.ndarray:
    """(N, 2) pixels -> (N, 3) rays K^-1 [u, v, 1]."""
    return backproject(camera, uv[:, 0], uv[:, 1], np.ones(len(uv)))


@dataclass
class GeometricTest:
    """Per pair (reference observation, current keypoint) of :func:`weighted_geometric_test`.

    Attributes
    ----------
    cos : (N,) |cos(n, K^-1 p2)|, nan where the baseline is too short
    angle : (N,) sin of the angle between the rays to p' and p2, nan without reference depth
    depth_change : (N,) |z - z'| / z', nan where a depth is missing
    delta : (N,) the score; dynamic : (N,) bool, delta >= sigma2
    off_line : (N,) bool, the off-line term above sigma1 (``cos`` alone: the plain epipolar
        test's verdict, no depth term)
    """

    cos: np.ndarray
    angle: np.ndarray
    depth_change: np.ndarray
    delta: np.ndarray
    dynamic: np.ndarray
    off_line: np.ndarray


def weighted_geometric_test(camera: PinholeCamera, R: np.ndarray, t: np.ndarray, uv_ref: np.ndarray,
                            z_ref: np.ndarray, uv_cur: np.ndarray, z_cur: np.ndarray,
                            config: GeometricConfig | None = None) -> GeometricTest:
    """Paper B's eq. 4 for N correspondences.

    Parameters
    ----------
    R, t : (N, 3, 3), (N, 3) or (3, 3), (3,), ``T_cur_ref`` of each pair
    uv_ref, uv_cur : (N, 2) pixels in the reference and current frames
    z_ref, z_cur : (N,) depth in metres, 0 = none
    """
    checks.points("uv_ref", uv_ref)
    checks.points("uv_cur", uv_cur, len(uv_ref))
    if np.shape(z_ref) != (len(uv_ref),) or np.shape(z_cur) != (len(uv_ref),):
        raise ValueError(f"z_ref {np.shape(z_ref)} and z_cur {np.shape(z_cur)} must be ({len(uv_ref)},) like uv_ref")
    cfg = config or GeometricConfig()
    R = np.broadcast_to(R, (len(uv_ref), 3, 3))
    t = np.broadcast_to(t, (len(uv_ref), 3))
    r1 = np.einsum("nij,nj->ni", R, rays(camera, uv_ref))
    r2 = rays(camera, uv_cur)
    n = np.cross(t, r1)
    norm = np.linalg.norm(n, axis=1) * np.linalg.norm(r2, axis=1)
    ok_plane = (np.linalg.norm(t, axis=1) >= cfg.min_baseline_m) & (norm > 1e-12)
    cos = np.full(len(uv_ref), np.nan)
    cos[ok_plane] = np.abs(np.sum(n * r2, axis=1)[ok_plane] / norm[ok_plane])
    z_pred = z_ref * r1[:, 2] + t[:, 2]
    ok_depth = (z_ref > 0) & (z_cur > 0) & (z_pred > 0)
    dz = np.full(len(uv_ref), np.nan)
    dz[ok_depth] = np.abs(z_cur - z_pred)[ok_depth] / z_pred[ok_depth]
    X = z_ref[:, None] * r1 + t  # the reference point where a static point is now
    ok_ray = (z_ref > 0) & (X[:, 2] > 0)
    angle = np.full(len(uv_ref), np.nan)
    sin = np.linalg.norm(np.cross(X, r2), axis=1) / np.maximum(np.linalg.norm(X, axis=1) * np.linalg.norm(r2, axis=1), 1e-12)
    angle[ok_ray] = sin[ok_ray]
    off = np.nan_to_num(cos)
    if cfg.along_line:
        off = np.where(ok_ray, angle, off)
    off_line = off > cfg.sigma1
    alpha = np.where(off_line, cfg.sigma2 / cfg.sigma1, 0.0)
    delta = alpha * off + np.nan_to_num(dz)
    return GeometricTest(cos, angle, dz, delta, delta >= cfg.sigma2, off_line)
