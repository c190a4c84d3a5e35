"""The shared RGB-D feature frontend of papers B and C (ORB-SLAM2-like, without loop closing)."""
from .frontend import Estimate, FeatureTracker, FrontendConfig, Keyframe, PointMap, TrackedFrame
from .matching import match_descriptors, search_by_projection
from .optimize import CHI2_MONO, CHI2_STEREO, Observations, local_bundle_adjustment, optimize_pose
from .orb import Features, ORBConfig, extract, frame_keypoints

__all__ = [
    "Estimate", "FeatureTracker", "FrontendConfig", "Keyframe", "PointMap", "TrackedFrame",
    "match_descriptors", "search_by_projection", "CHI2_MONO", "CHI2_STEREO", "Observations",
    "local_bundle_adjustment", "optimize_pose", "Features", "ORBConfig", "extract",
    "frame_keypoints",
]
