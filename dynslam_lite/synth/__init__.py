"""Synthetic dynamic RGB-D benchmark: a textured office with walking or seated people, written
in the TUM layout with exact ground-truth poses and moving-object masks."""
from .generator import SYNTH_CAMERA, SceneRenderer, SynthStats, ensure_scene, generate
from .scene import EXPOSURE_SCENES, OBJECT_SCENES, SCENES, TUM_SCENES

__all__ = ["EXPOSURE_SCENES", "OBJECT_SCENES", "SCENES", "TUM_SCENES", "SYNTH_CAMERA", "SceneRenderer", "SynthStats", "ensure_scene", "generate"]
