"""Zhang calibration on checkerboards rendered through a known pinhole camera (paper Sec. IV-A)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from lapwrench.perception import (
    CalibrationError,
    calibrate_from_images,
    read_intrinsics_yaml,
    write_intrinsics_yaml,
)
from lapwrench.perception.synthetic import render_checkerboard_view

FX, FY, U0, V0 = 506.57, 506.72, 312.22, 243.39
K = np.array([[FX, 0, U0], [0, FY, V0], [0, 0, 1]])
BOARD = (9, 6)
SQUARE = 0.025
# (rotation vector of the board, board-centre position in the camera frame [m]).
POSES = [
    ((0.0, 0.0, 0.0), (0.0, 0.0, 0.45)),
    ((0.4, 0.0, 0.0), (0.0, 0.0, 0.45)),
    ((-0.4, 0.0, 0.1), (0.0, 0.0, 0.50)),
    ((0.0, 0.45, 0.0), (0.0, 0.0, 0.45)),
    ((0.0, -0.45, -0.1), (0.0, 0.0, 0.50)),
    ((0.3, 0.3, 0.2), (0.03, -0.02, 0.42)),
    ((-0.3, 0.35, -0.2), (-0.03, 0.02, 0.48)),
    ((0.35, -0.3, 0.3), (0.02, 0.03, 0.45)),
]


def render_views() -> list[np.ndarray]:
    centre = np.array([(BOARD[0] - 1) * SQUARE / 2, (BOARD[1] - 1) * SQUARE / 2, 0.0])
    views = []
    for rvec, pos in POSES:
        R, _ = cv2.Rodrigues(np.array(rvec))
        tvec = np.array(pos) - R @ centre
        views.append(render_checkerboard_view(K, rvec, tvec, board=BOARD, square_size=SQUARE))
    return views


@pytest.fixture(scope="module")
def views() -> list[np.ndarray]:
    return render_views()


def test_recovers_known_intrinsics(views: list[np.ndarray]) -> None:
    res = calibrate_from_images(views, board=BOARD, square_size=SQUARE)
    assert (res.width, res.height) == (640, 480)
    assert res.fx == pytest.approx(FX, rel=0.01)
    assert res.fy == pytest.approx(FY, rel=0.01)
    assert abs(res.u0 - U0) < 3.0
    assert abs(res.v0 - V0) < 3.0
    assert res.rms < 0.5
    assert len(res.used) == len(POSES) and res.rejected == ()
    assert len(res.per_view_errors) == len(POSES)


def test_from_files_with_a_view_without_board(views: list[np.ndarray], tmp_path: Path) -> None:
    paths = []
    for i, v in enumerate(views):
        p = tmp_path / f"view{i}.png"
        cv2.imwrite(str(p), v)
        paths.append(p)
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640), 128, np.uint8))
    res = calibrate_from_images([*paths, blank], board=BOARD, square_size=SQUARE, fix_k3=True)
    assert res.rejected == (str(blank),)
    assert res.fx == pytest.approx(FX, rel=0.01)


def test_writes_intrinsics_yaml(views: list[np.ndarray], tmp_path: Path) -> None:
    res = calibrate_from_images(views, board=BOARD, square_size=SQUARE)
    path = write_intrinsics_yaml(res, tmp_path / "sub" / "intrinsics.yaml")
    data = yaml.safe_load(path.read_text())
    assert set(data["camera"]) == {"width", "height", "fx", "fy", "u0", "v0"}
    assert data["camera"]["width"] == 640 and data["camera"]["height"] == 480
    assert data["camera"]["fx"] == pytest.approx(res.fx, abs=1e-3)
    dist = data["calibration"]["distortion"]
    assert dist["model"] == "plumb_bob" and set(dist) >= {"k1", "k2", "p1", "p2", "k3"}
    assert data["calibration"]["rms_reprojection_error_px"] == pytest.approx(res.rms, abs=1e-4)
    assert read_intrinsics_yaml(path)["camera"]["v0"] == pytest.approx(res.v0, abs=1e-3)


def test_too_few_boards(views: list[np.ndarray]) -> None:
    blank = np.full((480, 640, 3), 128, np.uint8)
    with pytest.raises(CalibrationError, match="found in 2 of 4"):
        calibrate_from_images([views[0], views[1], blank, blank], board=BOARD, square_size=SQUARE)


def test_wrong_board_size_finds_nothing(views: list[np.ndarray]) -> None:
    with pytest.raises(CalibrationError, match="found in 0"):
        calibrate_from_images(views[:3], board=(7, 7), square_size=SQUARE)


def test_bad_inputs(views: list[np.ndarray], tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match="no calibration images"):
        calibrate_from_images([], board=BOARD)
    with pytest.raises(CalibrationError, match="not found"):
        calibrate_from_images([tmp_path / "missing.png"], board=BOARD)
    with pytest.raises(CalibrationError, match="not a file"):  # a folder is there, not missing
        calibrate_from_images([tmp_path], board=BOARD)
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"nope")
    with pytest.raises(CalibrationError, match="not a readable image"):
        calibrate_from_images([junk], board=BOARD)
    with pytest.raises(CalibrationError, match="differs"):
        calibrate_from_images([views[0], np.zeros((240, 320), np.uint8)], board=BOARD)
    with pytest.raises(CalibrationError, match="uint8"):
        calibrate_from_images([views[0].astype(np.float32)], board=BOARD)
    bad = tmp_path / "bad.yaml"
    bad.write_text("camera: {fx: 1}\n")
    with pytest.raises(CalibrationError, match="lacks"):
        read_intrinsics_yaml(bad)
