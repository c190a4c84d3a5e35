"""Shared fixtures: real-data paths (skipped when absent) and cached synthetic scenes."""
import os
from pathlib import Path

import pytest

# evo's settings/plot modules write ~/.evo; keep any such write out of the user's home.
os.environ.setdefault("MPLBACKEND", "Agg")

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FR2_DESK = SHARED_DATA / "rgbd_dataset_freiburg2_desk_50"
BONN_CROWD = SHARED_DATA / "rgbd_bonn_crowd_dev"
FR1_GT = SHARED_DATA / "groundtruth_only" / "rgbd_dataset_freiburg1_xyz" / "groundtruth.txt"


def render_clean(renderer, T_w_c, s=None):
    """Noise-free (gray [0, 1], depth m with 0 = none, moving mask) of a SceneRenderer's scene
    seen from ``T_w_c``; people posed at time ``s``, none when ``s`` is None."""
    import numpy as np
    from dynslam_lite.synth.generator import LIGHT_W
    from dynslam_lite.synth.raycast import render

    r = renderer
    groups = [p.boxes(s) for p in r.people] if s is not None else []
    rgb, depth, dyn, _, _ = render(r.camera, T_w_c, r.static, groups, r.textures, LIGHT_W, r.rays)
    gray = (rgb @ np.array([0.299, 0.587, 0.114], np.float32)).astype(np.float32)
    return gray, np.where(np.isfinite(depth), depth, 0).astype(np.float32), dyn


def need(path: Path):
    if not path.exists():
        pytest.skip(f"real data not available: {path} (the shared data folder beside the project)")
    return path


@pytest.fixture(autouse=True, scope="session")
def _isolated_home(tmp_path_factory):
    home = tmp_path_factory.mktemp("home")
    old = os.environ.get("HOME")
    os.environ["HOME"] = str(home)
    yield
    if old is not None:
        os.environ["HOME"] = old


@pytest.fixture(scope="session")
def synth_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("synth")


@pytest.fixture(scope="session")
def scene(synth_cache):
    """scene(name, frames, background=False) -> path of a generated sequence (cached)."""
    from dynslam_lite.synth import ensure_scene

    def make(name, frames, background=False):
        return ensure_scene(synth_cache, name, frames, seed=0, background=background)

    return make


@pytest.fixture(scope="session")
def tiny_tables(tmp_path_factory):
    """{file name: bytes} of the tables of a fresh tiny batch (own run cache, no notebooks): what
    any other tiny batch must write, byte for byte, apart from its wall-clock tables."""
    from dynslam_lite.cli import main

    root = tmp_path_factory.mktemp("tiny")
    assert main(["reproduce", "--profile", "tiny", "--jobs", "2", "--no-notebooks",
                 "--cache", str(root / "cache"), "--reports", str(root / "reports")]) == 0
    return {p.name: p.read_bytes() for p in (root / "reports" / "tables").iterdir()}


def tiny_plan(real_frames: int = 0) -> tuple[int, int]:
    """(runs, frames to track) of the tiny profile, with one real sequence of ``real_frames``
    frames when > 0: from the registry, so a new run of it needs no test edited."""
    from dynslam_lite import experiments as E
    from dynslam_lite.batch import load_registry

    tiny = load_registry()[0]["tiny"]
    runs = frames = 0
    for scene in tiny["scenes"]:
        n = len(E.runs_for("synthetic", scene))
        runs, frames = runs + n, frames + n * tiny["frames"]
    if real_frames:
        for stride in E.strides():
            n = len(E.runs_for("real", None, stride))
            runs, frames = runs + n, frames + n * -(-real_frames // stride)
    return runs, frames
