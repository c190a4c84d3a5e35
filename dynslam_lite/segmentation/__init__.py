"""Real semantic masks of people for papers B and C (mask sources ``person`` and ``onnx:PATH``)."""
from .selfie import PersonMasks, SelfieSegmenter
from .yolo import Letterbox, YoloSegMasks, decode

__all__ = ["PersonMasks", "SelfieSegmenter", "Letterbox", "YoloSegMasks", "decode"]
