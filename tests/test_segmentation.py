"""Real mask sources: instance splitting with depth, the bundled person model, and YOLO-seg ONNX
decoding checked on tiny ONNX models with the real output shapes and known outputs."""
import numpy as np
import pytest

from conftest import BONN_CROWD, need
from dynslam_lite.io import Frame, open_sequence
from dynslam_lite.imageops import split_instances
from dynslam_lite.masks import make_mask_source
from dynslam_lite.segmentation import selfie

onnx = pytest.importorskip("onnx", reason="the onnx package builds the test models")
from onnx import TensorProto, helper, numpy_helper  # noqa: E402


def test_split_instances_cuts_overlapping_people_at_the_depth_jump():
    mask = np.zeros((120, 160), bool)
    mask[20:100, 20:90] = mask[30:110, 80:140] = True  # two touching silhouettes
    depth = np.full(mask.shape, 4.0, np.float32)
    depth[30:110, 80:140] = 2.5
    depth[20:100, 20:90] = 1.5  # the left one in front
    assert len(split_instances(mask)) == 1
    parts = split_instances(mask, depth=depth)
    assert len(parts) == 2
    assert np.array_equal(np.logical_or.reduce(parts), mask)  # the cut pixels are given back
    left = parts[int(np.argmax([p[60, 30] for p in parts]))]
    assert left[20:100, 20:90].all() and left.sum() == 80 * 70


def test_person_model_is_checked_and_runs(tmp_path, monkeypatch):
    seg = selfie.SelfieSegmenter()
    rgb = np.zeros((48, 64, 3), np.uint8)
    p = seg.probability(rgb)
    assert p.shape == (48, 64) and p.dtype == np.float32 and 0 <= p.min() <= p.max() <= 1
    bad = tmp_path / "selfie_segmentation.tflite"
    bad.write_bytes(b"not a model")
    monkeypatch.setattr(selfie, "MODEL_DIR", tmp_path)
    with pytest.raises(ValueError, match="sha256 mismatch"):
        selfie.SelfieSegmenter()


def test_person_masks_find_people_on_bonn_crowd():
    seq = open_sequence(need(BONN_CROWD))
    src = make_mask_source("person")
    cover = [sum(m.sum() for m in src(seq[i])) / seq[i].depth.size for i in range(0, 120, 20)]
    # every sampled frame has people walking close to the camera
    assert all(0.05 < c < 0.8 for c in cover), cover


# --------------------------------------------------------------------------- YOLO-seg decoding
PERSON_BOX = (200.0, 280.0, 200.0, 200.0)  # cx, cy, w, h in the 640x640 input: x 100..300, y 180..380
M, C, PH = 32, 80, 160


def _candidates(v8: bool):
    """Rows [cx, cy, w, h, (obj), 80 scores, 32 coefficients]: one person, a weaker duplicate
    (removed by NMS), a chair (other class) and a person below the confidence threshold."""
    head = 4 if v8 else 5
    rows = np.zeros((4, head + C + M), np.float32)
    rows[:, :4] = [PERSON_BOX, (205, 285, 200, 200), (500, 300, 80, 80), (450, 450, 60, 60)]
    if not v8:
        rows[:, 4] = [0.95, 0.9, 0.9, 0.9]
    rows[0, head + 0], rows[1, head + 0], rows[3, head + 0] = 0.9, 0.8, 0.1
    rows[2, head + 56] = 0.9  # chair
    rows[:, head + C] = 1.0  # coefficient of prototype 0
    return rows


def _prototypes():
    proto = np.full((1, M, PH, PH), -8.0, np.float32)
    proto[0, 0, 45:95, 25:75] = 8.0  # a 200x200 square at x 100..300, y 180..380 of the input
    return proto


def _model(path, v8: bool):
    """An ONNX graph whose outputs are the constants above, wired to the input so no runtime
    folds them away: out = const + 0 * mean(images)."""
    n = 8400 if v8 else 25200
    det = np.zeros((n, (4 if v8 else 5) + C + M), np.float32)
    det[:4] = _candidates(v8)
    det = det.T[None] if v8 else det[None]
    nodes = [helper.make_node("ReduceMean", ["images"], ["mean"], keepdims=0),
             helper.make_node("Mul", ["mean", "zero"], ["nil"]),
             helper.make_node("Add", ["det", "nil"], ["output0"]),
             helper.make_node("Add", ["proto", "nil"], ["output1"])]
    inits = [numpy_helper.from_array(np.zeros((), np.float32), "zero"),
             numpy_helper.from_array(det.astype(np.float32), "det"),
             numpy_helper.from_array(_prototypes(), "proto")]
    graph = helper.make_graph(
        nodes, "yolo_seg_stub", [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 640, 640])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(det.shape)),
         helper.make_tensor_value_info("output1", TensorProto.FLOAT, [1, M, PH, PH])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return path


@pytest.mark.parametrize("v8", [False, True], ids=["yolov5-seg", "yolov8-seg"])
def test_yolo_seg_onnx_decodes_one_person(tmp_path, v8):
    src = make_mask_source(f"onnx:{_model(tmp_path / 'm.onnx', v8)}")
    frame = Frame(0, 0.0, np.zeros((480, 640, 3), np.uint8), np.zeros((480, 640), np.float32))
    masks = src(frame)
    assert len(masks) == 1  # duplicate suppressed, chair and weak person dropped
    # letterbox of 640x480 into 640x640: scale 1, 80 px of padding on top
    expected = np.zeros((480, 640), bool)
    expected[100:300, 100:300] = True
    iou = (masks[0] & expected).sum() / (masks[0] | expected).sum()
    assert iou > 0.97, iou


def test_onnx_source_reports_a_missing_or_foreign_model(tmp_path):
    with pytest.raises(FileNotFoundError, match="ONNX model not found"):
        make_mask_source(f"onnx:{tmp_path / 'none.onnx'}")
    from dynslam_lite.segmentation.yolo import split_outputs
    with pytest.raises(ValueError, match="not a YOLO-seg model"):
        split_outputs([np.zeros((1, 10))])
