"""Camera intrinsics from checkerboard images (Zhang's method, as the paper did, Sec. IV-A).

:func:`calibrate_from_images` finds the inner corners of a planar checkerboard in each view
(``cv2.findChessboardCorners`` + ``cv2.cornerSubPix``) and solves for the pinhole intrinsics and
the plumb-bob distortion with ``cv2.calibrateCamera``. :func:`write_intrinsics_yaml` writes the
result: the ``camera: {width, height, fx, fy, u0, v0}`` section the controller's configuration
reads, and a ``calibration:`` section (plumb-bob distortion, RMS reprojection error, views). With
``split=True`` the two go to separate files, ``intrinsics.yaml`` (``camera:`` only, loadable by
``lapwrench.config.load``) and ``intrinsics.calibration.yaml``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

ImageSource = str | os.PathLike[str] | np.ndarray


class CalibrationError(RuntimeError):
    """Calibration failed: unreadable images, inconsistent sizes, or too few usable views."""


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """Intrinsics estimated by :func:`calibrate_from_images`.

    Attributes:
        width, height: image size in pixels.
        camera_matrix: 3x3 ``K`` (``fx, fy, u0, v0``; zero skew).
        dist_coeffs: plumb-bob distortion ``(k1, k2, p1, p2, k3)``.
        rms: RMS reprojection error over all corners (pixels), as returned by OpenCV.
        per_view_errors: RMS reprojection error of each used view (pixels).
        used: labels of the views whose board was found (paths or ``"array[i]"``).
        rejected: labels of the views whose board was not found.
        board: inner corners ``(cols, rows)``.
        square_size: board square edge (the unit of the extrinsics, e.g. metres).
    """

    width: int
    height: int
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rms: float
    per_view_errors: tuple[float, ...]
    used: tuple[str, ...]
    rejected: tuple[str, ...]
    board: tuple[int, int]
    square_size: float
    rvecs: tuple[np.ndarray, ...] = field(default=(), repr=False)
    tvecs: tuple[np.ndarray, ...] = field(default=(), repr=False)

    @property
    def fx(self) -> float:
        return float(self.camera_matrix[0, 0])

    @property
    def fy(self) -> float:
        return float(self.camera_matrix[1, 1])

    @property
    def u0(self) -> float:
        return float(self.camera_matrix[0, 2])

    @property
    def v0(self) -> float:
        return float(self.camera_matrix[1, 2])

    def to_dict(self) -> dict[str, Any]:
        """The intrinsics YAML content as plain Python types."""
        k1, k2, p1, p2, k3 = (float(c) for c in np.ravel(self.dist_coeffs)[:5])
        return {
            "camera": {
                "width": int(self.width),
                "height": int(self.height),
                "fx": round(self.fx, 4),
                "fy": round(self.fy, 4),
                "u0": round(self.u0, 4),
                "v0": round(self.v0, 4),
            },
            "calibration": {
                "method": "Zhang (OpenCV findChessboardCorners + cornerSubPix + calibrateCamera)",
                "distortion": {"model": "plumb_bob", "k1": k1, "k2": k2, "p1": p1, "p2": p2, "k3": k3},
                "rms_reprojection_error_px": round(float(self.rms), 5),
                "views_used": len(self.used),
                "views_rejected": list(self.rejected),
                "board": {"cols": int(self.board[0]), "rows": int(self.board[1]),
                          "square_size": float(self.square_size)},
            },
        }


def board_object_points(board: tuple[int, int], square_size: float) -> np.ndarray:
    """Inner-corner coordinates ``(cols*rows, 3)`` in the board plane ``Z = 0``, row-major."""
    cols, rows = board
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2).astype(np.float32)
    return np.c_[grid * square_size, np.zeros(len(grid), np.float32)].astype(np.float32)


def _load_gray(src: ImageSource, label: str) -> np.ndarray:
    img: np.ndarray | None
    if isinstance(src, np.ndarray):
        img = src
    else:
        path = Path(src)
        if not path.is_file():
            raise CalibrationError(f"{label}: {'not a file' if path.exists() else 'image file not found'}")
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise CalibrationError(f"{label}: not a readable image")
    if img.size == 0:
        raise CalibrationError(f"{label}: empty image")
    if img.dtype != np.uint8:
        raise CalibrationError(f"{label}: image dtype must be uint8, got {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    if img.ndim == 2:
        return np.ascontiguousarray(img)
    raise CalibrationError(f"{label}: expected a gray or colour image, got shape {img.shape}")


def find_board_corners(gray: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners ``(cols*rows, 1, 2)`` of the checkerboard, or ``None`` if not found."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    found, corners = cv2.findChessboardCorners(gray, board, flags=flags)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    return cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), criteria)


def calibrate_from_images(
    images: Sequence[ImageSource],
    board: tuple[int, int] = (9, 6),
    square_size: float = 0.025,
    *,
    min_views: int = 3,
    fix_k3: bool = False,
) -> CalibrationResult:
    """Estimate camera intrinsics from checkerboard views (Zhang's method).

    Args:
        images: image paths or arrays (gray, BGR or BGRA uint8), all the same size.
        board: number of *inner* corners ``(cols, rows)`` (a 10x7-square board has 9x6).
        square_size: square edge length; sets the unit of the extrinsics only.
        min_views: fewest views with a detected board to attempt a calibration.
        fix_k3: hold the third radial coefficient at zero (advisable with few views).

    Raises:
        CalibrationError: unreadable or mismatched images, or fewer than ``min_views`` boards found.
    """
    if len(images) == 0:
        raise CalibrationError("no calibration images given")
    if board[0] < 2 or board[1] < 2:
        raise CalibrationError(f"board must have at least 2x2 inner corners, got {board}")
    if not square_size > 0:
        raise CalibrationError(f"square_size must be positive, got {square_size}")
    obj = board_object_points(board, square_size)
    size: tuple[int, int] | None = None
    obj_pts, img_pts, used, rejected = [], [], [], []
    for i, src in enumerate(images):
        label = f"array[{i}]" if isinstance(src, np.ndarray) else str(src)
        gray = _load_gray(src, label)
        hw = (gray.shape[1], gray.shape[0])
        if size is None:
            size = hw
        elif hw != size:
            raise CalibrationError(f"{label}: size {hw[0]}x{hw[1]} differs from {size[0]}x{size[1]}")
        corners = find_board_corners(gray, board)
        if corners is None:
            rejected.append(label)
            continue
        obj_pts.append(obj)
        img_pts.append(corners)
        used.append(label)
    assert size is not None
    if len(used) < min_views:
        raise CalibrationError(
            f"checkerboard {board[0]}x{board[1]} (inner corners) found in {len(used)} of {len(images)} "
            f"images; at least {min_views} needed (check the board size and the images)"
        )
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj_pts, img_pts, size, None, None, flags=flags)
    errors = []
    for o, p, r, t in zip(obj_pts, img_pts, rvecs, tvecs, strict=True):
        proj, _ = cv2.projectPoints(o, r, t, K, dist)
        errors.append(float(np.sqrt(np.mean(np.sum((proj - p) ** 2, axis=2)))))
    return CalibrationResult(
        width=size[0], height=size[1], camera_matrix=np.asarray(K, np.float64),
        dist_coeffs=np.asarray(dist, np.float64).ravel()[:5], rms=float(rms),
        per_view_errors=tuple(errors), used=tuple(used), rejected=tuple(rejected),
        board=(int(board[0]), int(board[1])), square_size=float(square_size),
        rvecs=tuple(rvecs), tvecs=tuple(tvecs),
    )


def write_intrinsics_yaml(
    result: CalibrationResult, path: str | os.PathLike[str], *, split: bool = False
) -> Any:
    """Write the intrinsics YAML and return its path.

    With ``split=False`` one file holds the ``camera`` section and the ``calibration`` details.
    With ``split=True`` (what the ``calibrate`` command writes) ``path`` holds only the ``camera``
    section, so :func:`lapwrench.config.load` accepts it as a configuration file (it rejects unknown
    top-level keys), and the details go to ``<stem>.calibration.yaml`` beside it; the return value
    is then ``(camera_path, details_path)``. :func:`read_intrinsics_yaml` reads either form.
    """
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    header = (
        "# Camera intrinsics estimated by lapwrench (Zhang's method).\n"
        f"# RMS reprojection error {result.rms:.4f} px over {len(result.used)} views.\n"
    )
    data = result.to_dict()
    if not split:
        out.write_text(header + yaml.safe_dump(data, sort_keys=False))
        return out
    details = calibration_details_path(out)
    out.write_text(header + f"# Distortion and per-view details: {details.name}\n"
                   + yaml.safe_dump({"camera": data["camera"]}, sort_keys=False))
    details.write_text(header + yaml.safe_dump({"calibration": data["calibration"]}, sort_keys=False))
    return out, details


def calibration_details_path(path: str | os.PathLike[str]) -> Path:
    """``<stem>.calibration.yaml`` beside an intrinsics YAML."""
    p = Path(path)
    return p.with_name(f"{p.stem}.calibration.yaml")


def read_intrinsics_yaml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read an intrinsics YAML back as a mapping (``camera`` section required).

    A ``calibration`` section is taken from the file itself or, when absent, from the
    ``<stem>.calibration.yaml`` file beside it (the split form written by ``calibrate``).
    """
    p = Path(path)
    if not p.is_file():
        raise CalibrationError(f"{p}: intrinsics file not found")
    try:
        data = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise CalibrationError(f"{p}: not valid YAML: {exc}") from exc
    if not isinstance(data, dict) or not isinstance(data.get("camera"), dict):
        raise CalibrationError(f"{p}: no 'camera' section")
    missing = {"width", "height", "fx", "fy", "u0", "v0"} - set(data["camera"])
    if missing:
        raise CalibrationError(f"{p}: camera section lacks {sorted(missing)}")
    details = calibration_details_path(p)
    if "calibration" not in data and details.is_file():
        extra = yaml.safe_load(details.read_text())
        if isinstance(extra, dict) and isinstance(extra.get("calibration"), dict):
            data["calibration"] = extra["calibration"]
    return data
