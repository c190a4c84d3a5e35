"""Paper C (bgrestore, "BR-SLAM"): semantic + epipolar removal of moving objects, keyframe-based
RGB and depth restoration of the removed regions, depth region growing with 3-class Otsu
thresholds, and tracking on the restored frames. One module per step."""
from .depthfill import DepthFill, depth_to_gray, fill_depth_hole, grow_region, otsu3
from .inpaint import KeyframeImage, Restoration, restore_from_keyframes, splat
from .method import BgRestoreConfig, BgRestoreMethod, FrameRestoration
from .removal import Removal, RemovalConfig, decide_removal

__all__ = [
    "DepthFill", "depth_to_gray", "fill_depth_hole", "grow_region", "otsu3", "KeyframeImage",
    "Restoration", "restore_from_keyframes", "splat", "BgRestoreConfig", "BgRestoreMethod",
    "FrameRestoration", "Removal", "RemovalConfig", "decide_removal",
]
