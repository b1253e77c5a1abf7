"""Detector runtime: letterbox, decoding and class-aware NMS on hand-made tensors, model file errors, drawing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ocslam.config import DetectorConfig
from app.ocslam.detector import (
    CLASS_COLORS,
    Detector,
    DetectorError,
    Letterbox,
    decode_output,
    draw_detections,
    input_shape_for,
    letterbox,
)
from app.ocslam.messages import CLASS_NAMES, Detection, Detections

NC = len(CLASS_NAMES)


def make_output(anchors: list[tuple[float, float, float, float, int, float]], n_total: int = 50) -> np.ndarray:
    """A ``(1, 4 + C, n_total)`` YOLO output: the given ``(cx, cy, w, h, class, score)`` anchors, then
    background anchors with scores far below any threshold."""
    out = np.zeros((1, 4 + NC, n_total), np.float32)
    out[0, :4, :] = [[10.0], [10.0], [4.0], [4.0]]
    out[0, 4:, :] = 0.001
    for i, (cx, cy, w, h, c, s) in enumerate(anchors):
        out[0, :4, i] = (cx, cy, w, h)
        out[0, 4 + c, i] = s
    return out


IDENTITY = Letterbox(scale=1.0, pad_x=0.0, pad_y=0.0, input_width=224, input_height=224)


def test_decode_keeps_best_of_overlapping_same_class_boxes() -> None:
    out = make_output(
        [
            (50, 50, 20, 20, 3, 0.9),  # table
            (51, 50, 20, 20, 3, 0.8),  # same table, IoU ≈ 0.9 → suppressed
            (51, 51, 20, 20, 4, 0.7),  # chair in the same place: another class, kept (class-aware NMS)
            (150, 150, 10, 10, 0, 0.3),  # ball below the threshold
            (150, 100, 10, 10, 0, 0.6),  # ball elsewhere
        ]
    )
    boxes, scores, cls = decode_output(out, NC, 0.4, 0.5, IDENTITY, 224, 224)
    assert cls.tolist() == [3, 4, 0]
    np.testing.assert_allclose(scores, [0.9, 0.7, 0.6], rtol=1e-6)
    np.testing.assert_allclose(boxes[0], [40, 40, 60, 60])
    np.testing.assert_allclose(boxes[2], [145, 95, 155, 105])


def test_decode_threshold_and_iou_are_respected() -> None:
    out = make_output([(50, 50, 20, 20, 1, 0.9), (56, 50, 20, 20, 1, 0.85)])  # IoU = 14·20/(2·400−280) ≈ 0.54
    assert len(decode_output(out, NC, 0.4, 0.5, IDENTITY, 224, 224)[0]) == 1
    assert len(decode_output(out, NC, 0.4, 0.6, IDENTITY, 224, 224)[0]) == 2
    assert len(decode_output(out, NC, 0.95, 0.5, IDENTITY, 224, 224)[0]) == 0


def test_decode_maps_back_through_the_letterbox_and_clips() -> None:
    # 640×480 into 224×192: scale 0.35, 12 px of padding top and bottom.
    blob, lb = letterbox(np.zeros((480, 640, 3), np.uint8), 224, 192)
    assert blob.shape == (1, 3, 192, 224) and blob.dtype == np.float32
    assert lb.scale == pytest.approx(0.35) and lb.pad_x == 0 and lb.pad_y == 12
    # A box that covers x 35..70, y 12+35..12+70 in the input is 100..200 in the original.
    out = make_output([(52.5, 12 + 52.5, 35, 35, 5, 0.95), (220, 100, 20, 20, 2, 0.9)])
    boxes, _, cls = decode_output(out, NC, 0.4, 0.5, lb, 640, 480)
    np.testing.assert_allclose(boxes[0], [100, 100, 200, 200], atol=1e-6)
    assert cls[0] == 5
    assert boxes[1][2] == 640.0  # clipped at the right edge


def test_decode_rejects_a_wrong_layout() -> None:
    with pytest.raises(DetectorError, match=r"\[1, 15, N\]"):
        decode_output(np.zeros((1, 10, 30), np.float32), NC, 0.4, 0.5, IDENTITY, 224, 224)


def test_decode_ignores_nan_scores() -> None:
    out = make_output([(50, 50, 20, 20, 3, 0.9)])
    out[0, 4:, 1] = np.nan
    boxes, _, _ = decode_output(out, NC, 0.4, 0.5, IDENTITY, 224, 224)
    assert len(boxes) == 1


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(0, 224), st.floats(0, 224), st.floats(2, 120), st.floats(2, 120),
            st.integers(0, NC - 1), st.floats(0.0, 1.0),
        ),
        max_size=30,
    ),
    st.floats(0.05, 0.95),
    st.floats(0.1, 0.9),
)
def test_decode_invariants(anchors, conf, iou) -> None:
    out = make_output(anchors, n_total=max(40, len(anchors)))
    boxes, scores, cls = decode_output(out, NC, conf, iou, IDENTITY, 224, 224)
    assert np.all(scores >= conf - 1e-6)
    assert np.all(np.diff(scores) <= 1e-9)  # best first
    assert np.all((boxes >= 0) & (boxes <= 224))
    assert np.all(boxes[:, 2] > boxes[:, 0]) and np.all(boxes[:, 3] > boxes[:, 1])
    # After NMS no two boxes of one class overlap by more than the IoU threshold.
    for c in np.unique(cls):
        b = boxes[cls == c]
        x1 = np.maximum(b[:, None, 0], b[None, :, 0])
        y1 = np.maximum(b[:, None, 1], b[None, :, 1])
        x2 = np.minimum(b[:, None, 2], b[None, :, 2])
        y2 = np.minimum(b[:, None, 3], b[None, :, 3])
        inter = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
        area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
        iou_m = inter / (area[:, None] + area[None, :] - inter)
        np.fill_diagonal(iou_m, 0)
        assert np.all(iou_m <= iou + 1e-4)


def test_input_shape_is_the_papers() -> None:
    assert input_shape_for(640, 480, 224) == (224, 192)  # 224×168 padded to the stride
    assert input_shape_for(640, 480, 320) == (320, 256)
    assert input_shape_for(320, 240, 224) == (224, 192)


def test_letterbox_pads_with_grey_and_keeps_content() -> None:
    img = np.full((480, 640, 3), 200, np.uint8)
    blob, lb = letterbox(img, 224, 224)
    assert blob.shape == (1, 3, 224, 224)
    assert lb.pad_y == 28
    np.testing.assert_allclose(blob[0, :, 0, 0], 114 / 255, atol=1e-6)
    np.testing.assert_allclose(blob[0, :, 112, 112], 200 / 255, atol=1e-6)


def test_missing_model_names_path_and_command(tmp_path: Path) -> None:
    missing = tmp_path / "nope.onnx"
    with pytest.raises(DetectorError) as e:
        Detector(DetectorConfig(), missing)
    assert str(missing) in str(e.value) and "ocslam train-detector" in str(e.value)


def test_corrupt_model_names_path_and_command(tmp_path: Path) -> None:
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"\x08\x07this is not a protobuf" * 10)
    with pytest.raises(DetectorError) as e:
        Detector(DetectorConfig(), bad)
    assert str(bad) in str(e.value) and "ocslam train-detector" in str(e.value)
    empty = tmp_path / "empty.onnx"
    empty.write_bytes(b"")
    with pytest.raises(DetectorError, match="empty.onnx"):
        Detector(DetectorConfig(), empty)


def test_draw_detections_colours_boxes_and_scales() -> None:
    img = np.zeros((240, 320, 3), np.uint8)
    dets = Detections(0.0, 640, 480, (Detection(100, 200, 300, 400, 3, 0.87),))
    out = draw_detections(img, dets)
    assert out.shape == img.shape and not np.shares_memory(out, img)
    assert np.all(img == 0)
    # The box (scaled by 0.5) has the table colour on its left edge, away from the label.
    assert tuple(out[150, 50]) == CLASS_COLORS[3]
    assert np.all(out[150, 100] == 0)  # inside the box stays untouched
    assert dets.yolo_boxes().tolist() == [[100, 200, 300, 400, 3, 87]]


def test_bad_images_give_a_clear_error() -> None:
    from app.ocslam.detector import _as_rgb

    with pytest.raises(DetectorError, match="uint8"):
        _as_rgb(np.zeros((10, 10, 3), np.float32))
    with pytest.raises(DetectorError, match="shape"):
        _as_rgb(np.zeros((10, 10, 2), np.uint8))
    assert _as_rgb(np.zeros((10, 10), np.uint8)).shape == (10, 10, 3)


def test_letterbox_into_a_kept_buffer_matches_a_fresh_one() -> None:
    rng = np.random.default_rng(3)
    a = rng.integers(0, 256, (240, 320, 3), dtype=np.uint8)
    b = rng.integers(0, 256, (240, 320, 3), dtype=np.uint8)
    fresh_b, lb = letterbox(b, 224, 192)
    buf, _ = letterbox(a, 224, 192)
    kept, lb2 = letterbox(b, 224, 192, out=buf)  # reused: only the content is rewritten
    assert kept is buf and lb2 == lb
    np.testing.assert_array_equal(kept, fresh_b)
    np.testing.assert_allclose(kept[0, :, : int(lb.pad_y), :], 114 / 255, atol=1e-7)


def test_detector_reuses_its_input_tensor_across_image_sizes() -> None:
    from pathlib import Path as _P

    from app.ocslam.messages import Image

    model = _P(__file__).resolve().parents[1] / "assets" / "models" / "detector.onnx"
    det = Detector(DetectorConfig(), model)
    img = np.full((240, 320, 3), 90, np.uint8)
    out1, _ = det.infer(img)
    det.detect(Image(0.0, np.full((300, 300, 3), 255, np.uint8)))  # another shape in between (side padding)
    out2, _ = det.infer(img)
    np.testing.assert_array_equal(out1, out2)  # same image, same output: no stale pixels or padding


def test_decode_ignores_infinite_scores() -> None:
    out = make_output([(50, 50, 20, 20, 3, 0.9), (150, 150, 20, 20, 2, 0.8)])
    out[0, 4 + 2, 1] = np.inf
    boxes, scores, cls = decode_output(out, NC, 0.4, 0.5, IDENTITY, 224, 224)
    assert cls.tolist() == [3] and np.all(np.isfinite(scores))
