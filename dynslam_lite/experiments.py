"""Experiments as data: which method runs on which sequences, with which masks and parameters.

One typed table read by the batch (:mod:`dynslam_lite.batch`), the results tables
(:mod:`dynslam_lite.tables`), notebook 90 and the tests. A run's label (the 'method' column of
every table, e.g. ``weightedstatic[oracle:degraded]``) is written here and nowhere else: to add a
run, add a :class:`Run` and put it in a :class:`RunSet`; to add a method, register it in
:data:`dynslam_lite.pipeline.METHODS` and add its runs here.

Results travel as :class:`RunRecord` (what ran where and what it measured), saved as
``trajectories/runs.json`` by the batch and read back by notebook 90.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from .evaluation import ErrorStats, MaskScores, TrajectoryErrors
from .synth.scene import EXPOSURE_SCENES, OBJECT_SCENES, TUM_SCENES

# The semantic mask source a run takes from its data: the synthetic ground truth split into
# instances (what a perfect person detector gives), and on real data the bundled person model.
SEMANTIC = "semantic"
SEMANTIC_SOURCE = {"synthetic": "oracle", "real": "person"}


@dataclass(frozen=True)
class Run:
    """One configuration of a method.

    Attributes
    ----------
    label : the name in the tables (unique)
    method : a key of :data:`dynslam_lite.pipeline.METHODS`
    masks : a mask source spec (:mod:`dynslam_lite.masks`), or :data:`SEMANTIC`
    params : config overrides, as ``--set key=value`` takes them
    description : what the configuration is, for the ablation tables
    """

    label: str
    method: str
    masks: str = "none"
    params: tuple[tuple[str, Any], ...] = ()
    description: str = ""

    def mask_source(self, kind: str) -> str:
        """The mask source spec on data of ``kind`` ('synthetic' or 'real')."""
        return SEMANTIC_SOURCE[kind] if self.masks == SEMANTIC else self.masks

    @property
    def overrides(self) -> dict[str, Any]:
        return dict(self.params)


def _run(label: str, method: str, masks: str = "none", description: str = "", **params) -> Run:
    return Run(label, method, masks, tuple(params.items()), description)


# ---------------------------------------------------------------- the runs
STATIC_DENSE = _run("static-dense", "static-dense", description="DVO-like dense baseline (paper A's DVO)")
OPENCV_ODOMETRY = _run("opencv-odometry", "opencv-odometry",
                       description="cv2.Odometry RGB-D, frame to frame, as OpenCV's defaults call it (COMMON)")
OPENCV_FAST = Run("opencv-odometry[fast]", "opencv-odometry", "none", (("algorithm", "fast"),),
                  "cv2.Odometry with OdometryAlgoType_FAST, otherwise the defaults")
DEPTHCLUSTER = _run("depthcluster", "depthcluster", description="paper A with every addition of ours (default)")
STATIC_ORB = _run("static-orb", "static-orb", description="no masks (static-orb)")
WEIGHTEDSTATIC = _run("weightedstatic", "weightedstatic", SEMANTIC,
                      "oracle (synthetic) / person model (real) masks + geometric test + weights")
BGRESTORE = _run("bgrestore", "bgrestore", SEMANTIC, "paper C with oracle (synthetic) / person model (real) masks")

# paper A's ablation: the paper alone (every addition of ours off), then each addition by itself
# (the release of explained pixels changes the reported mask only: its columns show it, no run needed)
_NO_PRIOR, _NO_GROW, _NO_CUT = ("propagate", False), ("outlier.grow", False), ("preremoval.max_region_fraction", 1.0)
_NO_RELEASE, _NO_SELECT = ("release", False), ("select_margin", 0.0)
_NO_BRIGHTNESS, _NO_GATE = ("dense.affine_brightness", False), ("dense.max_depth_diff_m", 0.0)
DC_PAPER = Run("depthcluster[paper]", "depthcluster", "none",
               (_NO_PRIOR, _NO_GROW, _NO_CUT, _NO_SELECT, _NO_RELEASE, _NO_BRIGHTNESS, _NO_GATE),
               "paper A only: every addition of ours off")
DC_PRIOR = Run("depthcluster[paper+prior]", "depthcluster", "none",
               (_NO_GROW, _NO_CUT, _NO_SELECT, _NO_RELEASE, _NO_BRIGHTNESS, _NO_GATE),
               "+ the previous pair's moving mask as a prior of the first estimate (propagate)")
DC_GROW = Run("depthcluster[paper+grow]", "depthcluster", "none",
              (_NO_PRIOR, _NO_CUT, _NO_SELECT, _NO_RELEASE, _NO_BRIGHTNESS, _NO_GATE),
              "+ whole depth-layer regions taken in the background update (outlier.grow)")
DC_CUT = Run("depthcluster[paper+cut]", "depthcluster", "none",
             (_NO_PRIOR, _NO_GROW, _NO_SELECT, _NO_RELEASE, _NO_BRIGHTNESS, _NO_GATE),
             "+ pre-removal regions over 25 % of the image cut to the dynamic blocks (max_region_fraction)")
DC_BRIGHTNESS = Run("depthcluster[paper+brightness]", "depthcluster", "none",
                    (_NO_PRIOR, _NO_GROW, _NO_CUT, _NO_SELECT, _NO_RELEASE, _NO_GATE),
                    "+ a gain and bias of the image brightness estimated with the pose (dense.affine_brightness)")
DC_GATE = Run("depthcluster[paper+gate]", "depthcluster", "none",
              (_NO_PRIOR, _NO_GROW, _NO_CUT, _NO_SELECT, _NO_RELEASE, _NO_BRIGHTNESS),
              "+ correspondences whose depths differ by over 7 cm left out of the solver (dense.max_depth_diff_m)")
DC_NO_SELECT = Run("depthcluster[no-select]", "depthcluster", "none", (_NO_SELECT,),
                   "the default without the pose selection: always the last estimate (select_margin = 0)")
DC_NO_BRIGHTNESS = Run("depthcluster[no-brightness]", "depthcluster", "none", (_NO_BRIGHTNESS,),
                       "the default without the brightness model: eq. 5's photometric term as printed")
DC_NO_GATE = Run("depthcluster[no-gate]", "depthcluster", "none", (_NO_GATE,),
                 "the default without the depth gate: every correspondence in the solver, eq. 5 as printed")

# paper B's ablation: masks alone, then the geometric test and the weights on degraded masks
STATIC_ORB_ORACLE = _run("static-orb[oracle]", "static-orb", "oracle", "masks only, oracle")
STATIC_ORB_DEGRADED = _run("static-orb[oracle:degraded]", "static-orb", "oracle:degraded", "masks only, degraded")
STATIC_ORB_PERSON = _run("static-orb[person]", "static-orb", "person", "masks only, person model")
WS_DEGRADED_GEOMETRY = Run("weightedstatic[oracle:degraded,geometry]", "weightedstatic", "oracle:degraded",
                           (("use_weights", False),), "degraded masks + geometric test")
WS_DEGRADED_WEIGHTS = Run("weightedstatic[oracle:degraded,weights]", "weightedstatic", "oracle:degraded",
                          (("use_geometry", False),), "degraded masks + weights")
WS_DEGRADED = _run("weightedstatic[oracle:degraded]", "weightedstatic", "oracle:degraded",
                   "degraded masks + geometric test + weights")
WS_NONE = _run("weightedstatic[none]", "weightedstatic", "none", "no masks, geometric test + weights")

# paper C's choices: removal without restoration, the paper's adjacent frames, no masks
BG_NO_RESTORE = _run("bgrestore[no-restore]", "bgrestore", SEMANTIC, "removal without restoration", restore=False)
BG_MAP_RESTORED = _run("bgrestore[map-restored]", "bgrestore", SEMANTIC,
                       "restored keypoints become map points too (ORB-SLAM2 on the restored frames)",
                       map_restored=True)
BG_ADJACENT = Run("bgrestore[adjacent]", "bgrestore", "oracle", (("removal.frame_gap", 1),),
                  "the paper's adjacent frames for the epipolar vote")
BG_NONE = _run("bgrestore[none]", "bgrestore", "none", "no masks (removes nothing)")
BG_ALL_VIEWS = Run("bgrestore[all-views]", "bgrestore", "oracle", (("views", 0),),
                   "every keyframe restores every hole pixel (eq. 9 as printed; default: the newest that reaches it)")
BG_TWO_VIEWS = Run("bgrestore[2-views]", "bgrestore", "oracle", (("views", 2),),
                   "each hole pixel restored from the newest 2 keyframes that reach it")

# where people cover most of the image: wider removed instances leave fewer measured matches, and
# the frontend's support check (ours) against a pose step pulled away by the few that are left
BG_WIDE = Run("bgrestore[dilate=15]", "bgrestore", SEMANTIC, (("removal.dilate_px", 15),),
              "removed instances dilated by 15 px instead of 10")
BG_WIDE_NO_CHECK = Run("bgrestore[dilate=15,no-support-check]", "bgrestore", SEMANTIC,
                       (("removal.dilate_px", 15), ("frontend.support_check", 0.0)),
                       "removed instances dilated by 15 px, without the frontend's support check")

# the object scenes (carried, pushed, still and crowding objects): what each step adds over masks
_SCREEN = "frontend.screen_new_points"  # the frontend's free-space screening of new keypoints (ours)
STATIC_ORB_CONSISTENT = Run("static-orb[oracle,consistent]", "static-orb", "oracle", (("consistent_pose", True),),
                            "masks only, pose on the PnP-RANSAC-consistent matches (ours)")
WS_EQ4 = Run("weightedstatic[eq4-only]", "weightedstatic", SEMANTIC,
             (("geometric.free_space", False), (_SCREEN, False)),
             "masks + geometric test + weights, eq. 4 only: no free-space test (of matches or of new keypoints)")
WS_NO_DILATE = Run("weightedstatic[no-dilation]", "weightedstatic", SEMANTIC,
                   (("frontend.mask_dilate_px", 0),),
                   "masks + geometric test + weights, masks as the source gives them (not dilated by 10 px)")
WS_NO_SCREEN = Run("weightedstatic[no-screening]", "weightedstatic", SEMANTIC,
                   ((_SCREEN, False),),
                   "masks + geometric test + weights, every new keypoint with depth becomes a map point")
WS_PAPER_FIRST = Run("weightedstatic[orb-first-pose]", "weightedstatic", "oracle", (("frontend.consistent_pose", False),),
                     "masks + geometric test + weights, first pose by ORB-SLAM2's optimisation")
BG_CONSISTENT = Run("bgrestore[consistent]", "bgrestore", SEMANTIC, (("frontend.consistent_pose", True),),
                    "paper C with the pose on the PnP-RANSAC-consistent matches (ours)")
BG_INSTANCES = Run("bgrestore[instances-only]", "bgrestore", SEMANTIC,
                   (("removal.drop_unsegmented", False), (_SCREEN, False)),
                   "paper C as printed: only instances voted on, every match outside them tracked, "
                   "every new keypoint a map point")
BG_NO_SCREEN = Run("bgrestore[no-screening]", "bgrestore", SEMANTIC, ((_SCREEN, False),),
                   "paper C with our removal of unsegmented matches; every new keypoint with depth "
                   "becomes a map point")
BG_ALL = _run("bgrestore[oracle:all]", "bgrestore", "oracle:all",
              "every object instance voted on (paper C's Mask R-CNN classes), not people only")
# a person detector that loses the people close to the camera for a while (oracle:missed): what
# keeps an unmasked person out of the map, where people crowd
_MISSED = "oracle:missed"
STATIC_ORB_MISSED = _run("static-orb[oracle:missed]", "static-orb", _MISSED,
                         "masks only, near people missed in 12 of every 36 frames")
STATIC_ORB_MISSED_SCREEN = Run("static-orb[oracle:missed,screening]", "static-orb", _MISSED,
                               (("screen_new_points", True),),
                               "masks only, near people missed; with the frontend's screening of new keypoints (ours)")
WS_MISSED_NO_SCREEN = Run("weightedstatic[oracle:missed,no-screening]", "weightedstatic", _MISSED, ((_SCREEN, False),),
                          "masks + geometric test + weights, near people missed; no screening of new keypoints")
WS_MISSED = _run("weightedstatic[oracle:missed]", "weightedstatic", _MISSED,
                 "masks + geometric test + weights, near people missed")
BG_MISSED_NO_SCREEN = Run("bgrestore[oracle:missed,no-screening]", "bgrestore", _MISSED, ((_SCREEN, False),),
                          "paper C, near people missed; no screening of new keypoints")
BG_MISSED = _run("bgrestore[oracle:missed]", "bgrestore", _MISSED, "paper C, near people missed")
STATIC_ORB_MOVING = _run("static-orb[oracle:moving]", "static-orb", "oracle:moving",
                         "masks of every moving object from the ground truth: the bound of any moving-object handling")

# the same runs with the keypoint budget 1 % lower and higher, on the real clips and our object
# scenes, which says how far one run's ATE moves when nothing that should matter changes
_BUDGETS = (990, 1010)
_KP = "frontend.orb.n_features"
SENSITIVITY_OF = {  # base run -> its runs with the budgets of _BUDGETS, in that order
    WEIGHTEDSTATIC: (
        Run("weightedstatic[orb.n_features=990]", "weightedstatic", SEMANTIC, ((_KP, 990),), "990 ORB keypoints"),
        Run("weightedstatic[orb.n_features=1010]", "weightedstatic", SEMANTIC, ((_KP, 1010),), "1010 ORB keypoints")),
    BGRESTORE: (
        Run("bgrestore[orb.n_features=990]", "bgrestore", SEMANTIC, ((_KP, 990),), "990 ORB keypoints"),
        Run("bgrestore[orb.n_features=1010]", "bgrestore", SEMANTIC, ((_KP, 1010),), "1010 ORB keypoints")),
}
SENSITIVITY = tuple(r for runs in SENSITIVITY_OF.values() for r in runs)


@dataclass(frozen=True)
class RunSet:
    """Runs made on a group of sequences: named synthetic scenes (``scenes``; None = every scene
    of the profile) or every real sequence (``real``), taken every ``stride``-th frame (real
    sequences only: 3 turns a 30 Hz recording into 10 Hz, with three times the motion between
    frames)."""

    name: str
    runs: tuple[Run, ...]
    scenes: tuple[str, ...] | None = None
    real: bool = False
    stride: int = 1

    def covers(self, kind: str, scene: str | None, stride: int = 1) -> bool:
        if stride != self.stride:
            return False
        if kind == "real":
            return self.real
        return not self.real and (self.scenes is None or scene in self.scenes)


# our object scenes: masks alone, with the consistent pose, paper B, paper C (restoration off, restored
# keypoints mapped, person-only and all-class masks), and the truth's moving-object masks as the bound
OBJECT_ROWS = (STATIC_ORB, STATIC_ORB_ORACLE, STATIC_ORB_CONSISTENT, WS_PAPER_FIRST, WS_EQ4, WS_NO_DILATE,
               WS_NO_SCREEN, WEIGHTEDSTATIC, BG_INSTANCES, BG_NO_SCREEN, BGRESTORE, BG_NO_RESTORE, BG_MAP_RESTORED,
               BG_CONSISTENT, BG_ALL, STATIC_ORB_MOVING)
# the same where the mask source misses the near people for a while (the crowd)
MISSED_ROWS = (STATIC_ORB_MISSED, STATIC_ORB_MISSED_SCREEN, WS_MISSED_NO_SCREEN, WS_MISSED, BG_MISSED_NO_SCREEN,
               BG_MISSED)
# ... and on the real clips: the person model losing the near people in the same frames (static-orb[person:missed],
# static-orb[person:missed,screening], weightedstatic[person:missed,no-screening], weightedstatic[person:missed],
# bgrestore[person:missed,no-screening], bgrestore[person:missed])
MISSED_REAL_ROWS = tuple(Run(r.label.replace(_MISSED, "person:missed"), r.method, "person:missed", r.params,
                             r.description.replace("near people missed", "person model, near people missed"))
                         for r in MISSED_ROWS)
# papers B and C on the real clips: masks alone, each paper's steps switched off one at a time
REAL_BC_ROWS = (STATIC_ORB, STATIC_ORB_PERSON, WS_NONE, WS_EQ4, WS_NO_DILATE, WS_NO_SCREEN, WEIGHTEDSTATIC, BG_NONE,
                BG_INSTANCES, BG_NO_SCREEN, BGRESTORE, BG_NO_RESTORE, BG_MAP_RESTORED, BG_CONSISTENT, BG_WIDE,
                BG_WIDE_NO_CHECK, *MISSED_REAL_ROWS)
# the methods on walking_exposure (the same runs exist on walking_xyz, the same frames at one exposure)
EXPOSURE_ROWS = (STATIC_DENSE, OPENCV_ODOMETRY, DC_NO_BRIGHTNESS, DEPTHCLUSTER, STATIC_ORB, WEIGHTEDSTATIC, BGRESTORE)
# paper A's ablation runs (the default is run anyway)
DC_ABLATION = (DC_PAPER, DC_PRIOR, DC_GROW, DC_CUT, DC_BRIGHTNESS, DC_GATE, DC_NO_SELECT, DC_NO_BRIGHTNESS,
               DC_NO_GATE)
# the methods of the summary figure; at lower frame rates depthcluster without its pose selection,
# its brightness model and its depth gate too
MAIN = (STATIC_DENSE, OPENCV_ODOMETRY, STATIC_ORB, DEPTHCLUSTER, WEIGHTEDSTATIC, BGRESTORE)
FRAME_RATE_ROWS = (STATIC_DENSE, OPENCV_ODOMETRY, STATIC_ORB, DC_NO_SELECT, DC_NO_BRIGHTNESS, DC_NO_GATE,
                   DEPTHCLUSTER, WEIGHTEDSTATIC, BGRESTORE)
WALKING = ("walking_xyz", "walking_halfsphere", "walking_rpy", "walking_static")
RUN_SETS = (
    RunSet("baselines and papers A, B", (STATIC_DENSE, OPENCV_ODOMETRY, DEPTHCLUSTER, STATIC_ORB, WEIGHTEDSTATIC),
           scenes=TUM_SCENES),
    RunSet("OpenCV's FAST variant", (OPENCV_FAST,), scenes=("static_xyz", "walking_xyz")),
    RunSet("paper A ablation", DC_ABLATION, scenes=WALKING),
    # paper A where people crowd (one close to the camera) and carry or push things: class-agnostic
    # removal with the truth to score it, against its baselines
    RunSet("paper A on the object scenes", (STATIC_DENSE, OPENCV_ODOMETRY, DEPTHCLUSTER), scenes=OBJECT_SCENES),
    RunSet("paper A ablation where people crowd", DC_ABLATION,
           scenes=("crowd",)),
    RunSet("paper B ablation", (STATIC_ORB_ORACLE, STATIC_ORB_DEGRADED, WS_DEGRADED_GEOMETRY, WS_DEGRADED_WEIGHTS,
                                WS_DEGRADED, WS_NONE), scenes=("walking_xyz", "walking_rpy")),
    RunSet("paper C", (BGRESTORE,), scenes=WALKING),  # paper C's tables cover the walking scenes
    RunSet("paper C ablation", (BG_NO_RESTORE, BG_MAP_RESTORED, BG_ADJACENT, BG_TWO_VIEWS, BG_ALL_VIEWS),
           scenes=("walking_xyz",)),
    # our object scenes: papers B and C where people carry and push things, stand still, crowd
    RunSet("object scenes", OBJECT_ROWS, scenes=OBJECT_SCENES),
    RunSet("missed detections", MISSED_ROWS, scenes=("crowd",)),
    # walking_xyz seen by a camera with automatic exposure: what a brightness change costs each method
    RunSet("automatic exposure", EXPOSURE_ROWS, scenes=tuple(EXPOSURE_SCENES)),
    RunSet("sensitivity on the object scenes", SENSITIVITY, scenes=OBJECT_SCENES),
    # real data: the bundled person model (a stand-in for the papers' networks), and without masks
    RunSet("real data", (STATIC_DENSE, OPENCV_ODOMETRY, OPENCV_FAST, DEPTHCLUSTER, STATIC_ORB, WEIGHTEDSTATIC, BGRESTORE,
                         STATIC_ORB_PERSON, WS_NONE, BG_NONE, BG_CONSISTENT, WS_EQ4, BG_INSTANCES, WS_NO_DILATE,
                         WS_NO_SCREEN, BG_NO_SCREEN, BG_NO_RESTORE, BG_MAP_RESTORED, BG_WIDE, BG_WIDE_NO_CHECK),
           real=True),
    # a detector that misses the near people for a while, on real people with true poses
    RunSet("missed detections on real data", MISSED_REAL_ROWS, real=True),
    RunSet("paper A ablation on real data", DC_ABLATION, real=True),
    RunSet("sensitivity on real data", SENSITIVITY, real=True),
    # the real clips at a lower frame rate: larger motion between frames, the hard moments of
    # longer clips (fast turns, motion blur) in a short one
    RunSet("real data, every 2nd frame", FRAME_RATE_ROWS, real=True, stride=2),
    RunSet("real data, every 3rd frame", FRAME_RATE_ROWS, real=True, stride=3),
)

# rows of paper A's ablation table, in order (the default last: every addition on)
PAPER_A_ABLATION = (*DC_ABLATION, DEPTHCLUSTER)
# rows of paper B's ablation table, in order
PAPER_B_ABLATION = (STATIC_ORB, STATIC_ORB_ORACLE, STATIC_ORB_DEGRADED, STATIC_ORB_PERSON, WS_DEGRADED_GEOMETRY,
                    WS_DEGRADED_WEIGHTS, WS_DEGRADED, WEIGHTEDSTATIC, WS_NONE)
# the papers' baselines: DVO (paper A) and ORB-SLAM2 (papers B and C)
STATIC_BASELINES = (STATIC_DENSE, STATIC_ORB)


def runs_for(kind: str, scene: str | None = None, stride: int = 1) -> list[Run]:
    """Every run on a sequence of ``kind`` ('synthetic' with its ``scene``, or 'real') taken every
    ``stride``-th frame, in the order of :data:`RUN_SETS` (each label once)."""
    out: dict[str, Run] = {}
    for s in RUN_SETS:
        if s.covers(kind, scene, stride):
            for r in s.runs:
                out.setdefault(r.label, r)
    return list(out.values())


def strides() -> tuple[int, ...]:
    """The frame strides of the run sets, 1 first."""
    return tuple(sorted({1, *(s.stride for s in RUN_SETS)}))


def sequence_name(sequence: str, stride: int = 1) -> str:
    """A sequence as progress lines, trajectory folders and tables name it: 'real/<folder>', and
    'real/<folder>/stride3' tracked every 3rd frame."""
    return sequence if stride == 1 else f"{sequence}/stride{stride}"


def all_runs() -> dict[str, Run]:
    """Every run of the registry by label."""
    return {r.label: r for s in RUN_SETS for r in s.runs}


# ---------------------------------------------------------------- results
@dataclass
class RunRecord:
    """One run of the batch: what ran on which sequence, and what it measured.

    Attributes
    ----------
    sequence : 'synthetic/<scene>' or 'real/<folder>'
    label, method, masks : the :class:`Run` (masks resolved for the data)
    path : the sequence folder (relative to the repository root where possible)
    frames : frames tracked
    errors : ATE and 1-s RPE against ground truth
    failed_frames : frames whose tracking failed
    ms_per_frame : mean wall-clock time per frame; stages: ms per frame of each stage
    extras : the method's own statistics (on a scene with automatic exposure also
        :func:`~dynslam_lite.evaluation.exposure_pair_errors`); scores: its verdicts against ground truth
        (:attr:`dynslam_lite.pipeline.RunResult.scores`); scored_points: keypoints scored
    trajectory : the estimate's file, relative to ``trajectories/``
    stride : the sequence was tracked every ``stride``-th frame (1: every frame)
    """

    sequence: str
    label: str
    method: str
    masks: str
    path: str
    frames: int
    errors: TrajectoryErrors
    failed_frames: int = 0
    ms_per_frame: float = 0.0
    stages: dict[str, float] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)
    scores: dict[str, MaskScores] = field(default_factory=dict)
    scored_points: int = 0
    trajectory: str = ""
    stride: int = 1

    @property
    def name(self) -> str:
        """The sequence with its stride (:func:`sequence_name`)."""
        return sequence_name(self.sequence, self.stride)

    @property
    def is_real(self) -> bool:
        return self.sequence.startswith("real/")

    def score(self, key: str) -> MaskScores | None:
        """Score ``key`` when anything was counted (else None)."""
        s = self.scores.get(key)
        return s if s is not None and s.counted else None

    def to_json(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["errors"] = self.errors.as_dict()
        d["scores"] = {k: asdict(v) for k, v in self.scores.items()}
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> "RunRecord":
        d = dict(d)
        e = d["errors"]
        stats = [ErrorStats(**{k: (math.nan if v is None else v) for k, v in e[key].items()})
                 for key in ("ate_m", "rpe_trans_m_per_s", "rpe_rot_deg_per_s")]
        d["errors"] = TrajectoryErrors(*stats, e["matched_poses"])
        d["scores"] = {k: MaskScores(**v) for k, v in d.get("scores", {}).items()}
        return cls(**d)


def runs_json(records: list[RunRecord]) -> str:
    """Text of ``runs.json`` for ``records``."""
    return json.dumps([r.to_json() for r in records], indent=1) + "\n"


def read_runs(runs_dir: str | Path) -> list[RunRecord]:
    """The records of ``runs_dir/runs.json`` (written by the batch)."""
    path = Path(runs_dir) / "runs.json"
    return [RunRecord.from_json(d) for d in json.loads(path.read_text(encoding="utf-8"))]
