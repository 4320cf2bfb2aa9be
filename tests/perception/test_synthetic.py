"""lapwrench.perception.synthetic: the drawn scenes, checkerboards and tiny ONNX models the perception
tests and benchmarks are built on must themselves be right: reproducible, with true ground truth."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from lapwrench.perception.synthetic import (
    board_object_points,
    checkerboard_texture,
    draw_instrument_scene,
    make_constant_yolo_onnx,
    make_tiny_conv_yolo_onnx,
    render_checkerboard_view,
)
from lapwrench.perception.yolo_model import open_session, parse_names, parse_stride


def test_a_scene_is_reproducible_from_its_seed() -> None:
    a, truth_a = draw_instrument_scene(seed=3)
    b, truth_b = draw_instrument_scene(seed=3)
    c, _ = draw_instrument_scene(seed=4)
    assert a.shape == (480, 640, 3) and a.dtype == np.uint8
    np.testing.assert_array_equal(a, b)
    assert truth_a == truth_b and not np.array_equal(a, c)


def test_the_ground_truth_is_where_the_instruments_are_drawn() -> None:
    img, truth = draw_instrument_scene((640, 480), 2, seed=11, n_bright_speckles=0, n_dark_speckles=0)
    assert len(truth) == 2
    grey = img.astype(float).mean(axis=2)
    for inst in truth:
        x0, y0, x1, y1 = inst.box
        assert 0 <= x0 < x1 <= 640 and 0 <= y0 < y1 <= 480
        u, v = inst.tip
        assert 0.2 * 640 <= u <= 0.8 * 640 and 0.2 * 480 <= v <= 0.8 * 480  # tips in the central 60 %
        assert x0 - 2 <= u <= x1 + 2 and y0 - 2 <= v <= y1 + 2
        shaft = np.asarray(inst.entry) + 0.4 * (np.asarray(inst.tip) - np.asarray(inst.entry))
        su, sv = np.clip(np.round(shaft).astype(int), 0, [639, 479])
        assert grey[sv, su] < 0.6 * np.median(grey)  # the shaft is dark against the tissue


def test_a_rendered_checkerboard_shows_its_corners_where_the_camera_projects_them() -> None:
    K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
    rvec, tvec = np.array([0.15, -0.1, 0.05]), np.array([-0.1, -0.06, 0.45])
    img = render_checkerboard_view(K, rvec, tvec, board=(9, 6), square_size=0.025)
    found, corners = cv2.findChessboardCorners(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), (9, 6))
    assert found
    expected, _ = cv2.projectPoints(board_object_points((9, 6), 0.025), rvec, tvec, K, None)
    err = np.linalg.norm(corners.reshape(-1, 2) - expected.reshape(-1, 2), axis=1)
    if err.max() > 2.0:  # OpenCV may report the grid from its other end
        err = np.linalg.norm(corners.reshape(-1, 2)[::-1] - expected.reshape(-1, 2), axis=1)
    assert err.max() < 1.0


def test_the_checkerboard_texture_has_its_inner_corners() -> None:
    tex = checkerboard_texture((4, 3), square_px=10, margin_px=5)
    assert tex.shape == (4 * 10 + 10, 5 * 10 + 10) and tex[5, 5] == 0 and tex[0, 0] == 255
    assert tex[5, 15] == 255 and tex[15, 15] == 0  # squares alternate


def test_the_constant_model_returns_its_tensors_whatever_the_image(tmp_path: Path) -> None:
    outs = {"boxes": np.arange(8, dtype=np.float32).reshape(1, 2, 4), "classes": np.array([[1, 0]], np.int64)}
    s = open_session(make_constant_yolo_onnx(tmp_path / "c.onnx", outs, metadata={"stride": "8"}), 1)
    for fill in (0.0, 1.0):
        got = s.run(None, {"images": np.full((1, 3, 640, 640), fill, np.float32)})
        np.testing.assert_array_equal(got[0], outs["boxes"])
        assert got[1].dtype == np.int64 and got[1].tolist() == [[1, 0]]
    assert parse_stride(s.get_modelmeta().custom_metadata_map) == 8


def test_the_tiny_conv_model_has_a_yolov8_shaped_output_at_stride_16(tmp_path: Path) -> None:
    s = open_session(make_tiny_conv_yolo_onnx(tmp_path / "t.onnx", num_classes=2, names=["a", "b"]), 1)
    (out,) = s.run(None, {"images": np.random.default_rng(0).random((1, 3, 320, 256), dtype=np.float32)})
    assert out.shape == (1, 4 + 2, (320 // 16) * (256 // 16))
    assert np.all(out[0, 4:] > 0) and np.all(out[0, 4:] < 1)  # class scores through a sigmoid
    meta = s.get_modelmeta().custom_metadata_map
    assert parse_names(meta) == {0: "a", 1: "b"} and parse_stride(meta) == 16
