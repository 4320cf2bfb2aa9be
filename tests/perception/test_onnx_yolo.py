"""OnnxYoloDetector against tiny ONNX graphs emitting each YOLO output layout."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from lapwrench.perception import (
    Detection,
    DetectorConfig,
    FrameError,
    ModelError,
    OnnxYoloDetector,
    OutputLayout,
    TrackingPoint,
    TrackingPointRule,
    make_detector,
)
from lapwrench.perception.synthetic import make_constant_yolo_onnx

if TYPE_CHECKING:
    from perception.conftest import ModelFactory, Truth

pytest.importorskip("onnx", reason="these tests build ONNX graphs with the onnx helper API (dev extra)")

LAYOUTS = {
    "yolov5": OutputLayout.YOLOV5,
    "yolov7_raw": OutputLayout.YOLOV5,
    "yolov8": OutputLayout.YOLOV8,
    "yolov7_e2e": OutputLayout.YOLOV7_E2E,
    "yolov7_e2e_split": OutputLayout.YOLOV7_E2E_SPLIT,
}
# (model input (h, w), dynamic axes): ratio 1 with 80 px bars, ratio 0.5, and stride-aligned 320x256.
GEOMETRIES = [((640, 640), False), ((320, 320), False), ((320, 320), True)]


def summary(dets: list[Detection]) -> list[tuple[int, float]]:
    return [(d.class_id, round(d.score, 4)) for d in dets]


def assert_matches(dets: list[Detection], truth: dict[str, Truth], names: list[str]) -> None:
    assert summary(dets) == [(truth[n].cls, truth[n].score) for n in names]
    for d, n in zip(dets, names, strict=True):
        np.testing.assert_allclose(d.box, truth[n].box, atol=1e-3)


@pytest.mark.parametrize("layout", list(LAYOUTS))
@pytest.mark.parametrize(("input_hw", "dynamic"), GEOMETRIES)
def test_each_layout_decodes_and_unletterboxes(
    make_layout_model: ModelFactory,
    frame: np.ndarray,
    truth: dict[str, Truth],
    layout: str,
    input_hw: tuple[int, int],
    dynamic: bool,
) -> None:
    det = OnnxYoloDetector(make_layout_model(layout, input_hw, dynamic), input_size=input_hw if dynamic else None)
    assert det.layout.layout is LAYOUTS[layout]
    assert det.dynamic is dynamic
    dets = det.detect(frame)
    # Per-class NMS drops A_dup (raw layouts) but keeps B (another class); D is below 0.25.
    assert_matches(dets, truth, ["A", "B", "C"])
    # Default tracking point: the box centre (u, v).
    assert dets[0].point == pytest.approx((150.0, 140.0), abs=1e-3)


def test_test_time_flip_adds_the_mirrored_pass_and_fuses(
    make_layout_model: ModelFactory, frame: np.ndarray, truth: dict[str, Truth]
) -> None:
    # The constant model emits the same input-space boxes for the mirrored frame, so each truth
    # box also comes back mirrored (x -> 640 - x at ratio 1); A absorbs its near-duplicate.
    det = OnnxYoloDetector(make_layout_model("yolov8", (640, 640)), test_time_flip=True)
    assert "test_time_flip=True" in repr(det)
    dets = det.detect(frame)
    assert summary(dets) == [(0, 0.9), (0, 0.9), (1, 0.7), (1, 0.7), (2, 0.6), (2, 0.6)]
    a, a_dup = np.array(truth["A"].box), np.array(truth["A_dup"].box)
    fused_a = (0.9 * a + 0.8 * a_dup) / 1.7
    mirrored_a = np.array([640 - fused_a[2], fused_a[1], 640 - fused_a[0], fused_a[3]])
    left_to_right = sorted((d.box for d in dets[:2]), key=lambda b: b[0])
    np.testing.assert_allclose(left_to_right, [fused_a, mirrored_a], atol=1e-3)
    c_boxes = sorted((d.box for d in dets[4:]), key=lambda b: b[0])
    np.testing.assert_allclose(c_boxes, [[640 - 500.0, 300.0, 640 - 400.0, 420.0], truth["C"].box], atol=1e-3)


def test_dynamic_input_is_stride_aligned(make_layout_model: ModelFactory) -> None:
    det = OnnxYoloDetector(make_layout_model("yolov8", (320, 320), dynamic=True), input_size=320)
    assert det.input_shape_for((480, 640)) == (256, 320)
    default = OnnxYoloDetector(make_layout_model("yolov8", (320, 320), dynamic=True))
    assert default.input_shape_for((480, 640)) == (480, 640)  # 640 default: no padding at all
    static = OnnxYoloDetector(make_layout_model("yolov8", (320, 320), dynamic=False))
    assert static.input_shape_for((480, 640)) == (320, 320)


@pytest.mark.parametrize("layout", ["yolov5", "yolov8"])
def test_agnostic_nms_suppresses_across_classes(
    make_layout_model: ModelFactory, frame: np.ndarray, truth: dict[str, Truth], layout: str
) -> None:
    det = OnnxYoloDetector(make_layout_model(layout), DetectorConfig(agnostic_nms=True))
    assert_matches(det.detect(frame), truth, ["A", "C"])


@pytest.mark.parametrize("layout", ["yolov5", "yolov8"])
def test_high_iou_threshold_keeps_duplicates(
    make_layout_model: ModelFactory, frame: np.ndarray, truth: dict[str, Truth], layout: str
) -> None:
    det = OnnxYoloDetector(make_layout_model(layout), DetectorConfig(iou_threshold=0.95))
    assert_matches(det.detect(frame), truth, ["A", "A_dup", "B", "C"])


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_class_filter(make_layout_model: ModelFactory, frame: np.ndarray, truth: dict[str, Truth], layout: str) -> None:
    det = OnnxYoloDetector(make_layout_model(layout), DetectorConfig(classes=frozenset({2})))
    assert_matches(det.detect(frame), truth, ["C"])


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_score_threshold(
    make_layout_model: ModelFactory, frame: np.ndarray, truth: dict[str, Truth], layout: str
) -> None:
    det = OnnxYoloDetector(make_layout_model(layout), DetectorConfig(score_threshold=0.65))
    assert_matches(det.detect(frame), truth, ["A", "B"])
    low = OnnxYoloDetector(make_layout_model(layout), DetectorConfig(score_threshold=0.05))
    assert [d.score for d in low.detect(frame)][-1] == pytest.approx(0.10)


def test_max_detections(make_layout_model: ModelFactory, frame: np.ndarray, truth: dict[str, Truth]) -> None:
    det = OnnxYoloDetector(make_layout_model("yolov8"), DetectorConfig(max_detections=1))
    assert_matches(det.detect(frame), truth, ["A"])


def test_v5_score_is_objectness_times_class_probability(tmp_path: Path, frame: np.ndarray) -> None:
    rows = np.zeros((40, 7), np.float32)
    rows[:, :4] = [10, 10, 4, 4]
    rows[3] = [320, 320, 100, 100, 0.8, 0.25, 0.75]  # obj 0.8, best class 1 with p 0.75
    det = OnnxYoloDetector(make_constant_yolo_onnx(tmp_path / "m.onnx", {"output": rows[None]}))
    (d,) = det.detect(frame)
    assert d.class_id == 1
    assert d.score == pytest.approx(0.6)
    assert d.box == pytest.approx((270.0, 190.0, 370.0, 290.0))


def test_boxes_are_clipped_to_the_frame(tmp_path: Path, frame: np.ndarray) -> None:
    rows = np.zeros((40, 6), np.float32)
    rows[0] = [5, 320, 60, 40, 0.9, 1.0]  # extends left of the frame
    det = OnnxYoloDetector(make_constant_yolo_onnx(tmp_path / "m.onnx", {"output": rows[None]}))
    (d,) = det.detect(frame)
    assert d.box == pytest.approx((0.0, 220.0, 35.0, 260.0))


def test_class_names_from_ultralytics_metadata(make_layout_model: ModelFactory, frame: np.ndarray) -> None:
    meta = {"names": "{0: 'grasper', 1: 'scissors', 2: 'hook'}", "stride": "32"}
    det = OnnxYoloDetector(make_layout_model("yolov8", metadata=meta))
    assert [d.class_name for d in det.detect(frame)] == ["grasper", "scissors", "hook"]
    named = OnnxYoloDetector(make_layout_model("yolov5"), class_names=["a", "b", "c"])
    assert [d.class_name for d in named.detect(frame)] == ["a", "b", "c"]


def test_bgr_frames_are_accepted(make_layout_model: ModelFactory, frame: np.ndarray, truth: dict[str, Truth]) -> None:
    det = OnnxYoloDetector(make_layout_model("yolov8"), DetectorConfig(color_order="bgr"))
    assert_matches(det.detect(frame), truth, ["A", "B", "C"])


def test_tracking_point_rule_is_applied(make_layout_model: ModelFactory, frame: np.ndarray) -> None:
    rule = TrackingPointRule(TrackingPoint.EDGE_NEAREST_REFERENCE)
    det = OnnxYoloDetector(make_layout_model("yolov8"), DetectorConfig(tracking_point=rule))
    a = det.detect(frame)[0]  # box (100, 100, 200, 180); image centre (320, 240): right edge
    assert a.point == pytest.approx((200.0, 140.0))


def test_make_detector_dispatches_on_suffix(make_layout_model: ModelFactory, tmp_path: Path) -> None:
    assert isinstance(make_detector(make_layout_model("yolov8")), OnnxYoloDetector)
    with pytest.raises(ModelError, match="unknown detector"):
        make_detector(tmp_path / "model.tflite")


# -- bad models --------------------------------------------------------------------------------


def test_missing_model_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.onnx"
    with pytest.raises(ModelError, match="not found") as exc:
        OnnxYoloDetector(path)
    assert str(path) in str(exc.value)


def test_directory_is_not_a_model(tmp_path: Path) -> None:
    with pytest.raises(ModelError, match="not a file"):
        OnnxYoloDetector(tmp_path)


def test_corrupt_model_file(tmp_path: Path) -> None:
    path = tmp_path / "corrupt.onnx"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    with pytest.raises(ModelError, match="cannot load as an ONNX model") as exc:
        OnnxYoloDetector(path)
    assert exc.value.path == str(path)


@pytest.mark.parametrize(
    "outputs",
    [
        {"out": np.zeros((1, 6, 6), np.float32)},  # square: channel axis undecidable
        {"out": np.zeros((20, 6), np.float32)},  # rank 2 but not [N, 7]
        {"out": np.zeros((1, 3, 20, 20, 9), np.float32)},  # rank 5 only
        {"a": np.zeros((1, 100, 9), np.float32), "b": np.zeros((1, 100, 9), np.float32)},  # which one?
        {"out": np.zeros((1, 100, 4), np.float32)},  # too narrow for any layout
    ],
    ids=["square", "rank2", "rank5", "two-candidates", "narrow"],
)
def test_unknown_layout_raises(tmp_path: Path, outputs: dict[str, np.ndarray]) -> None:
    path = make_constant_yolo_onnx(tmp_path / "weird.onnx", outputs)
    with pytest.raises(ModelError, match="unknown YOLO output layout") as exc:
        OnnxYoloDetector(path)
    assert str(path) in str(exc.value)


def test_forced_layout_that_does_not_fit_raises(make_layout_model: ModelFactory) -> None:
    with pytest.raises(ModelError, match="does not fit layout"):
        OnnxYoloDetector(make_layout_model("yolov7_e2e"), layout="yolov8")


def test_forced_layout_overrides_auto(tmp_path: Path, frame: np.ndarray) -> None:
    # [1, 6, 6] is ambiguous in auto mode; forcing v8 decodes it (nc = 2).
    out = np.zeros((1, 6, 6), np.float32)
    out[0, :, 0] = [320, 320, 40, 40, 0.1, 0.9]
    det = OnnxYoloDetector(make_constant_yolo_onnx(tmp_path / "m.onnx", {"o": out}), layout="yolov8")
    (d,) = det.detect(frame)
    assert (d.class_id, d.score) == (1, pytest.approx(0.9))


def test_fixed_input_size_conflict(make_layout_model: ModelFactory) -> None:
    with pytest.raises(ModelError, match="fixed input"):
        OnnxYoloDetector(make_layout_model("yolov8", (640, 640)), input_size=320)


# -- bad frames --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("image", "match"),
    [
        (np.zeros((0, 0, 3), np.uint8), "empty"),
        (np.zeros((480, 0, 3), np.uint8), "empty"),
        (np.zeros((240, 320, 3), np.uint8), "expected 640x480"),
        (np.zeros((480, 640, 3), np.float32), "dtype must be uint8"),
        (np.zeros((480, 640), np.uint8), "H x W x 3"),
        (np.zeros((480, 640, 4), np.uint8), "H x W x 3"),
        ([[0, 0, 0]], "numpy array"),
    ],
    ids=["empty", "zero-width", "wrong-size", "float", "gray-2d", "rgba", "list"],
)
def test_bad_frames_raise(make_layout_model: ModelFactory, image: np.ndarray | list[list[int]], match: str) -> None:
    det = OnnxYoloDetector(make_layout_model("yolov8"))
    with pytest.raises(FrameError, match=match):
        det.detect(image)


def test_non_contiguous_frame_is_fine(make_layout_model: ModelFactory, truth: dict[str, Truth]) -> None:
    det = OnnxYoloDetector(make_layout_model("yolov8"))
    big = np.zeros((480, 1280, 3), np.uint8)
    view = big[:, ::2]  # strided view, 640 wide
    assert not view.flags.c_contiguous
    assert len(det.detect(view)) == 3
    assert len(det.detect(np.zeros((480, 640, 3), np.uint8)[:, :, ::-1])) == 3


def test_any_frame_size_when_unconfigured(make_layout_model: ModelFactory) -> None:
    det = OnnxYoloDetector(make_layout_model("yolov8", (320, 320), dynamic=True),
                           DetectorConfig(frame_size=None), input_size=320)
    assert det.detect(np.zeros((100, 200, 3), np.uint8)) is not None


def test_a_non_finite_box_is_never_a_detection(make_layout_model: ModelFactory) -> None:
    """Issue 11: a YOLOv8 output with a NaN box gave a detection at (NaN, NaN)."""
    det = OnnxYoloDetector(make_layout_model("yolov8", (640, 640)))
    out = np.zeros((1, 4 + 3, 3), dtype=np.float32)
    out[0, :4, 0] = [np.nan, 100.0, 20.0, 20.0]  # x, y, w, h
    out[0, :4, 1] = [200.0, 200.0, np.inf, 20.0]
    out[0, :4, 2] = [300.0, 300.0, 20.0, 20.0]
    out[0, 4, :] = 0.9  # class 0, well above the threshold
    boxes, _scores, _ = det.decode([out])
    assert len(boxes) == 1 and np.isfinite(boxes).all()
    np.testing.assert_allclose(boxes[0], [290.0, 290.0, 310.0, 310.0])


# -- found by the fuzz suite (tests/fuzz/test_fuzz_models.py) -------------------------------------


def test_an_integer_output_model_is_refused(tmp_path: Path) -> None:
    """Issue 11 item 8: an integer-output model was accepted silently (every score 0 or 1)."""
    out = np.zeros((1, 4 + 2, 20), np.int64)
    out[0, :4, 0], out[0, 4, 0] = [160, 160, 40, 30], 1
    path = make_constant_yolo_onnx(tmp_path / "int.onnx", {"output0": out}, input_hw=(320, 320))
    with pytest.raises(ModelError, match="output 'output0' has dtype int64; YOLO boxes and scores must be floating"):
        OnnxYoloDetector(path)


def test_an_integer_num_dets_and_classes_are_fine_in_the_split_layout(make_layout_model: ModelFactory) -> None:
    det = OnnxYoloDetector(make_layout_model("yolov7_e2e_split"))
    assert det.layout.layout is OutputLayout.YOLOV7_E2E_SPLIT


@pytest.mark.parametrize(
    "meta",
    [{"stride": "inf"}, {"stride": "0"}, {"names": "{'a': 'x'}"}, {"names": "[" * 500}, {"imgsz": "[[1], [2]]"},
     {"imgsz": "[0, 0]"}, {"imgsz": "[100000, 100000]"}],
    ids=["stride-inf", "stride-0", "names-str-keys", "names-deep", "imgsz-nested", "imgsz-zero", "imgsz-huge"],
)
def test_unreadable_metadata_falls_back_to_the_defaults(
    make_layout_model: ModelFactory, frame: np.ndarray, meta: dict[str, str]
) -> None:
    """A bad metadata value raised OverflowError/ValueError/TypeError or a cv2 error out of the loader."""
    det = OnnxYoloDetector(make_layout_model("yolov8", (320, 320), dynamic=True, metadata=meta))
    assert det.stride in (32, 1) and det.input_hw == (640, 640)
    assert len(det.detect(frame)) == 3


def test_a_bad_input_size_is_a_model_error(make_layout_model: ModelFactory) -> None:
    with pytest.raises(ModelError, match="input_size"):
        OnnxYoloDetector(make_layout_model("yolov8", (320, 320), dynamic=True), input_size=0)


def test_scores_are_in_0_1_and_junk_candidates_are_dropped(make_layout_model: ModelFactory) -> None:
    """An inf score was a detection with score inf; a logit of 5 a score of 5; a box at 1e30 and a
    NaN class were candidates."""
    det = OnnxYoloDetector(make_layout_model("yolov8", (640, 640)))
    out = np.zeros((1, 4 + 3, 5), dtype=np.float32)
    out[0, :4, :] = [[100.0], [100.0], [20.0], [20.0]]
    out[0, 4, 0] = np.inf  # dropped
    out[0, 4, 1] = 5.0  # an un-squashed logit: counts as 1
    out[0, 4, 2] = 0.9
    out[0, :4, 2] = [1e30, 100.0, 20.0, 20.0]  # junk box: dropped
    out[0, 5, 3] = 0.8  # class 1, fine
    boxes, scores, cls = det.decode([out])
    np.testing.assert_allclose(scores, [1.0, 0.8])
    assert cls.tolist() == [0, 1] and np.isfinite(boxes).all()


def test_a_negative_detection_count_selects_nothing(tmp_path: Path) -> None:
    """num_dets = -1 sliced [: -1]: every junk row but the last became a candidate."""
    outputs = {
        "num_dets": np.array([[-1]], np.int32),
        "det_boxes": np.full((1, 5, 4), 10.0, np.float32) + np.array([0, 0, 50, 50], np.float32),
        "det_scores": np.full((1, 5), 0.9, np.float32),
        "det_classes": np.zeros((1, 5), np.int32),
    }
    det = OnnxYoloDetector(make_constant_yolo_onnx(tmp_path / "split.onnx", outputs))
    assert len(det.decode(list(outputs.values()))[0]) == 0


def test_a_huge_box_does_not_switch_nms_off_for_the_other_boxes() -> None:
    """Per-class NMS offset the boxes by class x the largest coordinate: one box at 1e30 rounded every
    other box onto a point, and two overlapping boxes of one class were both kept."""
    from lapwrench.perception.boxes import nms

    boxes = np.array([[1e30, 0, 2e30, 10], [0, 0, 10, 10], [1, 0, 11, 10]], np.float64)
    keep = nms(boxes, np.array([0.9, 0.8, 0.7]), 0.45, np.array([0, 1, 1]))
    assert keep.tolist() == [0, 1]


def test_a_model_error_is_one_short_line() -> None:
    """A runtime's error may run over many lines; the user gets one line naming the file."""
    exc = ModelError("m.onnx", "first line\nsecond line\n" * 100)
    assert "\n" not in str(exc) and str(exc).startswith("m.onnx: first line second line")
    assert len(exc.problem) <= ModelError.MAX_PROBLEM
