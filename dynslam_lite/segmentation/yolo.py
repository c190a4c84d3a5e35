"""Mask source ``onnx:PATH``: person instances from a YOLOv5-seg or YOLOv8-seg ONNX export.

The papers' own kind of network (paper B uses YOLOv5s-seg). No weights ship with the project;
export one elsewhere (``python export.py --weights yolov5s-seg.pt --include onnx`` in YOLOv5,
``yolo export model=yolov8n-seg.pt format=onnx`` in Ultralytics) and pass its path.

Outputs of such an export for a 640x640 input (letterboxed RGB in [0, 1]):

* detections: YOLOv5-seg ``(1, N, 5 + C + M)`` rows ``[cx, cy, w, h, objectness, C class
  scores, M mask coefficients]``; YOLOv8-seg ``(1, 4 + C + M, N)`` columns ``[cx, cy, w, h,
  C class scores, M coefficients]`` (no objectness); boxes in input pixels;
* prototypes ``(1, M, H/4, W/4)``.

Decoding: score = objectness x class score (v5) or class score (v8), keep the person class (0 in
COCO) above ``conf``, non-maximum suppression (``cv2.dnn.NMSBoxes``), instance mask =
sigmoid(coefficients . prototypes), upsampled to the input, cut to its box, the letterbox removed,
resized to the frame and thresholded at 0.5.

References: YOLACT (Bolya et al. 2019) for prototype masks; Ultralytics YOLOv5/v8 export layouts.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import SequenceError
from ..io import Frame


@dataclass
class Letterbox:
    """Resize-and-pad of a frame into the square network input."""

    scale: float
    pad_x: int
    pad_y: int
    size: int

    @classmethod
    def of(cls, shape: tuple[int, int], size: int) -> "Letterbox":
        h, w = shape
        s = min(size / h, size / w)
        return cls(s, (size - round(w * s)) // 2, (size - round(h * s)) // 2, size)

    def apply(self, rgb: np.ndarray) -> np.ndarray:
        h, w = rgb.shape[:2]
        nw, nh = round(w * self.scale), round(h * self.scale)
        out = np.full((self.size, self.size, 3), 114, np.uint8)  # YOLO's grey padding
        out[self.pad_y:self.pad_y + nh, self.pad_x:self.pad_x + nw] = cv2.resize(rgb, (nw, nh))
        return out

    def undo(self, image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """Network-input-sized image -> frame-sized image."""
        h, w = shape
        nw, nh = round(w * self.scale), round(h * self.scale)
        crop = image[self.pad_y:self.pad_y + nh, self.pad_x:self.pad_x + nw]
        return cv2.resize(crop, (w, h), interpolation=cv2.INTER_LINEAR)


def split_outputs(outputs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, bool]:
    """(detections (N, K) one row per candidate, prototypes (M, h, w), has objectness)."""
    det = next((o for o in outputs if o.ndim == 3), None)
    proto = next((o for o in outputs if o.ndim == 4), None)
    if det is None or proto is None:
        raise ValueError(f"not a YOLO-seg model: outputs {[o.shape for o in outputs]}, expected a "
                         "3-D detection tensor and 4-D prototypes")
    det, proto = det[0], proto[0]
    v8 = det.shape[0] < det.shape[1]  # (4 + C + M, N): channels first
    if v8:
        det = det.T
    if det.shape[1] <= (4 if v8 else 5) + proto.shape[0]:
        raise ValueError(f"detection rows of {det.shape[1]} values leave no class scores for "
                         f"{proto.shape[0]} mask coefficients")
    return det, proto, not v8


def decode(outputs: list[np.ndarray], frame_shape: tuple[int, int], box: Letterbox,
           conf: float = 0.25, iou: float = 0.45, class_id: int = 0) -> list[np.ndarray]:
    """Instance masks (H, W) bool of ``class_id`` from the raw outputs of a YOLO-seg network."""
    det, proto, objectness = split_outputs(outputs)
    m = proto.shape[0]
    head = 5 if objectness else 4
    scores = det[:, head + class_id] * (det[:, 4] if objectness else 1.0)
    best = det[:, head:-m].argmax(axis=1)
    cand = np.flatnonzero((scores >= conf) & (best == class_id))
    if cand.size == 0:
        return []
    cx, cy, bw, bh = det[cand, :4].T
    boxes = np.column_stack([cx - bw / 2, cy - bh / 2, bw, bh])
    keep = np.asarray(cv2.dnn.NMSBoxes(boxes.tolist(), scores[cand].tolist(), conf, iou), int).ravel()
    if keep.size == 0:
        return []
    coeff = det[cand[keep], -m:]
    logits = (coeff @ proto.reshape(m, -1)).reshape(len(keep), *proto.shape[1:])
    prob = 1.0 / (1.0 + np.exp(-logits))
    out = []
    size = box.size
    for p, (x0, y0, w, h) in zip(prob, boxes[keep]):
        up = cv2.resize(p.astype(np.float32), (size, size), interpolation=cv2.INTER_LINEAR)
        inside = np.zeros_like(up)
        xa, ya = int(max(np.floor(x0), 0)), int(max(np.floor(y0), 0))
        xb, yb = int(min(np.ceil(x0 + w), size)), int(min(np.ceil(y0 + h), size))
        inside[ya:yb, xa:xb] = up[ya:yb, xa:xb]
        mask = box.undo(inside, frame_shape) > 0.5
        if mask.any():
            out.append(mask)
    return out


class YoloSegMasks:
    """Mask source ``onnx:PATH`` (see the module docstring)."""

    def __init__(self, path: str | Path, conf: float = 0.25, iou: float = 0.45, class_id: int = 0,
                 size: int = 640):
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: ONNX model not found")
        try:
            self.net = cv2.dnn.readNetFromONNX(str(path))
        except cv2.error as exc:
            raise SequenceError(f"{path}: OpenCV cannot read this ONNX model: {exc}") from None
        self.name = f"onnx:{path}"
        self.conf, self.iou, self.class_id, self.size = conf, iou, class_id, size

    def __call__(self, frame: Frame) -> list[np.ndarray]:
        box = Letterbox.of(frame.rgb.shape[:2], self.size)
        blob = cv2.dnn.blobFromImage(box.apply(frame.rgb), 1.0 / 255.0, (self.size, self.size))
        self.net.setInput(blob)
        outputs = self.net.forward(self.net.getUnconnectedOutLayersNames())
        return decode(list(outputs), frame.rgb.shape[:2], box, self.conf, self.iou, self.class_id)
