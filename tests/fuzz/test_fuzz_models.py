"""Property-based fuzzing of the ONNX YOLO model loader and decoder (issue 11).

The properties: loading a file either gives a working detector or raises
:class:`~lapwrench.perception.ModelError` (a :class:`~lapwrench.perception.PerceptionError`) with a
one-line message naming the file; a model whose detection tensor is not floating point is refused
at load (item 8); whatever numbers a loaded model emits (NaN, inf, huge, negative, logits), a
detection has a finite box inside the frame, a finite tracking point and a score in [0, 1].
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from lapwrench.perception import Detection, ModelError, OnnxYoloDetector, PerceptionError
from lapwrench.perception.synthetic import make_constant_yolo_onnx

pytest.importorskip("onnx", reason="these tests build ONNX graphs with the onnx helper API (dev extra)")

FRAME_W, FRAME_H = 640, 480
INPUT = (320, 320)
FRAME = np.random.default_rng(0).integers(0, 256, (FRAME_H, FRAME_W, 3), dtype=np.uint8)


def _v8_output(n: int = 20, nc: int = 2) -> np.ndarray:
    out = np.zeros((1, 4 + nc, n), np.float32)
    out[0, :4, :] = [[160.0], [160.0], [40.0], [30.0]]
    out[0, 4, 0] = 0.9
    return out


def _check_error(exc: ModelError, path: Path) -> None:
    message = str(exc)
    assert isinstance(exc, PerceptionError)
    assert "\n" not in message and "\r" not in message, f"not one line: {message!r}"
    assert str(path) in message and len(message) < 400 + len(str(path))


def _check_detections(dets: list[Detection]) -> None:
    for d in dets:
        x0, y0, x1, y1 = d.box
        assert np.isfinite(d.box).all() and np.isfinite(d.point).all()
        assert 0.0 <= x0 < x1 <= FRAME_W and 0.0 <= y0 < y1 <= FRAME_H
        assert 0.0 <= d.score <= 1.0, f"score {d.score}"
        assert 0.0 <= d.u <= FRAME_W and 0.0 <= d.v <= FRAME_H


def _load(path: Path, **kw: Any) -> OnnxYoloDetector | None:
    """The detector, or None after checking the ModelError; any other exception fails the test."""
    try:
        return OnnxYoloDetector(path, **kw)
    except ModelError as exc:
        _check_error(exc, path)
        return None


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("models")


@pytest.fixture(scope="module")
def valid_model(workdir: Path) -> bytes:
    """The bytes of a working YOLOv8-layout model with ultralytics-style metadata."""
    path = make_constant_yolo_onnx(workdir / "valid.onnx", {"output0": _v8_output()}, input_hw=INPUT,
                                   metadata={"names": "{0: 'grasper', 1: 'hook'}", "stride": "32"})
    return path.read_bytes()


# -- files -----------------------------------------------------------------------------------------


@settings(max_examples=100)
@given(st.binary(max_size=600))
@example(b"")
def test_garbage_bytes_are_a_model_error(workdir: Path, data: bytes) -> None:
    path = workdir / "garbage.onnx"
    path.write_bytes(data)
    assert _load(path) is None


@settings(max_examples=60)
@given(cut=st.integers(0, 10**6), flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), max_size=3))
def test_a_truncated_or_corrupted_model_loads_cleanly_or_is_a_model_error(
    workdir: Path, valid_model: bytes, cut: int, flips: list[tuple[int, int]]
) -> None:
    data = bytearray(valid_model[: cut % (len(valid_model) + 1)])
    for pos, x in flips:
        if data:
            data[pos % len(data)] ^= x
    path = workdir / "cut.onnx"
    path.write_bytes(bytes(data))
    det = _load(path)
    if det is not None:
        _check_detections(det.detect(FRAME))


def test_a_directory_or_a_missing_file_is_a_model_error(workdir: Path) -> None:
    for path in (workdir, workdir / "missing.onnx"):
        with pytest.raises(ModelError) as exc:
            OnnxYoloDetector(path)
        _check_error(exc.value, path)


# -- model structure -------------------------------------------------------------------------------

out_dtypes = st.sampled_from([np.float32, np.float32, np.int32, np.int64, np.uint8])
out_shapes = st.one_of(
    st.tuples(st.just(1), st.integers(1, 9), st.integers(1, 30)),  # [1, A, B]: v5 or v8 or nothing
    hnp.array_shapes(min_dims=1, max_dims=5, min_side=1, max_side=8),
    st.tuples(st.integers(0, 6), st.just(7)),  # v7 end-to-end
)
metadata = st.fixed_dictionaries({}, optional={
    "names": st.one_of(st.sampled_from(["{0: 'a', 1: 'b'}", "['a']", "{'a': 1}", "{(1, 2): 'x'}", "[[", "{}",
                                        "{1e400: 'x'}", "[" * 200]), st.text(max_size=12)),
    "stride": st.one_of(st.sampled_from(["32", "0", "-8", "inf", "nan", "1e400", "[32]", "16.5"]), st.text(max_size=6)),
    "imgsz": st.one_of(st.sampled_from(["640", "[320, 320]", "[0, 0]", "[-5, 640]", "[[1], [2]]", "'x'", "1e9",
                                        "[320.5, 320]", "(1, 2, 3)", "[100000, 100000]"]), st.text(max_size=6)),
    "end2end": st.sampled_from(["True", "true", "False", "1"]),
})


@st.composite
def constant_models(draw: st.DrawFn) -> tuple[dict[str, np.ndarray], dict[str, str], bool]:
    """One or two outputs of any shape and dtype (values anything for floats), metadata, dynamic input."""
    outputs = {}
    for name in draw(st.sampled_from([["output0"], ["out"], ["output0", "extra"]])):
        dtype, shape = draw(out_dtypes), draw(out_shapes)
        elements = st.floats(width=32, allow_nan=True, allow_infinity=True) if dtype is np.float32 else None
        outputs[name] = draw(hnp.arrays(dtype, shape, elements=elements))
    return outputs, draw(metadata), draw(st.booleans())


@settings(max_examples=60)
@given(constant_models())
@example(({"output0": np.round(_v8_output() * 100).astype(np.int64)}, {}, False))  # item 8: integer output
@example(({"output0": _v8_output()}, {"stride": "inf"}, False))
@example(({"output0": _v8_output()}, {"names": "{'a': 'x'}"}, False))
@example(({"output0": _v8_output()}, {"imgsz": "[[1], [2]]"}, True))
@example(({"output0": _v8_output()}, {"imgsz": "[0, 0]"}, True))
def test_any_model_loads_and_detects_soundly_or_is_a_model_error(workdir: Path, model: tuple) -> None:
    outputs, meta, dynamic = model
    path = make_constant_yolo_onnx(workdir / "struct.onnx", outputs, input_hw=None if dynamic else INPUT,
                                   metadata=meta or None)
    det = _load(path)
    if det is None:
        return
    main = outputs[det.output_names[det.layout.outputs[0]]]
    assert main.dtype.kind == "f", f"a {main.dtype} detection output was accepted"
    _check_detections(det.detect(FRAME))


@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.uint8])
def test_an_integer_output_model_is_refused_naming_the_dtype(workdir: Path, dtype: type) -> None:
    """Issue 11 item 8: an integer-output model was accepted silently."""
    out = (_v8_output() > 0.5).astype(dtype)
    path = make_constant_yolo_onnx(workdir / "int.onnx", {"output0": out}, input_hw=INPUT)
    with pytest.raises(ModelError, match=f"output0.*{np.dtype(dtype).name}") as exc:
        OnnxYoloDetector(path)
    _check_error(exc.value, path)


# -- non-maximum suppression ----------------------------------------------------------------------

coords = st.one_of(st.floats(-50.0, 700.0), st.sampled_from([0.0, 1e30, -1e30, 3e38]))


@given(
    boxes=st.lists(st.tuples(coords, coords, st.floats(0.0, 300.0), st.floats(0.0, 300.0)), max_size=12),
    data=st.data(),
    iou=st.floats(0.05, 1.0),
)
@example(boxes=[(1e30, 0.0, 1e30, 10.0), (0.0, 0.0, 10.0, 10.0), (1.0, 0.0, 10.0, 10.0)], data=None, iou=0.45)
def test_nms_suppresses_a_box_only_for_an_overlapping_better_box_of_its_class(
    boxes: list[tuple[float, float, float, float]], data: st.DataObject | None, iou: float
) -> None:
    from lapwrench.perception.boxes import box_iou, nms

    xyxy = np.array([[x, y, x + w, y + h] for x, y, w, h in boxes], np.float64).reshape(-1, 4)
    n = len(xyxy)
    if data is None:  # the regression example: a huge box made two overlapping boxes of class 1 both kept
        scores, classes = np.array([0.9, 0.8, 0.7]), np.array([0, 1, 1])
    else:
        scores = np.array(data.draw(st.lists(st.floats(0.01, 1.0), min_size=n, max_size=n)))
        class_ids = st.integers(0, 3) | st.integers(-(2**31), 2**31)
        classes = np.array(data.draw(st.lists(class_ids, min_size=n, max_size=n)))
    keep = nms(xyxy, scores, iou, classes)
    kept = set(keep.tolist())
    for i in range(n):
        if i in kept:
            continue
        same = [k for k in kept if classes[k] == classes[i] and scores[k] >= scores[i]]
        overlaps = box_iou(xyxy[i], xyxy[same]) > iou if same else np.zeros(0, bool)
        assert overlaps.any(), f"box {i} was suppressed without an overlapping better box of its class"
    for i in kept:  # and two kept boxes of one class do not overlap
        for k in kept:
            if k != i and classes[k] == classes[i]:
                assert not box_iou(xyxy[i], xyxy[k : k + 1])[0] > iou, f"boxes {i} and {k} overlap, both kept"


# -- decoding whatever a model emits ---------------------------------------------------------------

LAYOUT_OUTPUTS = {
    "yolov8": {"output0": _v8_output(12, 2)},
    "yolov5": {"output": np.zeros((1, 12, 7), np.float32)},
    "yolov7_e2e": {"output": np.zeros((5, 7), np.float32)},
    "e2e": {"output0": np.zeros((1, 6, 6), np.float32)},
    "yolov7_e2e_split": {
        "num_dets": np.array([[1]], np.int32),
        "det_boxes": np.zeros((1, 6, 4), np.float32),
        "det_scores": np.zeros((1, 6), np.float32),
        "det_classes": np.zeros((1, 6), np.int32),
    },
}


@pytest.fixture(scope="module")
def detectors(workdir: Path) -> dict[str, OnnxYoloDetector]:
    """One detector per layout, built once."""
    out = {}
    for name, outputs in LAYOUT_OUTPUTS.items():
        meta = {"end2end": "True"} if name == "e2e" else None
        path = make_constant_yolo_onnx(workdir / f"{name}.onnx", outputs, input_hw=INPUT, metadata=meta)
        out[name] = OnnxYoloDetector(path)
    return out


class _FakeSession:
    """Stands in for the onnxruntime session: returns the given outputs whatever the input."""

    def __init__(self, outputs: list[np.ndarray]) -> None:
        self.outputs = outputs

    def run(self, names: object, feeds: object) -> list[np.ndarray]:
        return self.outputs


wild = st.one_of(
    st.floats(width=32, allow_nan=True, allow_infinity=True),
    st.floats(-20.0, 700.0, width=32),  # plausible pixels, scores and logits
    st.sampled_from([0.0, 1.0, 0.9, 3e38, -3e38, 1e30, 1e20]),
)


any_int32 = st.integers(-(2**31), 2**31 - 1)


@st.composite
def emitted(draw: st.DrawFn, name: str) -> list[np.ndarray]:
    """Outputs of the shapes the layout's model declares, with wild values."""
    outs = []
    for key, ref in LAYOUT_OUTPUTS[name].items():
        if ref.dtype.kind == "f":
            outs.append(draw(hnp.arrays(np.float32, ref.shape, elements=wild)))
        elif key == "num_dets":
            outs.append(np.array([[draw(any_int32 | st.integers(-3, 10))]], np.int32))
        else:
            outs.append(draw(hnp.arrays(np.int32, ref.shape, elements=any_int32 | st.integers(-1, 3))))
    return outs


@settings(max_examples=150)
@given(st.sampled_from(sorted(LAYOUT_OUTPUTS)), st.data(), st.booleans(), st.booleans())
def test_decoded_detections_are_finite_inside_the_frame_with_scores_in_0_1(
    detectors: dict[str, OnnxYoloDetector], name: str, data: st.DataObject, flip: bool, agnostic: bool
) -> None:
    det = detectors[name]
    outputs = data.draw(emitted(name))
    boxes, scores, cls = det.decode(outputs)
    assert np.isfinite(boxes).all() and np.isfinite(scores).all()
    assert ((scores >= 0.0) & (scores <= 1.0)).all()
    assert len(boxes) == len(scores) == len(cls)
    if name == "yolov7_e2e_split":  # only the first num_dets rows are detections
        assert len(boxes) <= max(0, int(outputs[0][0, 0]))
    session, config = det.session, det.config
    det.session, det.test_time_flip = _FakeSession(outputs), flip
    det.config = replace(config, agnostic_nms=agnostic)
    try:
        _check_detections(det.detect(FRAME))
    finally:
        det.session, det.test_time_flip, det.config = session, False, config
