"""Mask source ``person``: the bundled MediaPipe Selfie Segmentation model, run with OpenCV.

A stand-in for the papers' networks (paper B: YOLOv5s-seg, paper C: Mask R-CNN), which cannot be
downloaded here. The model gives one person probability per pixel (no instances, no classes);
instances are split by connected components and depth discontinuities
(:func:`dynslam_lite.imageops.split_instances`). It was trained for people within about 2 m of a
front camera: on real Bonn frames it finds walking people, also fires on some salient static
objects (chairs), and misses strongly motion-blurred people; the papers' geometric checks are meant
to handle both. The synthetic bodies are not photographs of people and it may not fire on them.

Model files (Apache-2.0, see ``models/NOTICE``), checked by sha256 when loaded:

* ``square``: ``selfie_segmentation.tflite``, 256x256 input;
* ``landscape``: ``selfie_segmentation_landscape.tflite``, 256x144 input.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np

from ..io import Frame
from ..errors import ConfigError, SequenceError
from ..imageops import split_instances

MODEL_DIR = Path(__file__).resolve().parent / "models"
MODELS = {  # variant -> (file, (width, height) of the input, sha256)
    "square": ("selfie_segmentation.tflite", (256, 256),
               "9ee168ec7c8f2a16c56fe8e1cfbc514974cbbb7e434051b455635f1bd1462f5c"),
    "landscape": ("selfie_segmentation_landscape.tflite", (256, 144),
                  "a77d03f4659b9f6b6c1f5106947bf40e99d7655094b6527f214ea7d451106edd"),
}


def load_checked(path: Path, sha256: str) -> bytes:
    """Bytes of a model file after checking its sha256 (clear error if missing or altered)."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: model file missing (reinstall the package)")
    data = path.read_bytes()
    if hashlib.sha256(data).hexdigest() != sha256:
        raise SequenceError(f"{path}: sha256 mismatch, the model file is damaged or replaced")
    return data


class SelfieSegmenter:
    """Person probability of an RGB image with the MediaPipe Selfie Segmentation model."""

    def __init__(self, variant: str = "square"):
        if variant not in MODELS:
            raise ConfigError(f"unknown selfie model {variant!r}: use {', '.join(MODELS)}")
        name, self.size, sha = MODELS[variant]
        path = MODEL_DIR / name
        load_checked(path, sha)
        self.net = cv2.dnn.readNetFromTFLite(str(path))

    def probability(self, rgb: np.ndarray) -> np.ndarray:
        """(H, W) float32 in [0, 1] for an (H, W, 3) uint8 RGB image."""
        blob = cv2.dnn.blobFromImage(rgb, 1.0 / 255.0, self.size)  # RGB in, NCHW float
        self.net.setInput(blob)
        p = self.net.forward().reshape(self.size[1], self.size[0])
        return cv2.resize(p, (rgb.shape[1], rgb.shape[0]), interpolation=cv2.INTER_LINEAR)


class PersonMasks:
    """Mask source ``person``: probability > ``threshold``, split into instances.

    Parameters
    ----------
    variant : "square" or "landscape" model
    threshold : person probability above which a pixel is a person
    min_area : instances smaller than this (pixels) are dropped
    split_depth : also cut instances along depth discontinuities
    """

    def __init__(self, variant: str = "square", threshold: float = 0.5, min_area: int = 400,
                 split_depth: bool = True):
        self.name = "person" if variant == "square" else f"person:{variant}"
        self.segmenter = SelfieSegmenter(variant)
        self.threshold = threshold
        self.min_area = min_area
        self.split_depth = split_depth

    def __call__(self, frame: Frame) -> list[np.ndarray]:
        mask = self.segmenter.probability(frame.rgb) > self.threshold
        return split_instances(mask, self.min_area, frame.depth if self.split_depth else None)
