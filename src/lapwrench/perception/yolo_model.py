"""Loading a YOLO ONNX export: the onnxruntime session, its metadata and its image input.

Everything here checks the model before the detector uses it, so that a bad file, input or output
raises :class:`~lapwrench.perception.detection.ModelError` naming the file. Metadata (ultralytics'
``names``, ``stride``, ``imgsz``) is a hint: a value that does not parse is ignored.
"""

from __future__ import annotations

import ast
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lapwrench.perception.detection import ModelError
from lapwrench.perception.yolo_layout import LayoutInfo, OutputLayout

__all__ = [
    "DEFAULT_INPUT_SIZE",
    "MAX_INPUT_SIDE",
    "ModelInput",
    "check_floating_outputs",
    "open_session",
    "parse_names",
    "parse_stride",
    "read_input",
]

DEFAULT_INPUT_SIZE = 640
MAX_INPUT_SIDE = 8192
"""Largest network input side accepted (from the model, its ``imgsz`` metadata or ``input_size``)."""


def open_session(path: Path, num_threads: int) -> Any:
    """An onnxruntime CPU session for the model file ``path`` (sequential, ``num_threads`` intra-op).

    Raises:
        ModelError: the file is missing, not a file, or not a loadable ONNX model.
    """
    import onnxruntime as ort

    if not path.exists():
        raise ModelError(path, "model file not found")
    if not path.is_file():
        raise ModelError(path, "model path is not a file")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = max(1, int(num_threads))
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    opts.log_severity_level = 3
    try:
        return ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
    except Exception as exc:
        raise ModelError(path, f"cannot load as an ONNX model ({type(exc).__name__}: {exc})") from exc


@dataclass(frozen=True)
class ModelInput:
    """The model's image input: its name, dtype, network ``(height, width)`` and whether it is dynamic."""

    name: str
    dtype: type[np.floating[Any]]
    hw: tuple[int, int]
    dynamic: bool



def read_input(session: Any, input_size: int | tuple[int, int] | None, meta: dict[str, str],
               path: Path) -> ModelInput:
    """The model's one image input, checked: float/float16 ``[1, 3, H, W]``.

    A fixed ``H x W`` is used as it is (``input_size``, if given, must equal it); a dynamic one becomes
    ``input_size``, else the ``imgsz`` metadata, else :data:`DEFAULT_INPUT_SIZE`.

    Raises:
        ModelError: the input is not one image tensor of a usable size.
    """
    inputs = session.get_inputs()
    if len(inputs) != 1:
        raise ModelError(path, f"expected one image input, found {len(inputs)}: {[i.name for i in inputs]}")
    inp = inputs[0]
    if inp.type not in ("tensor(float)", "tensor(float16)"):
        raise ModelError(path, f"input '{inp.name}' has type {inp.type}; expected float/float16")
    dtype = np.float16 if inp.type == "tensor(float16)" else np.float32
    shape = list(inp.shape)
    if len(shape) != 4 or _static_dim(shape[1]) not in (3, None):
        raise ModelError(path, f"input '{inp.name}' has shape {shape}; expected [1, 3, H, W]")
    h, w = _static_dim(shape[2]), _static_dim(shape[3])
    wanted: tuple[int, int] | None = None
    if input_size is not None:
        wanted = (input_size, input_size) if isinstance(input_size, int) else tuple(input_size)  # type: ignore[assignment]
        if len(wanted) != 2 or not _valid_size(wanted):  # type: ignore[arg-type]
            raise ModelError(path, f"configured input_size {str(input_size)[:60]} is not two sizes "
                                   f"in [1, {MAX_INPUT_SIDE}]")
    if h is not None and w is not None:
        if not _valid_size((h, w)):
            raise ModelError(path, f"model input of {h}x{w} (HxW) is beyond {MAX_INPUT_SIDE} px")
        if wanted is not None and wanted != (h, w):
            raise ModelError(path, f"model has a fixed input of {h}x{w} (HxW); "
                                   f"configured input_size {wanted} differs")
        return ModelInput(inp.name, dtype, (h, w), False)
    if wanted is None:
        wanted = meta_imgsz(meta) or (DEFAULT_INPUT_SIZE, DEFAULT_INPUT_SIZE)
    return ModelInput(inp.name, dtype, (int(wanted[0]), int(wanted[1])), True)


def _static_dim(d: Any) -> int | None:
    return int(d) if isinstance(d, int) and d > 0 else None


def _literal(text: str | None) -> object:
    """A metadata value parsed as a Python literal, or None when it is not one (metadata is a hint:
    a model with unreadable metadata still loads, with the defaults)."""
    if not text or len(text) > 100_000:
        return None
    try:
        return ast.literal_eval(text)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return None


def parse_names(meta: dict[str, str]) -> dict[int, str] | None:
    """Class names from ultralytics' ``names`` metadata (``{0: 'a', ...}`` or ``['a', ...]``), else None."""
    parsed = _literal(meta.get("names"))
    if isinstance(parsed, dict):
        if not all(type(k) is int for k in parsed):
            return None
        return {k: str(v) for k, v in parsed.items()}
    if isinstance(parsed, list | tuple):
        return {i: str(v) for i, v in enumerate(parsed)}
    return None


def parse_stride(meta: dict[str, str]) -> int:
    """The model's stride from its metadata: a whole number in [1, 256], else YOLO's usual 32."""
    try:
        stride = float(meta.get("stride", 32))
    except (TypeError, ValueError):
        return 32
    return int(stride) if 1.0 <= stride <= 256.0 else 32


def _valid_size(hw: tuple[object, object]) -> bool:
    """Two whole sizes in [1, MAX_INPUT_SIDE]."""
    return all(type(d) is int and 1 <= d <= MAX_INPUT_SIDE for d in hw)


def meta_imgsz(meta: dict[str, str]) -> tuple[int, int] | None:
    """The ``imgsz`` metadata as (h, w) if it is one or two sizes in [1, MAX_INPUT_SIDE], else None."""
    val = _literal(meta.get("imgsz"))
    hw = (val, val) if type(val) is int else tuple(val) if isinstance(val, list | tuple) else ()
    return hw if len(hw) == 2 and _valid_size(hw) else None


def check_floating_outputs(path: Path, layout: LayoutInfo, names: list[str], outputs: Sequence[object]) -> None:
    """The tensors holding boxes and scores must be floating point (item 8 of issue 11: an integer
    output was accepted silently, and every score was rounded to 0 or 1)."""
    roles = layout.outputs[1:3] if layout.layout is OutputLayout.YOLOV7_E2E_SPLIT else layout.outputs[:1]
    for i in roles:
        dtype = getattr(outputs[i], "dtype", None)
        if dtype is None or np.dtype(dtype).kind != "f":
            kind = np.dtype(dtype).name if dtype is not None else type(outputs[i]).__name__
            raise ModelError(path, f"output '{names[i]}' has dtype {kind}; YOLO boxes and scores must be "
                                   "floating point (float32/float16)")
