"""Synthetic inputs for tests and benchmarks: drawn instrument scenes, checkerboards, tiny ONNX models.

Nothing here is used at run time by the controller. The ONNX builders import :mod:`onnx` (a dev
dependency) lazily.

- :func:`draw_instrument_scene`: a pink/red textured tissue background with dark shafts and light
  metallic jaws drawn with OpenCV, plus bright and dark speckles; returns the ground truth.
- :func:`render_checkerboard_view`: a planar checkerboard seen through a pinhole camera of known
  intrinsics (``cv2.projectPoints`` + ``warpPerspective``), for calibration tests.
- :func:`make_constant_yolo_onnx`: an ONNX graph that ignores its image (``ReduceMean * 0``) and
  emits fixed tensors, so each YOLO output layout can be decoded against known values.
- :func:`make_tiny_conv_yolo_onnx`: a small random-weight convolutional net with a YOLOv8-shaped
  output, a stand-in to time the ONNX pipeline (letterbox, session, decode, NMS) before a trained
  model exists. It detects nothing meaningful.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from lapwrench.perception.calibration import board_object_points as board_object_points

# --------------------------------------------------------------------------------------------
# Drawn laparoscopic scenes
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DrawnInstrument:
    """Ground truth of one drawn instrument: box xyxy (pixels, clipped), tip and entry point."""

    box: tuple[float, float, float, float]
    tip: tuple[float, float]
    entry: tuple[float, float]


def tissue_background(size: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """Pink/red tissue texture, RGB uint8, ``size = (width, height)``."""
    w, h = size
    base = np.array([205, 105, 115], dtype=np.float32) + rng.normal(0, 12, 3).astype(np.float32)
    # Low-frequency shading and mid-frequency texture.
    low = cv2.resize(rng.normal(0, 1, (6, 8)).astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC)
    mid = cv2.GaussianBlur(rng.normal(0, 1, (h, w)).astype(np.float32), (0, 0), 3.0) * 6.0
    shade = 1.0 + 0.18 * low + 0.05 * mid
    img = base[None, None, :] * shade[..., None]
    # Vignetting like a laparoscope.
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((xx - w / 2) / (w / 2)) ** 2 + ((yy - h / 2) / (h / 2)) ** 2
    img *= (1.0 - 0.35 * np.clip(r2 - 0.3, 0, None))[..., None]
    img += rng.normal(0, 4, img.shape).astype(np.float32)
    out = np.clip(img, 0, 255).astype(np.uint8)
    # Red vessels.
    for _ in range(int(rng.integers(3, 7))):
        pts = np.cumsum(rng.normal(0, 25, (8, 2)), axis=0) + rng.uniform([0, 0], [w, h])
        cv2.polylines(out, [pts.astype(np.int32)], False, (150, 30, 45), int(rng.integers(1, 4)), cv2.LINE_AA)
    return out


def draw_speckles(img: np.ndarray, rng: np.random.Generator, n_bright: int, n_dark: int) -> None:
    """Small bright (specular) and dark speckles, drawn in place."""
    h, w = img.shape[:2]
    for _ in range(n_bright):
        c = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        g = int(rng.integers(215, 256))
        cv2.circle(img, c, int(rng.integers(1, 5)), (g, g, g), -1, cv2.LINE_AA)
    for _ in range(n_dark):
        c = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        g = int(rng.integers(20, 60))
        cv2.circle(img, c, int(rng.integers(1, 6)), (g, g, g + 5), -1, cv2.LINE_AA)


def _border_point(size: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    w, h = size
    side = int(rng.integers(0, 4))
    t = rng.uniform(0.1, 0.9)
    return np.array([(t * w, -20.0), (t * w, h + 20.0), (-20.0, t * h), (w + 20.0, t * h)][side])


def draw_instrument(
    img: np.ndarray,
    entry: Sequence[float] | np.ndarray,
    tip: Sequence[float] | np.ndarray,
    rng: np.random.Generator,
    width: int = 16,
) -> DrawnInstrument:
    """Draw a dark shaft from ``entry`` to the jaw base and light jaws reaching ``tip``, in place."""
    h, w = img.shape[:2]
    entry_a = np.asarray(entry, dtype=np.float64)
    tip_a = np.asarray(tip, dtype=np.float64)
    axis = tip_a - entry_a
    length = float(np.linalg.norm(axis))
    d = axis / length
    n = np.array([-d[1], d[0]])
    jaw_len = min(0.3 * length, float(rng.uniform(25, 40)))
    base = tip_a - d * jaw_len
    mask = np.zeros((h, w), np.uint8)
    g = int(rng.integers(25, 65))
    shaft_col = (g, g, g + int(rng.integers(0, 8)))
    cv2.line(img, tuple(np.round(entry_a).astype(int)), tuple(np.round(base).astype(int)), shaft_col, width,
             cv2.LINE_AA)
    cv2.line(mask, tuple(np.round(entry_a).astype(int)), tuple(np.round(base).astype(int)), 255, width)
    # Highlight stripe along the shaft (cylindrical sheen), still dark.
    s = int(min(g + 35, 110))
    cv2.line(img, tuple(np.round(entry_a + n * width * 0.2).astype(int)),
             tuple(np.round(base + n * width * 0.2).astype(int)), (s, s, s + 4), max(2, width // 6), cv2.LINE_AA)
    # Two jaws diverging slightly.
    opening = float(rng.uniform(0.05, 0.35))
    jw = max(3, width // 3)
    for sign in (-1.0, 1.0):
        jd = d * np.cos(opening) + sign * n * np.sin(opening)
        end = base + jd * jaw_len
        start = base + sign * n * width * 0.2
        m = int(rng.integers(160, 215))
        cv2.line(img, tuple(np.round(start).astype(int)), tuple(np.round(end).astype(int)), (m, m, m + 6), jw,
                 cv2.LINE_AA)
        cv2.line(mask, tuple(np.round(start).astype(int)), tuple(np.round(end).astype(int)), 255, jw)
    ys, xs = np.nonzero(mask)
    box = (float(xs.min()), float(ys.min()), float(xs.max() + 1), float(ys.max() + 1))
    return DrawnInstrument(box=box, tip=(float(tip_a[0]), float(tip_a[1])),
                           entry=(float(entry_a[0]), float(entry_a[1])))


def draw_instrument_scene(
    size: tuple[int, int] = (640, 480),
    n_instruments: int = 2,
    *,
    seed: int | None = None,
    n_bright_speckles: int = 40,
    n_dark_speckles: int = 15,
    blur: float = 0.0,
    noise: float = 0.0,
) -> tuple[np.ndarray, list[DrawnInstrument]]:
    """A synthetic laparoscopic frame (RGB uint8) and the ground truth of its instruments.

    Each instrument enters from a random border point and its tip lies in the central 60 % of the
    image; bright and dark speckles are sprinkled over the tissue as distractors.
    """
    rng = np.random.default_rng(seed)
    w, h = size
    img = tissue_background(size, rng)
    draw_speckles(img, rng, n_bright_speckles, n_dark_speckles)
    truth = []
    for _ in range(n_instruments):
        for _attempt in range(20):
            entry = _border_point(size, rng)
            tip = rng.uniform([0.2 * w, 0.2 * h], [0.8 * w, 0.8 * h])
            if np.linalg.norm(tip - entry) > 0.25 * w:
                break
        truth.append(draw_instrument(img, entry, tip, rng, width=int(rng.integers(12, 22))))
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if noise > 0:
        img = np.clip(img.astype(np.float32) + rng.normal(0, noise, img.shape), 0, 255).astype(np.uint8)
    return img, truth


# --------------------------------------------------------------------------------------------
# Checkerboards seen by a pinhole camera
# --------------------------------------------------------------------------------------------


def checkerboard_texture(board: tuple[int, int], square_px: int = 40, margin_px: int = 40) -> np.ndarray:
    """A grayscale checkerboard with ``board = (cols, rows)`` inner corners and a white margin."""
    cols, rows = board
    sq_x, sq_y = cols + 1, rows + 1
    tex = np.full((sq_y * square_px + 2 * margin_px, sq_x * square_px + 2 * margin_px), 255, np.uint8)
    for j in range(sq_y):
        for i in range(sq_x):
            if (i + j) % 2 == 0:
                y0, x0 = margin_px + j * square_px, margin_px + i * square_px
                tex[y0:y0 + square_px, x0:x0 + square_px] = 0
    return tex


def render_checkerboard_view(
    camera_matrix: np.ndarray,
    rvec: Sequence[float],
    tvec: Sequence[float],
    *,
    board: tuple[int, int] = (9, 6),
    square_size: float = 0.025,
    image_size: tuple[int, int] = (640, 480),
    square_px: int = 40,
    background: int = 128,
) -> np.ndarray:
    """Render a planar checkerboard at pose ``(rvec, tvec)`` (board frame -> camera) as BGR uint8.

    The board lies in its plane ``Z = 0`` with the first inner corner at the origin and squares of
    ``square_size`` metres, matching :func:`board_object_points`. There is no lens distortion, so
    the image is an exact homography of the texture.
    """
    margin_px = square_px
    tex = checkerboard_texture(board, square_px, margin_px)
    th, tw = tex.shape
    # Texture pixel (x, y) -> board metres: the first inner corner sits at margin + square_px.
    origin = margin_px + square_px
    m_per_px = square_size / square_px
    corners_px = np.array([[0, 0], [tw, 0], [tw, th], [0, th]], np.float64)
    corners_m = np.c_[(corners_px - origin) * m_per_px, np.zeros(4)]
    img_pts, _ = cv2.projectPoints(corners_m, np.asarray(rvec, np.float64), np.asarray(tvec, np.float64),
                                   np.asarray(camera_matrix, np.float64), None)
    H = cv2.getPerspectiveTransform(corners_px.astype(np.float32), img_pts.reshape(4, 2).astype(np.float32))
    w, h = image_size
    gray = cv2.warpPerspective(tex, H, (w, h), flags=cv2.INTER_AREA, borderMode=cv2.BORDER_CONSTANT,
                               borderValue=background)
    return cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)


# --------------------------------------------------------------------------------------------
# Tiny ONNX models
# --------------------------------------------------------------------------------------------

_OPSET = 17
_IR_VERSION = 8


def _onnx_dtype(arr: np.ndarray) -> int:
    from onnx import helper

    return helper.np_dtype_to_tensor_dtype(arr.dtype)


def make_constant_yolo_onnx(
    path: str | os.PathLike[str],
    outputs: Mapping[str, np.ndarray],
    *,
    input_hw: tuple[int, int] | None = (640, 640),
    input_name: str = "images",
    metadata: Mapping[str, str] | None = None,
) -> Path:
    """Write an ONNX model that ignores its image and emits the given tensors.

    Each output is ``const + cast(ReduceMean(images) * 0)``, so the graph depends on the input but
    always returns ``outputs`` exactly (float outputs as float32, integer ones keep their dtype).

    Args:
        path: where to write the ``.onnx`` file.
        outputs: output name -> tensor, in output order.
        input_hw: fixed input ``(height, width)``; ``None`` makes H and W dynamic axes.
        input_name: the image input name.
        metadata: ``metadata_props`` (e.g. ultralytics' ``names``, ``stride``, ``imgsz``).
    """
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    in_shape: list[int | str] = [1, 3, *(input_hw if input_hw is not None else ("height", "width"))]
    nodes = [
        helper.make_node("ReduceMean", [input_name], ["mean"], keepdims=0),
        helper.make_node("Constant", [], ["zero_f"], value=numpy_helper.from_array(np.array(0.0, np.float32))),
        helper.make_node("Mul", ["mean", "zero_f"], ["zero"]),
    ]
    graph_outputs = []
    for name, value in outputs.items():
        arr = np.asarray(value)
        if arr.dtype.kind == "f":
            arr = arr.astype(np.float32)
        const = f"{name}_const"
        nodes.append(helper.make_node("Constant", [], [const], value=numpy_helper.from_array(arr, const)))
        if arr.dtype == np.float32:
            nodes.append(helper.make_node("Add", [const, "zero"], [name]))
        else:
            nodes.append(helper.make_node("Cast", ["zero"], [f"{name}_zero"], to=_onnx_dtype(arr)))
            nodes.append(helper.make_node("Add", [const, f"{name}_zero"], [name]))
        graph_outputs.append(helper.make_tensor_value_info(name, _onnx_dtype(arr), list(arr.shape)))
    graph = helper.make_graph(
        nodes, "constant_yolo", [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, in_shape)],
        graph_outputs,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", _OPSET)],
                              producer_name="lapwrench-tests")
    model.ir_version = _IR_VERSION
    if metadata:
        helper.set_model_props(model, dict(metadata))
    onnx.checker.check_model(model)
    out = Path(path)
    onnx.save(model, str(out))
    return out


def make_tiny_conv_yolo_onnx(
    path: str | os.PathLike[str],
    *,
    num_classes: int = 1,
    channels: Sequence[int] = (8, 16, 32, 32),
    seed: int = 0,
    names: Sequence[str] | None = None,
) -> Path:
    """Write a small random-weight conv net with a YOLOv8-shaped output ``[1, 4+nc, N]``.

    Four stride-2 3x3 convolutions (ReLU) and a 1x1 head at stride 16, dynamic input H and W.
    Box channels are ReLU-scaled, class channels pass a sigmoid with a negative bias so that only
    a few anchors clear a 0.25 threshold. A timing stand-in only: untrained, detects nothing real.
    """
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(seed)
    inits = []
    nodes = []
    prev, c_in = "images", 3
    for k, c_out in enumerate(channels):
        wname, bname, xname = f"w{k}", f"b{k}", f"x{k}"
        w = (rng.normal(0, np.sqrt(2.0 / (9 * c_in)), (c_out, c_in, 3, 3))).astype(np.float32)
        inits += [numpy_helper.from_array(w, wname), numpy_helper.from_array(np.zeros(c_out, np.float32), bname)]
        nodes.append(helper.make_node("Conv", [prev, wname, bname], [f"c{k}"], kernel_shape=[3, 3],
                                      strides=[2, 2], pads=[1, 1, 1, 1]))
        nodes.append(helper.make_node("Relu", [f"c{k}"], [xname]))
        prev, c_in = xname, c_out
    no = 4 + num_classes
    wh = rng.normal(0, 0.1, (no, c_in, 1, 1)).astype(np.float32)
    bh = np.r_[np.full(4, 8.0), np.full(num_classes, -4.0)].astype(np.float32)
    inits += [numpy_helper.from_array(wh, "wh"), numpy_helper.from_array(bh, "bh"),
              numpy_helper.from_array(np.array([1, no, -1], np.int64), "shape"),
              numpy_helper.from_array(np.array([4], np.int64), "split"),
              numpy_helper.from_array(np.array(4.0, np.float32), "box_scale")]
    inits += [numpy_helper.from_array(np.array([0], np.int64), "zero_i"),
              numpy_helper.from_array(np.array([1], np.int64), "one_i"),
              numpy_helper.from_array(np.array([no], np.int64), "end_c")]
    nodes += [
        helper.make_node("Conv", [prev, "wh", "bh"], ["head"], kernel_shape=[1, 1]),
        helper.make_node("Reshape", ["head", "shape"], ["flat"]),
        helper.make_node("Slice", ["flat", "zero_i", "split", "one_i"], ["box_raw"]),
        helper.make_node("Slice", ["flat", "split", "end_c", "one_i"], ["cls_raw"]),
        helper.make_node("Relu", ["box_raw"], ["box_pos"]),
        helper.make_node("Mul", ["box_pos", "box_scale"], ["boxes"]),
        helper.make_node("Sigmoid", ["cls_raw"], ["cls"]),
        helper.make_node("Concat", ["boxes", "cls"], ["output0"], axis=1),
    ]
    graph = helper.make_graph(
        nodes, "tiny_conv_yolo",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, "height", "width"])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, no, "anchors"])],
        initializer=inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", _OPSET)],
                              producer_name="lapwrench-bench")
    model.ir_version = _IR_VERSION
    names = list(names) if names is not None else [f"class{i}" for i in range(num_classes)]
    helper.set_model_props(model, {"names": repr(dict(enumerate(names))), "stride": "16",
                                   "description": "untrained timing stand-in"})
    onnx.checker.check_model(model)
    out = Path(path)
    onnx.save(model, str(out))
    return out
