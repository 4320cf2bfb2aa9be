"""The perception CLI functions: calibrate (glob -> config-loadable intrinsics), dataset, train."""

from __future__ import annotations

import argparse
import importlib.util
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import make_renderable_world

from lapwrench.config import load
from lapwrench.perception import read_intrinsics_yaml
from lapwrench.perception.cli import (
    add_calibrate_arguments,
    add_dataset_arguments,
    add_train_arguments,
    calibrate_main,
    dataset_main,
    main,
    train_main,
)
from lapwrench.perception.synthetic import render_checkerboard_view

FX, FY, U0, V0 = 506.57, 506.72, 312.22, 243.39
K = np.array([[FX, 0, U0], [0, FY, V0], [0, 0, 1]])
BOARD = (9, 6)
SQUARE = 0.025
POSES = [((0.0, 0.0, 0.0), (0.0, 0.0, 0.45)), ((0.4, 0.0, 0.0), (0.0, 0.0, 0.45)),
         ((-0.4, 0.0, 0.1), (0.0, 0.0, 0.50)), ((0.0, 0.45, 0.0), (0.0, 0.0, 0.45)),
         ((0.0, -0.45, -0.1), (0.0, 0.0, 0.50)), ((0.3, 0.3, 0.2), (0.03, -0.02, 0.42))]


def render_views() -> list[np.ndarray]:
    centre = np.array([(BOARD[0] - 1) * SQUARE / 2, (BOARD[1] - 1) * SQUARE / 2, 0.0])
    views = []
    for rvec, pos in POSES:
        R, _ = cv2.Rodrigues(np.array(rvec))
        views.append(render_checkerboard_view(K, rvec, np.array(pos) - R @ centre, board=BOARD, square_size=SQUARE))
    return views


def parse(add: Callable[[argparse.ArgumentParser], None], argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add(p)
    return p.parse_args(argv)


def test_calibrate_writes_config_loadable_intrinsics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for i, img in enumerate(render_views()):
        cv2.imwrite(str(tmp_path / f"view_{i:02d}.png"), img)
    out = tmp_path / "cal" / "intrinsics.yaml"
    args = parse(add_calibrate_arguments, [str(tmp_path / "view_*.png"), "--board", "9x6", "--square",
                                           str(SQUARE), "--out", str(out)])
    assert args.board == BOARD
    assert calibrate_main(args) == 0
    text = capsys.readouterr().out
    assert "intrinsics.calibration.yaml" in text and "use it" in text
    cfg = load(out)  # the camera-only file is a valid configuration (other sections default)
    assert cfg.camera.fx == pytest.approx(FX, rel=0.01) and cfg.camera.fy == pytest.approx(FY, rel=0.01)
    assert abs(cfg.camera.u0 - U0) < 3 and abs(cfg.camera.v0 - V0) < 3
    data = read_intrinsics_yaml(out)
    assert data["calibration"]["distortion"]["model"] == "plumb_bob"
    assert data["calibration"]["rms_reprojection_error_px"] < 0.5


def test_calibrate_bad_inputs_give_clear_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = parse(add_calibrate_arguments, [str(tmp_path / "nothing_*.png"), "--out", str(tmp_path / "i.yaml")])
    assert calibrate_main(args) == 2
    assert "image file not found" in capsys.readouterr().err
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((48, 64, 3), 255, np.uint8))
    args = parse(add_calibrate_arguments, [str(blank), str(blank), str(blank), "--out", str(tmp_path / "i.yaml")])
    assert calibrate_main(args) == 2
    assert "found in 0 of 3" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parse(add_calibrate_arguments, ["x.png", "--board", "nine"])


def test_dataset_main_tiny(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("mujoco")
    make_renderable_world().close()  # skips (naming why) only when headless rendering is unavailable
    args = parse(add_dataset_arguments, ["--out", str(tmp_path), "--train", "1", "--val", "0", "--test", "1",
                                         "--splits", "train,test"])
    assert dataset_main(args) == 0
    assert (tmp_path / "data.yaml").is_file() and len(list((tmp_path / "images" / "test").glob("*.jpg"))) == 1
    assert "data file" in capsys.readouterr().out
    with pytest.raises(SystemExit) as info:  # refused as it is parsed (issue 11, item 10)
        parse(add_dataset_arguments, ["--out", str(tmp_path), "--splits", "bogus"])
    assert info.value.code == 2
    bad = parse(add_dataset_arguments, ["--out", str(tmp_path)])
    bad.splits = "bogus"  # as a program calling dataset_main would pass it
    assert dataset_main(bad) == 2


def test_train_main_without_torch_or_data_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = parse(add_train_arguments, ["--data", str(tmp_path / "missing.yaml")])
    assert train_main(args) == 2
    err = capsys.readouterr().err
    if importlib.util.find_spec("ultralytics") is None:
        assert "scripts/train_detector.sh setup" in err or "not found" in err
    else:
        assert "not found" in err


def test_module_main_dispatches(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "calibrate" in capsys.readouterr().out


def test_output_paths_and_numbers_are_checked_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 11 item 10: an output under a plain file (unwritable even as root), a folder given for a file
    and nonsense numbers end in argparse's one error line (exit 2), not a traceback after the work."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for add, argv in ((add_calibrate_arguments, ["x.png", "--out", str(blocker / "i.yaml")]),
                      (add_calibrate_arguments, ["x.png", "--out", str(tmp_path)]),
                      (add_calibrate_arguments, ["x.png", "--square", "nan"]),
                      (add_calibrate_arguments, ["x.png", "--min-views", "0"]),
                      (add_dataset_arguments, ["--out", str(blocker / "ds")]),
                      (add_dataset_arguments, ["--train", "-5"]),
                      (add_train_arguments, ["--ship", str(blocker / "m.onnx")]),
                      (add_train_arguments, ["--epochs", "0"])):
        with pytest.raises(SystemExit) as info:
            parse(add, argv)
        assert info.value.code == 2
    assert "Traceback" not in capsys.readouterr().err
    # the details file written beside --out is a folder: refused before calibrating
    (tmp_path / "i.calibration.yaml").mkdir()
    args = parse(add_calibrate_arguments, ["x.png", "--out", str(tmp_path / "i.yaml")])
    assert calibrate_main(args) == 2 and "i.calibration.yaml" in capsys.readouterr().err
