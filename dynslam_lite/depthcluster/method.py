"""Paper A's pipeline on one frame pair, and the ``depthcluster`` method for the runner.

For a reference frame A and the current frame B (paper fig. 1):

1. depth layers of A by k-means (:mod:`.clustering`);
2. pre-removal from the change of depth between A and B (:mod:`.preremoval`);
3. pose T_B_A by the dense photometric + lambda_I * depth Gauss-Newton (eq. 5) on the static
   pixels of A (:func:`dynslam_lite.odometry.dense.align` with ``mask_ref``);
4. background update (:mod:`.background`): residual outliers of the pose leave the static set,
   the pose is re-estimated from the previous one, ``update_iterations`` times (7 in the paper).

Ours, each measured in ``tables/paper_a_ablation.md``: the previous pair's mask as a prior of the
first estimate (``propagate``), whole depth-layer regions in the update (``outlier.grow``), the
cut of oversized pre-removal regions (``preremoval.max_region_fraction``), the choice of the
reported pose among the prediction and the pair's estimates (``select_margin``), a gain and bias
of the image brightness estimated with the pose (``dense.affine_brightness``), and a last release
of the removed pixels the final pose explains (``release``: the reported mask, not the pose).

Measured and not adopted (2026-12-04, prototypes outside the package, single runs, ATE RMSE):
a keyframe as the reference instead of the previous frame (new keyframe every N frames), Bonn
dev clip N = 1 (today) 0.0986, 2: 0.100, 3: 0.128, 5: 0.226 m, also worse with a new keyframe
when the removed area grows; synthetic walking_static N = 3 0.0120 -> 0.0017, walking_xyz 0.0286
-> 0.0256 m. Pre-removal compares the two depth images unwarped, so a longer baseline leaves it
less to see (without pre-removal N = 3 beats N = 1 on Bonn dev: 0.314 against 0.456 m).

Measured and not adopted (2026-12-05, with the brightness model): the update's residual images at
the solver's finest level (half resolution, upsampled to the mask by nearest neighbour) instead of
full resolution: 1.17x -> 1.07x opencv-odometry on the first 40 Bonn dev frames (3 rounds in
lockstep), not the 1.0x asked for; ATE Bonn dev every frame / 2nd / 3rd / 4th 0.0911 / 0.0826 /
0.1093 / 0.1259 -> 0.0929 / 0.0786 / 0.1010 / 0.1278 m, fr2/desk 0.0071 -> 0.0077, synthetic crowd
0.0715 -> 0.0816, walking_xyz 0.0294 -> 0.0272 m: mixed, within a single run's spread.

Measured and not adopted (2026-12-05, for speed, ATE RMSE Bonn dev every frame / 3rd, synthetic
crowd): the pre-removal block statistics from every 2nd row and column (about 2 ms a frame),
0.0911 / 0.1093 / 0.0715 -> 0.0914 / 0.1416 / 0.0802 m (a flipped block decision changes the
pair); the updates on the half-resolution level only (``refine_levels`` 2), 0.0946 / 0.1068 /
0.0820 m.

Measured and not adopted (2026-12-07, for speed, ATE RMSE Bonn dev every frame / 2nd / 3rd,
synthetic crowd, walking_xyz, walking_halfsphere; today 0.0911 / 0.0818 / 0.0792 / 0.0535 /
0.0198 / 0.0153 m): an earlier stop of the updates (``stable_fraction`` 0.005: 0.0930 / 0.0816 /
0.0799 / 0.1149 / 0.0198 / 0.0153; 0.01: 0.0953 / 0.0808 / 0.0798 / 0.1278 / 0.0198 / 0.0152);
each Gauss-Newton level stopped once an accepted step lowers the cost by less than a fraction
of it (a fifth of the levels end with a step that raises it and is undone): 1e-3, 13-17 % fewer
cost evaluations, 0.0912 / 0.0822 / 0.1153 / 0.1126 / 0.0198 / 0.0151; 1e-4, 5-8 % fewer,
0.0911 / 0.0816 / 0.0799 / 0.0585 / 0.0197 / 0.0152 m, and 1.16x / 1.15-1.16x opencv-odometry
against 1.16-1.21x without (60 Bonn dev frames, two 3-round bench runs each): within the spread.

Measured on a longer synthetic crowd (2026-12-07, 570 frames = 19 s, as long as the longer real
clip; ``python -m dynslam_lite synth --scene crowd --frames 570 DIR``): ATE RMSE 0.136 m against
0.0535 at 150 frames. The error comes in bursts: frames 124-127 and 373-376 are 33-52 mm off each
against a median of 1.7 mm. In the first, a near person fills the left half and is removed by
pre-removal, and a second person enters at the right border, is missed and takes the pose along.
It starts at frame 121, where pre-removal with the prior leaves under ``min_static_fraction``
static: the pair falls back to every pixel, its update starts from the pre-removal mask again and
is rejected, and the next pairs lose their prior. Not adopted, both within the spread: the
updates starting from the fallback (Bonn dev 0.0911 -> 0.0907, synthetic crowd 0.0535 -> 0.0562,
crowd at 570 frames 0.1358 -> 0.1385 m); and falling back to the prior alone before every pixel,
with the updates starting from it (0.0865, 0.0724, 0.1548 m). The prior itself is wide: it
carries the pose's whole removed mask (``excluded``, 40-60 % of the image in the crowd), not the
moving one; the moving one as the prior does not narrow the removal (pose mask 0.488 -> 0.481
of the Bonn dev image: pre-removal takes most of it) and moves ATE within the spread (Bonn dev
0.0911 -> 0.0945, crowd 0.0535 -> 0.0588, walking_xyz 0.0198 -> 0.0204, walking_halfsphere
0.0153 -> 0.0149, walking_static 0.0123 -> 0.0134, crowd at 570 frames 0.1358 -> 0.1337 m).

The solver leaves out correspondences whose two depths differ by more than 7 cm (ours,
``dense.max_depth_diff_m``, OpenCV's ``maxDepthDiff``; measured in :class:`DepthClusterConfig`):
where the masks miss a surface that occludes or uncovers the room, it cannot pull the pose.
"""
from __future__ import annotations

import dataclasses
from contextlib import nullcontext
from dataclasses import astuple, dataclass, field

import cv2
import numpy as np

from ..checks import depth as check_depth, image01
from ..geometry import PinholeCamera, invert, rotation_angle_deg, warp_coordinates
from ..odometry.dense import DenseConfig, align
from ..tracking import Labels, Method, Tracked
from ..imageops import disk
from .background import OutlierConfig, current_samples, outliers, release, residuals
from .clustering import DepthClusters, cluster_depth, layer_components
from .preremoval import PreRemoval, PreRemovalConfig, pre_remove


@dataclass
class DepthClusterConfig:
    """All parameters of paper A, the paper's values as defaults.

    Attributes
    ----------
    n_clusters : depth layers; 0 = eq. 1, floor((D_max - D_min) / D_sd)
    max_clusters : upper clamp of eq. 1 (a few far outliers can inflate D_max)
    max_edge_run : longest zero run at an edge filled from the right (pixels)
    preremoval : the block test (sec. 3), see :class:`PreRemovalConfig`
    use_preremoval : False skips step 2 (ablation)
    dense : the Gauss-Newton solver of step 3 (lambda_I = ``dense.lambda_depth``); here with
        ``affine_brightness`` on (ours): the pose and a gain and bias of the reference intensities
        are estimated together, and the background update, the pose selection and the release
        read the residuals under that gain and bias. A camera with automatic exposure changes the
        brightness of the whole image between two frames (the Bonn dev clip every 10-13 frames, by
        up to 19 grey levels), and an uncompensated change turns most of the static room into
        photometric outliers. Measured (2026-12-05, ATE RMSE, this default without / with it):
        Bonn dev clip 0.0986 / 0.0911 m, every 2nd frame 0.1087 / 0.0826, every 3rd 0.1442 /
        0.1093, every 4th 0.2404 / 0.1259; TUM fr2/desk 0.0071 / 0.0071; synthetic walking_xyz
        0.0286 / 0.0294, walking_halfsphere 0.0157 / 0.0153, static_xyz 0.0055 / 0.0050 (no
        exposure change there: the differences are those of another numerical path); on
        walking_exposure (walking_xyz under a known gain and bias changing every 10-13 frames)
        the frame-to-frame error of the pairs across a change 4.3 / 1.7 mm (other pairs 2.1),
        ATE 0.0280 / 0.0312 m: clean depth holds the whole trajectory either way. Added to
        the paper alone (every other addition off) it made the Bonn dev clip worse, 0.1090 ->
        0.1342 m (one run, cause not investigated). And with ``max_depth_diff_m`` 0.07 (ours,
        OpenCV's default): a correspondence whose two depths differ by more than 7 cm is left out
        of the solver; the masks miss people entering at the border and the room behind a
        person who just left, and each such pixel still pulls the pose under the Huber weights.
        Measured (2026-12-08, single runs, ATE RMSE without / with it; the mean frame-to-frame
        translation error in brackets): on sequences not used to try the variants: walking_rpy
        0.0249 / 0.0176, sitting_xyz 0.0108 / 0.0076, sitting_halfsphere 0.0170 / 0.0122,
        sitting_rpy 0.0146 / 0.0095, static_xyz 0.0050 / 0.0053, walking_carry 0.0413 / 0.0341,
        walking_push 0.1019 / 0.0407, walking_exposure 0.0217 / 0.0088, crowd at 300 frames seeds 2
        and 3 0.0573 / 0.0273 and 0.0845 / 0.0761, the Bonn dev clip every 2nd frame from frame 1
        0.0779 / 0.0688 (21.6 / 20.7 mm), every 3rd from frames 1 and 2 0.1147 / 0.0780 (34.3 /
        27.6 mm) and 0.1290 / 0.0707 (29.5 / 21.0 mm); and on the sequences the earlier choices
        were made on: Bonn dev every frame 0.0878 / 0.1013 (11.1 / 10.0 mm), every 2nd 0.0729 /
        0.0670, 3rd 0.0788 / 0.0622, 4th 0.1100 / 0.1210, fr2/desk 0.0071 / 0.0077, synthetic crowd
        0.0469 / 0.0646, crowd at 570 frames 0.1293 / 0.0989, crowd at 300 frames seed 1 0.0611 /
        0.0378, walking_xyz 0.0198 / 0.0083, walking_halfsphere 0.0153 / 0.0117, walking_static
        0.0123 / 0.0071. Better on 19 of 24 sequences, the per-pair error lower almost everywhere;
        the Bonn dev clip at full rate drifts more (its per-pair error is lower). About 4 % more
        time per frame. Not tuned: 7 cm is OpenCV's value; the variants tried (5 % or 3 % of the
        depth, 15 cm, occluding surfaces only, the photometric term only, only where pre-removal
        left too little) were no better overall on the sequences they were tried on; the two
        finest levels only was as good on those and worse on the Bonn frames from 1 and 2
    update_iterations : background updates after the first estimate (7 in the paper)
    refine_levels : pyramid levels of each update, which starts from the previous pose
        (3 = quarter resolution down to ``dense.finest_level``)
    outlier : the residual test of step 4, see :class:`OutlierConfig`
    accumulate : removed pixels stay removed in later iterations (the paper's reading: each
        iteration "removes part of the moving objects again"); False re-derives them each time
    stable_fraction : stop early when an update would change fewer than this fraction of the
        pixels (no new estimate is made), or changed them and the pose by less than
        0.1 mm / 0.01 deg (the paper sees convergence after ~4); 0 runs all iterations
    min_static_fraction : fewer static pixels than this (fraction of valid depth) = the update
        is rejected and the previous estimate kept
    propagate : the runner carries the moving mask of each pair into the next reference frame
        as a prior for the first estimate (:func:`propagate_mask`); not in the paper, which treats
        each pair on its own: a person walking slowly gives the depth test little to see
    select_margin : the reported pose is the last estimate unless the prediction ``T_init`` or an
        earlier estimate of the pair explains the reference image clearly better: a median
        absolute photometric residual (:func:`median_residual`) lower by more than this
        fraction; 0 = off (ours, LMedS-style: the static room is most of the image, so a pose
        that followed the people or lost the floor to pre-removal leaves most pixels misaligned).
        Measured with depthcluster's defaults, per frame pair against the ground truth, mean /
        largest translation error: Bonn dev clip 1.38 / 10.7 -> 1.29 / 5.1 cm, every 2nd frame
        2.79 / 24.7 -> 2.54 / 14.6 cm, every 3rd 5.33 / 27.1 -> 4.29 / 26.6 cm, every 4th
        8.11 / 48.2 -> 5.65 / 24.5 cm, the dev clip played backwards 1.85 / 36.3 -> 1.53 /
        17.8 cm; unchanged on the synthetic walking scenes and crowd. ATE RMSE there: dev
        0.076 -> 0.099 m (its errors with the last estimates partly cancel), the others
        0.116 -> 0.109, 0.217 -> 0.144, 0.412 -> 0.240, 0.203 -> 0.129 m. 0.25 rather than
        0.15: at 0.15 noise-level differences replaced estimates on synthetic crowd (ATE 0.119
        -> 0.147 m)
    select_min_gradient : the selection's median reads only the reference pixels whose intensity
        gradient is at least this ([0, 1] per pixel; 0.02 = 5 grey levels; 0 = every pixel with
        depth). A flat wall gives the same noise-level residual at every pose near the truth, and
        most of a room is flat: on synthetic crowd (300 frames, seed 1) an unremoved person pulled
        pairs 121-127 4-5 cm off while the true prediction's median over every pixel was only
        10-15 % lower, on the textured pixels 30-50 % lower
    select_depth : a pose replaces the last estimate only if its median absolute depth residual
        (same grid, every pixel with depth) is not higher: the photometric term alone must not
        overrule both terms of eq. 5 (on the Bonn dev clip its minimum is biased, see
        :class:`~dynslam_lite.odometry.dense.DenseConfig`). Measured (2026-12-06, ATE RMSE,
        before / both / ``select_min_gradient`` 0.02 alone / ``select_depth`` alone): Bonn dev
        every frame 0.0911 / 0.0911 / 0.1196 / 0.0911, every 2nd 0.0826 / 0.0818 / 0.0907 /
        0.0682, 3rd 0.1093 / 0.0792 / 0.1263 / 0.1141, 4th 0.1259 / 0.1278 (mean per-pair error
        4.54 -> 3.60 cm) / - / -; synthetic crowd 0.0715 / 0.0535 / 0.0545 / 0.0715, walking_xyz
        0.0294 / 0.0198 / 0.0198 / 0.0294, walking_carry 0.0494 / 0.0413, walking_rpy 0.0254 /
        0.0249, crowd 300 frames seed 1 0.0897 / 0.0611, seed 2 0.0892 / 0.0573; unchanged on
        fr2/desk, static_xyz, walking_static, walking_halfsphere, walking_push, sitting_xyz,
        sitting_halfsphere. With the depth test, gradient 0.01 / 0.04: Bonn 3rd 0.0792 / 0.1141,
        crowd 0.0715 / 0.0718, crowd 300 seed 1 0.0816 / 0.0608; the rest as at 0.02
    select_far_m : a candidate more than this far (metres, translation) from the last estimate
        replaces it when its median is lower at all, not by ``select_margin`` (ours): the margin
        keeps noise-level differences between nearby poses from replacing estimates, but two
        poses centimetres apart are two hypotheses (the room's, and one a missed person pulled
        the solver to), and the median tells them apart. 0 = the margin for every candidate.
        Measured (2026-12-08, ATE RMSE, 0 / 0.02 / 0.01 m): Bonn dev every frame 0.0911 / 0.0878 /
        0.0905, 2nd 0.0818 / 0.0729 / 0.0737, 3rd 0.0792 / 0.0788 / 0.0788, 4th 0.1278 / 0.1100
        / 0.1100; synthetic crowd 0.0535 / 0.0469 / 0.0469 (pair 124: a person entering at the
        right border took the estimate 36 mm off, the prediction 3.8 mm off scored 0.0291
        against 0.0362, within the margin), crowd at 570 frames 0.1358 / 0.1293 / 0.1394, crowd
        300 frames seed 1 0.0611 / 0.0611 / 0.0610; unchanged on fr2/desk, walking_xyz,
        walking_halfsphere, walking_static. The later pairs of that burst (125-127) stay 38-52
        mm off: there the median prefers the estimate that follows the person to the
        prediction, whose rotation is off too
    release : the reported moving mask is the pose's mask less the pixels the final pose explains
        (:func:`.background.release`; ours): pre-removal and the update must over-remove for the
        pose (a wall sharing the person's layer, the blurred outline), the reader should see the
        person removed, not the floor. The pose and the prior keep the unreleased mask.
    """

    n_clusters: int = 0
    max_clusters: int = 12
    max_edge_run: int = 12
    preremoval: PreRemovalConfig = field(default_factory=PreRemovalConfig)
    use_preremoval: bool = True
    dense: DenseConfig = field(default_factory=lambda: DenseConfig(affine_brightness=True, max_depth_diff_m=0.07))
    update_iterations: int = 7
    refine_levels: int = 3
    outlier: OutlierConfig = field(default_factory=OutlierConfig)
    accumulate: bool = True
    stable_fraction: float = 0.002
    min_static_fraction: float = 0.15
    propagate: bool = True
    select_margin: float = 0.25
    select_min_gradient: float = 0.02
    select_depth: bool = True
    select_far_m: float = 0.02
    release: bool = True


@dataclass
class Iteration:
    """One pose estimate of the pair: iteration 0 after pre-removal, then each update.

    Attributes
    ----------
    T_cur_ref : (4, 4) pose after this iteration
    removed : (H, W) bool, reference pixels excluded from this iteration's estimate
    residual : (H, W) photometric residual of this pose (only when recorded), NaN where undefined
    tau : photometric outlier threshold derived from this pose's residuals
    static_fraction : fraction of valid-depth pixels used
    ok, reason : outcome of the solver
    score : :func:`median_residual` of this pose (the pose selection, ``select_margin``; NaN
        when not computed)
    brightness : (gain, bias) estimated with this pose (``dense.affine_brightness``), else None
    """

    T_cur_ref: np.ndarray
    removed: np.ndarray
    residual: np.ndarray | None
    tau: float
    static_fraction: float
    ok: bool
    reason: str = ""
    score: float = float("nan")
    brightness: tuple[float, float] | None = None


@dataclass
class PairResult:
    """Paper A on one frame pair.

    Attributes
    ----------
    T_cur_ref : final pose estimate; ok/reason: whether it can be trusted
    clusters : depth layers of the reference frame
    preremoval : the block test (None when skipped)
    iterations : every pose estimate, first one first
    moving : (H, W) bool, final moving-object mask on the reference pixels
    excluded : (H, W) bool, the reference pixels the final pose was estimated without (``moving``
        plus what the release gave back; the same as ``moving`` without release)
    warp : ``warp_coordinates`` of the reference depth under the final pose, when computed
    chosen : which pose is reported: 'last estimate', 'prediction' or 'estimate k' (an earlier
        iteration, ``iterations[k]``), see ``DepthClusterConfig.select_margin``
    """

    T_cur_ref: np.ndarray
    ok: bool
    reason: str
    clusters: DepthClusters
    preremoval: PreRemoval | None
    iterations: list[Iteration]
    moving: np.ndarray
    excluded: np.ndarray
    warp: tuple | None = None
    chosen: str = "last estimate"


def _layers(depth: np.ndarray, cfg: DepthClusterConfig) -> DepthClusters:
    return cluster_depth(depth, cfg.n_clusters or None, max_edge_run=cfg.max_edge_run,
                         max_clusters=cfg.max_clusters)


SCORE_STEP = 4  # the pose selection scores every 4th row and column (19 200 pixels at 640 x 480)


def median_residual(r_i: np.ndarray, valid: np.ndarray) -> float:
    """Median |r| over the ``valid`` reference pixels of every ``SCORE_STEP``-th row and column
    where the residual is defined (inf where none is): how well a pose explains the reference
    image (r_I) or depth (r_D) when most of it is static. ``r_i`` is the whole residual image or
    its grid (``residuals(..., step=SCORE_STEP)``); ``valid`` the whole image's."""
    grid = valid[::SCORE_STEP, ::SCORE_STEP]
    a = np.abs(r_i if r_i.shape == grid.shape else r_i[::SCORE_STEP, ::SCORE_STEP])[grid]
    a = a[np.isfinite(a)]
    return float(np.median(a)) if a.size else float("inf")


def clearly_better(T_o: np.ndarray, score_o: float, T_last: np.ndarray, score_last: float,
                   cfg: DepthClusterConfig) -> bool:
    """Whether a candidate pose (score ``score_o``) replaces the last estimate (``score_last``):
    lower by more than ``select_margin``, or lower at all when the two poses are more than
    ``select_far_m`` apart (the depth test of ``select_depth`` comes after)."""
    apart = cfg.select_far_m > 0 and np.linalg.norm((invert(T_last) @ T_o)[:3, 3]) > cfg.select_far_m
    return score_o * (1.0 + (0.0 if apart else cfg.select_margin)) < score_last


def _textured(gray: np.ndarray, valid: np.ndarray, min_gradient: float) -> np.ndarray:
    """``valid`` on the pose selection's grid (every ``SCORE_STEP``-th row and column; False
    elsewhere) less the pixels whose intensity gradient (central differences, the border
    replicated, [0, 1] per pixel) is below ``min_gradient``; ``valid`` itself when it is 0."""
    if min_gradient <= 0:
        return valid
    H, W = gray.shape
    rows, cols = np.arange(0, H, SCORE_STEP), np.arange(0, W, SCORE_STEP)
    on_rows = gray[rows]
    gu = on_rows[:, np.minimum(cols + 1, W - 1)] - on_rows[:, np.maximum(cols - 1, 0)]
    gv = gray[np.minimum(rows + 1, H - 1)][:, cols] - gray[np.maximum(rows - 1, 0)][:, cols]
    out = np.zeros(valid.shape, bool)
    out[::SCORE_STEP, ::SCORE_STEP] = valid[::SCORE_STEP, ::SCORE_STEP] & (np.hypot(gu, gv) * 0.5 >= min_gradient)
    return out


def estimate_pair(
    gray_ref: np.ndarray, depth_ref: np.ndarray, gray_cur: np.ndarray, depth_cur: np.ndarray,
    camera: PinholeCamera, T_init: np.ndarray | None = None, config: DepthClusterConfig | None = None,
    clusters_ref: DepthClusters | None = None, filled_cur: np.ndarray | None = None,
    prior: np.ndarray | None = None, record: bool = False, timer=None, shared: dict | None = None,
    preremoval: PreRemoval | None = None,
) -> PairResult:
    """Run the four steps of paper A on frames A (reference) and B (current).

    Parameters
    ----------
    gray_ref, gray_cur : (H, W) float32 intensity in [0, 1]
    depth_ref, depth_cur : (H, W) float32 metres, 0 = invalid
    T_init : initial guess of T_cur_ref (identity if None)
    clusters_ref, filled_cur : reuse layers / hole-filled depth computed earlier (the runner
        clusters each frame once)
    prior : (H, W) bool, moving pixels of A predicted from the previous pair (see
        :func:`propagate_mask`); excluded from the first estimate only, so a wrong prior cannot
        persist: the updates re-derive the moving pixels from the residuals
    record : keep the residual image of every iteration (notebooks)
    timer : optional :class:`dynslam_lite.pipeline.StageTimer`
    shared : the alignments' dict of this pair (:func:`dynslam_lite.odometry.dense.align`), when
        the caller wants its pyramids or brings the reference frame's
    preremoval : step 2's result for this pair with ``config.preremoval``, made earlier (the
        runner keeps it with the frame, :meth:`~dynslam_lite.io.Frame.derive`)
    """
    image01("gray_ref", gray_ref)
    image01("gray_cur", gray_cur, gray_ref.shape)
    check_depth("depth_ref", depth_ref, gray_ref.shape)
    check_depth("depth_cur", depth_cur, gray_ref.shape)
    cfg = config or DepthClusterConfig()
    stage = timer.stage if timer is not None else (lambda name: nullcontext())
    with stage("cluster"):
        if clusters_ref is None:
            clusters_ref = _layers(depth_ref, cfg)
        if filled_cur is None:
            filled_cur = _layers(depth_cur, cfg).filled
    valid = depth_ref > 0
    n_valid = max(int(valid.sum()), 1)
    scored = _textured(gray_ref, valid, cfg.select_min_gradient) if cfg.select_margin > 0 else valid

    def static_fraction(removed: np.ndarray) -> float:
        return np.count_nonzero(valid & ~removed) / n_valid

    pre = None
    removed = np.zeros(depth_ref.shape, bool)
    if cfg.use_preremoval:
        with stage("preremove"):
            pre = pre_remove(clusters_ref, filled_cur, cfg.preremoval) if preremoval is None else preremoval
            removed = pre.mask.copy()
    base = removed.copy()
    if prior is not None:
        removed |= prior
    if static_fraction(removed) < cfg.min_static_fraction:
        removed = base.copy()  # prior and pre-removal took nearly everything: do not trust them
    if static_fraction(removed) < cfg.min_static_fraction:
        removed[:] = False
    shared = {} if shared is None else shared  # pyramids of the pair, built by the first alignment
    with stage("align_0"):
        r = align(gray_ref, depth_ref, gray_cur, depth_cur, camera, T_init, ~removed, cfg.dense, shared,
                  validate=False)
    its: list[Iteration] = []
    if not r.ok:
        its.append(Iteration(r.T_cur_ref, removed, None, float("nan"), 0.0, False, r.reason))
        return PairResult(r.T_cur_ref, False, r.reason, clusters_ref, pre, its, removed, removed)
    T = r.T_cur_ref
    ab = r.brightness if cfg.dense.affine_brightness else None  # the pair's gain and bias
    refine = dataclasses.replace(cfg.dense, levels=min(cfg.refine_levels, cfg.dense.levels),
                                 iterations=cfg.dense.iterations[-min(cfg.refine_levels, cfg.dense.levels):])
    comps = layer_components(clusters_ref) if cfg.outlier.grow else None
    last: tuple = (None,)  # (pose, r_I, r_D, warp) of the latest residual images
    samples = current_samples(gray_cur, depth_cur)  # what the residuals sample, once per pair
    for k in range(cfg.update_iterations + 1):
        if k == cfg.update_iterations and not record:
            its.append(Iteration(T, removed, None, float("nan"), static_fraction(removed), True, brightness=ab))
            break
        with stage(f"update_{k + 1}"):
            last = _residuals(gray_ref, depth_ref, gray_cur, depth_cur, camera, T, samples, ab,
                              depth=cfg.outlier.depth_outliers)
            _, r_i, r_d, _ = last
            score = median_residual(r_i, scored) if cfg.select_margin > 0 else float("nan")
            out, tau = outliers(r_i, r_d, depth_ref, valid & ~removed, cfg.outlier, comps)
        its.append(Iteration(T, removed, r_i if record else None, tau, static_fraction(removed), True, score=score,
                             brightness=ab))
        if k == cfg.update_iterations:
            break
        new_removed = ((removed if k else base) | out) if cfg.accumulate else (base | out)
        if static_fraction(new_removed) < cfg.min_static_fraction:
            its[-1].reason = "update rejected: too few static pixels left"
            break
        changed = np.count_nonzero(new_removed != removed) / removed.size
        if cfg.stable_fraction > 0 and changed < cfg.stable_fraction:
            # the mask is stable: an estimate on nearly the same pixels from the same pose
            # would not move, so it is not computed
            its[-1].reason = "converged"
            removed = new_removed
            break
        with stage(f"update_{k + 1}"):
            rr = align(gray_ref, depth_ref, gray_cur, depth_cur, camera, T, ~new_removed, refine, shared, ab,
                       validate=False)
        if not rr.ok:
            its[-1].reason = f"update rejected: {rr.reason}"
            break
        dT = np.linalg.inv(T) @ rr.T_cur_ref
        small = np.linalg.norm(dT[:3, 3]) < 1e-4 and rotation_angle_deg(dT[:3, :3]) < 0.01
        T, removed = rr.T_cur_ref, new_removed
        if ab is not None:
            ab = rr.brightness
        if cfg.stable_fraction > 0 and changed < cfg.stable_fraction and small:
            its.append(Iteration(T, removed, None, tau, static_fraction(removed), True, "converged", brightness=ab))
            break
    chosen = "last estimate"
    if cfg.select_margin > 0:
        with stage("select"):
            def score(T_k: np.ndarray, ab_k, depth: bool = False) -> float:
                r_k = residuals(gray_ref, depth_ref, gray_cur, depth_cur, camera, T_k, samples=samples,
                                step=SCORE_STEP, brightness=ab_k, intensity=not depth, depth=depth)
                return median_residual(r_k[1], valid) if depth else median_residual(r_k[0], scored)

            for it in its:  # its[-1] is the last estimate T
                if np.isnan(it.score):
                    it.score = score(it.T_cur_ref, it.brightness)
            T_pred = np.eye(4) if T_init is None else np.asarray(T_init, float)
            # the prediction has no brightness of its own: the last estimate's is the pair's best
            options = [("prediction", T_pred, removed, score(T_pred, ab), ab)] + [
                (f"estimate {k}", it.T_cur_ref, it.removed, it.score, it.brightness) for k, it in enumerate(its[:-1])]
            better = [o for o in options if clearly_better(o[1], o[3], T, its[-1].score, cfg)]
            if better and cfg.select_depth:  # and not contradicted by the depth residuals
                d_last = score(T, None, depth=True)
                better = [o for o in better if score(o[1], None, depth=True) <= d_last]
            if better:
                chosen, T, removed, _, ab = min(better, key=lambda o: o[3])
    moving = removed
    if cfg.release:
        with stage("release"):
            if last[0] is not T:  # the pose moved since the last residuals
                last = _residuals(gray_ref, depth_ref, gray_cur, depth_cur, camera, T, samples, ab)
            elif last[2] is None:  # the updates read r_I only
                r_d = residuals(gray_ref, depth_ref, gray_cur, depth_cur, camera, T, last[3], samples,
                                intensity=False)[1]
                last = (T, last[1], r_d, last[3])
            moving = release(removed, last[1], last[2], depth_ref, cfg.outlier,
                             comps if comps is not None else layer_components(clusters_ref))
    return PairResult(T, True, "", clusters_ref, pre, its, moving, removed, last[3] if last[0] is T else None,
                      chosen)


def _residuals(gray_ref, depth_ref, gray_cur, depth_cur, camera, T, samples, brightness=None, depth=True) -> tuple:
    """(T, r_I, r_D, warp): the whole residual images of the pose T (with the pair's
    ``brightness``; r_D None unless ``depth``, see :func:`.background.residuals`) and its warp."""
    warp = warp_coordinates(camera, depth_ref, T)
    return (T, *residuals(gray_ref, depth_ref, gray_cur, depth_cur, camera, T, warp, samples, brightness=brightness,
                          depth=depth), warp)


def propagate_mask(moving: np.ndarray, depth_ref: np.ndarray, camera: PinholeCamera,
                   T_cur_ref: np.ndarray, close_px: int = 5, warp: tuple | None = None) -> np.ndarray:
    """Moving pixels of the reference frame carried into the current frame with the pose.

    Each moving pixel with depth is projected into the current image (nearest pixel); the
    scattered result is closed morphologically. Objects move a few pixels between frames, so
    this is a prior for the next pair, not a mask. ``warp``: the whole image's
    ``warp_coordinates`` under ``T_cur_ref`` when the caller has it.
    """
    H, W = moving.shape
    if warp is not None:
        mu, mv = warp[0][moving], warp[1][moving]
    else:
        v, u = np.nonzero(moving & (depth_ref > 0))  # only the moving pixels
        mu, mv, _ = warp_coordinates(camera, depth_ref[v, u], T_cur_ref, (u, v))
    ok = np.isfinite(mu)
    u, v = np.rint(mu[ok]).astype(int), np.rint(mv[ok]).astype(int)
    inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
    out = np.zeros((H, W), np.uint8)
    out.reshape(-1)[v[inside] * W + u[inside]] = 1
    k = disk(close_px)
    return cv2.dilate(cv2.morphologyEx(out, cv2.MORPH_CLOSE, k), k).astype(bool)


class DepthClusterMethod(Method):
    """Method ``depthcluster`` for :func:`dynslam_lite.pipeline.run_method`.

    Clusters every frame once (the current frame's layers are the next pair's reference
    layers). Each pair's labels are the final moving mask and the pre-removal mask of the
    reference frame ('final', 'preremoval', and 'pose': what the pose was estimated without); its
    detail is the :class:`PairResult`.
    """

    name = "depthcluster"
    config_type = DepthClusterConfig

    def __init__(self, camera: PinholeCamera, config: DepthClusterConfig):
        self.camera, self.config = camera, config
        self._cache: tuple[float, np.ndarray, DepthClusters] | None = None  # the last frame's
        self._prior: tuple[float, np.ndarray] | None = None
        self._pyramids: tuple[float, tuple] | None = None  # the last current frame's, for the next pair
        self.iterations_used: list[int] = []
        self.replaced = 0  # pairs whose reported pose is not the last estimate (select_margin)
        self.area = np.zeros(3)  # sums over pairs of the removed fraction: pre-removal, final, pose

    def _prepare(self, frame, timer) -> tuple[np.ndarray, DepthClusters]:
        """The frame's intensity in [0, 1] and its depth layers, computed once per frame (the
        current frame of one pair is the reference of the next; the layers are kept with the
        frame where it keeps them, :meth:`~dynslam_lite.io.Frame.derive`)."""
        if self._cache is not None and self._cache[0] == frame.timestamp:
            return self._cache[1:]
        layers = frame.derive(self._layers_key(), lambda: _layers(frame.depth, self.config), timer, "cluster")
        self._cache = (frame.timestamp, frame.gray.astype(np.float32) / 255.0, layers)
        return self._cache[1:]

    def _layers_key(self) -> tuple:
        cfg = self.config
        return ("depth_layers", cfg.n_clusters, cfg.max_clusters, cfg.max_edge_run)

    def track(self, ref, cur, T_init, timer) -> Tracked:
        with timer.stage("cluster"):
            gray_ref, c_ref = self._prepare(ref, timer)
            gray_cur, c_cur = self._prepare(cur, timer)
        pre = None
        if self.config.use_preremoval:  # a function of the pair's layers: kept with the current frame
            with timer.stage("preremove"):
                key = ("preremoval", astuple(self.config.preremoval), self._layers_key(), ref.index)
                pre = cur.derive(key, lambda: pre_remove(c_ref, c_cur.filled, self.config.preremoval), timer, "preremove")
        prior = None
        if self._prior is not None and self._prior[0] == ref.timestamp:
            prior = self._prior[1]
        shared = {}
        if self._pyramids is not None and self._pyramids[0] == ref.timestamp:
            shared["ref_pyramids"] = self._pyramids[1]
        res = estimate_pair(gray_ref, ref.depth, gray_cur, cur.depth, self.camera, T_init,
                            self.config, c_ref, c_cur.filled, prior, timer=timer, shared=shared,
                            preremoval=pre)
        if "pyramids" in shared:
            self._pyramids = (cur.timestamp, shared["pyramids"][2:])
        if self.config.propagate and res.ok:
            with timer.stage("propagate"):
                self._prior = (cur.timestamp, propagate_mask(res.excluded, ref.depth, self.camera,
                                                             res.T_cur_ref, warp=res.warp))
        self.iterations_used.append(len(res.iterations) - 1)
        self.replaced += res.chosen != "last estimate"
        self.area += [0.0 if res.preremoval is None else res.preremoval.mask.mean(), res.moving.mean(),
                      res.excluded.mean()]
        labels = Labels(ref.index, {"final": res.moving, "pose": res.excluded})
        if res.preremoval is not None:
            labels.masks["preremoval"] = res.preremoval.mask
        return Tracked(res.T_cur_ref, res.ok, res.reason, labels=labels, detail=res)

    def extras(self) -> dict:
        """Mean background updates (re-estimates) per pair, and the mean fraction of the reference
        pixels removed by pre-removal, excluded from the pose, and reported as moving in the end
        (whether or not anything moves), and the fraction of pairs whose reported pose is the
        prediction or an earlier estimate (``select_margin``)."""
        n = max(len(self.iterations_used), 1)
        return {"mean_updates": float(np.mean(self.iterations_used)) if self.iterations_used else 0.0,
                "pose_replaced_fraction": self.replaced / n,
                "removed_area_preremoval": float(self.area[0] / n), "removed_area_final": float(self.area[1] / n),
                "removed_area_pose": float(self.area[2] / n)}

