"""lapwrench.perception.yolo_model: a YOLO ONNX export is checked before the detector uses it: the
session opens or the file is named, the one image input has a usable size, the metadata is a hint
(ignored when it does not parse), and boxes and scores must be floating point."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lapwrench.perception.detection import ModelError
from lapwrench.perception.synthetic import make_constant_yolo_onnx
from lapwrench.perception.yolo_layout import LayoutInfo, OutputLayout
from lapwrench.perception.yolo_model import (
    DEFAULT_INPUT_SIZE,
    MAX_INPUT_SIDE,
    check_floating_outputs,
    meta_imgsz,
    open_session,
    parse_names,
    parse_stride,
    read_input,
)

OUT = {"output0": np.zeros((1, 5, 10), np.float32)}


def session_of(tmp_path: Path, input_hw: tuple[int, int] | None) -> object:
    path = make_constant_yolo_onnx(tmp_path / "m.onnx", OUT, input_hw=input_hw)
    return open_session(path, 1)


def test_a_missing_a_folder_or_a_broken_file_is_named(tmp_path: Path) -> None:
    (tmp_path / "dir.onnx").mkdir()
    (tmp_path / "junk.onnx").write_bytes(b"not onnx")
    for name, words in (("none.onnx", "model file not found"), ("dir.onnx", "not a file"),
                        ("junk.onnx", "cannot load as an ONNX model")):
        with pytest.raises(ModelError, match=words) as err:
            open_session(tmp_path / name, 1)
        assert name in str(err.value) and "\n" not in str(err.value)


def test_a_fixed_input_is_used_as_it_is_and_a_different_size_refused(tmp_path: Path) -> None:
    s = session_of(tmp_path, (320, 480))
    inp = read_input(s, None, {}, tmp_path / "m.onnx")
    assert (inp.name, inp.dtype, inp.hw, inp.dynamic) == ("images", np.float32, (320, 480), False)
    assert read_input(s, (320, 480), {}, tmp_path / "m.onnx").hw == (320, 480)
    with pytest.raises(ModelError, match=r"fixed input of 320x480 \(HxW\); configured input_size \(640, 640\)"):
        read_input(s, 640, {}, tmp_path / "m.onnx")


def test_a_dynamic_input_takes_the_setting_then_the_metadata_then_the_default(tmp_path: Path) -> None:
    s = session_of(tmp_path, None)
    path = tmp_path / "m.onnx"
    assert read_input(s, 512, {"imgsz": "[256, 320]"}, path).hw == (512, 512)
    assert read_input(s, None, {"imgsz": "[256, 320]"}, path).hw == (256, 320)
    assert read_input(s, None, {"imgsz": "huge"}, path).hw == (DEFAULT_INPUT_SIZE,) * 2
    assert read_input(s, None, {}, path).dynamic
    with pytest.raises(ModelError, match=f"in \\[1, {MAX_INPUT_SIDE}\\]"):
        read_input(s, MAX_INPUT_SIDE + 1, {}, path)


def test_metadata_that_does_not_parse_is_ignored() -> None:
    assert parse_names({"names": "{0: 'grasper', 1: 'scissors'}"}) == {0: "grasper", 1: "scissors"}
    assert parse_names({"names": "['a', 'b']"}) == {0: "a", 1: "b"}
    assert parse_names({"names": "{'x': 'a'}"}) is None and parse_names({"names": "__import__('os')"}) is None
    assert parse_names({}) is None
    assert [parse_stride({"stride": s}) for s in ("16", "0", "x", "300")] == [16, 32, 32, 32]
    assert meta_imgsz({"imgsz": "640"}) == (640, 640) and meta_imgsz({"imgsz": "[1, 2, 3]"}) is None


def test_boxes_and_scores_must_be_floating_point(tmp_path: Path) -> None:
    layout = LayoutInfo(OutputLayout.YOLOV8, (0,), 1)
    check_floating_outputs(tmp_path / "m.onnx", layout, ["output0"], [np.zeros((1, 5, 3), np.float16)])
    with pytest.raises(ModelError, match="output 'output0' has dtype int64; YOLO boxes and scores must be floating"):
        check_floating_outputs(tmp_path / "m.onnx", layout, ["output0"], [np.zeros((1, 5, 3), np.int64)])
    split = LayoutInfo(OutputLayout.YOLOV7_E2E_SPLIT, (0, 1, 2, 3))
    outs = [np.zeros(1, np.int64), np.zeros((1, 4), np.float32), np.zeros(1, np.float32), np.zeros(1, np.int64)]
    check_floating_outputs(tmp_path / "m.onnx", split, ["num", "boxes", "scores", "classes"], outs)  # counts: ints
