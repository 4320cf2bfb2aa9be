"""Train a small YOLO on the synthetic dataset with ultralytics, on the CPU, and export ONNX.

Optional extra (``scripts/train_detector.sh``): needs ``torch==2.13.0`` (CPU build) and
ultralytics, installed in the separate ``.venv-train``. Nothing here is imported by the controller
or by CI; :mod:`torch` and :mod:`ultralytics` are imported inside the functions.

Offline by construction: the model is built from a yaml written here (:data:`MODEL_SCALES`), no
weights are downloaded; :func:`prepare_offline_env` sets ``YOLO_OFFLINE=1``, a project-local
``YOLO_CONFIG_DIR`` holding a local TrueType font as ``Arial.ttf`` / ``Arial.Unicode.ttf`` (the
plotting code would otherwise fetch it) and ``sync=False``; :mod:`torch_compat` makes PyPI's
torchvision usable beside the CPU torch.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

# The YOLO11 detection architecture (ultralytics' cfg/models/11/yolo11.yaml) with extra, slimmer
# compound scales: [depth, width, max_channels]. "p" (pico) halves the width of "n"
# (channels 8-128 instead of 16-256): about a quarter of YOLO11n's FLOPs.
MODEL_SCALES: dict[str, tuple[float, float, int]] = {
    "p": (0.33, 0.125, 256),
    "u": (0.50, 0.1875, 384),
    "n": (0.50, 0.25, 1024),
}

_YOLO11_BODY = """backbone:
  - [-1, 1, Conv, [64, 3, 2]] # 0-P1/2
  - [-1, 1, Conv, [128, 3, 2]] # 1-P2/4
  - [-1, 2, C3k2, [256, False, 0.25]]
  - [-1, 1, Conv, [256, 3, 2]] # 3-P3/8
  - [-1, 2, C3k2, [512, False, 0.25]]
  - [-1, 1, Conv, [512, 3, 2]] # 5-P4/16
  - [-1, 2, C3k2, [512, True]]
  - [-1, 1, Conv, [1024, 3, 2]] # 7-P5/32
  - [-1, 2, C3k2, [1024, True]]
  - [-1, 1, SPPF, [1024, 5]] # 9
  - [-1, 2, C2PSA, [1024]] # 10
head:
  - [-1, 1, nn.Upsample, [None, 2, "nearest"]]
  - [[-1, 6], 1, Concat, [1]] # cat backbone P4
  - [-1, 2, C3k2, [512, False]] # 13
  - [-1, 1, nn.Upsample, [None, 2, "nearest"]]
  - [[-1, 4], 1, Concat, [1]] # cat backbone P3
  - [-1, 2, C3k2, [256, False]] # 16 (P3/8-small)
  - [-1, 1, Conv, [256, 3, 2]]
  - [[-1, 13], 1, Concat, [1]] # cat head P4
  - [-1, 2, C3k2, [512, False]] # 19 (P4/16-medium)
  - [-1, 1, Conv, [512, 3, 2]]
  - [[-1, 10], 1, Concat, [1]] # cat head P5
  - [-1, 2, C3k2, [1024, True]] # 22 (P5/32-large)
  - [[16, 19, 22], 1, Detect, [nc]] # Detect(P3, P4, P5)
"""


def model_yaml_text(scale: str, nc: int = 1) -> str:
    """The ultralytics model yaml of YOLO11 at ``scale`` (a key of :data:`MODEL_SCALES`)."""
    if scale not in MODEL_SCALES:
        raise ValueError(f"unknown model scale {scale!r}; choose one of {sorted(MODEL_SCALES)}")
    d, w, c = MODEL_SCALES[scale]
    return (f"# YOLO11-{scale} for lapwrench (depth {d}, width {w}, max channels {c})\n"
            f"nc: {nc}\nscales:\n  {scale}: [{d}, {w}, {c}]\n" + _YOLO11_BODY)


def write_model_yaml(directory: str | os.PathLike[str], scale: str, nc: int = 1) -> Path:
    """Write ``yolo11{scale}.yaml`` (the file name selects the scale in ultralytics)."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    out = d / f"yolo11{scale}.yaml"
    out.write_text(model_yaml_text(scale, nc))
    return out


def prepare_offline_env(config_dir: str | os.PathLike[str]) -> Path:
    """Environment for ultralytics with no network: offline flag, local config dir and fonts.

    Must run before ultralytics is imported. Returns the config directory.
    """
    cfg = Path(config_dir).resolve()
    (cfg / "Ultralytics").mkdir(parents=True, exist_ok=True)
    os.environ["YOLO_OFFLINE"] = "1"
    os.environ["YOLO_CONFIG_DIR"] = str(cfg)
    font = _local_font()
    if font is not None:
        for d in (cfg, cfg / "Ultralytics"):
            for name in ("Arial.ttf", "Arial.Unicode.ttf"):
                if not (d / name).exists():
                    shutil.copyfile(font, d / name)
    from lapwrench.perception.torch_compat import install_import_hook

    install_import_hook()
    return cfg


def _local_font() -> Path | None:
    for root in ("/usr/share/fonts", "/usr/local/share/fonts"):
        fonts = sorted(Path(root).rglob("*.ttf")) if Path(root).is_dir() else []
        for f in fonts:
            if f.name == "DejaVuSans.ttf":
                return f
        if fonts:
            return fonts[0]
    return None


@dataclass(frozen=True)
class TrainSettings:
    """One training run (ultralytics argument names where they exist)."""

    data: str
    out_dir: str = "out/train"
    name: str = "instruments"
    scale: str = "n"
    imgsz: int = 320
    epochs: int = 60
    batch: int = 16
    seed: int = 0
    workers: int = 2
    patience: int = 100
    close_mosaic: int = 10
    export_hw: tuple[int, int] = (256, 320)
    threads: int = 2
    time_hours: float | None = None
    init_weights: str | None = None
    """Start from these weights (a previous run's ``best.pt``) instead of random initialisation."""
    lr0: float | None = None
    """Initial learning rate; ultralytics ignores it with ``optimizer="auto"``."""
    warmup_epochs: float | None = None
    optimizer: str = "auto"


@dataclass(frozen=True)
class TrainResult:
    best_pt: Path
    onnx: Path
    metrics: dict[str, float]
    seconds: float


def train(settings: TrainSettings, config_dir: str | os.PathLike[str] = ".yolo-config") -> TrainResult:
    """Train YOLO11-``scale`` from scratch on ``settings.data`` on the CPU; export ONNX.

    The ONNX export has a static input ``export_hw`` (height, width) and the raw YOLOv8/11 output
    layout ``[1, 4+nc, N]`` (decoded with NMS by :class:`OnnxYoloDetector`).
    """
    prepare_offline_env(config_dir)
    import torch

    torch.set_num_threads(settings.threads)
    from ultralytics import YOLO
    from ultralytics.utils import SETTINGS

    SETTINGS.update({"sync": False})
    t0 = time.perf_counter()
    out = Path(settings.out_dir).resolve()
    run_dir = out / settings.name
    if settings.init_weights:
        model = YOLO(str(settings.init_weights))  # architecture and weights of an earlier run
    else:
        model = YOLO(str(write_model_yaml(out / "model_yaml", settings.scale, nc=1)))
    kwargs: dict[str, Any] = {
        "data": str(Path(settings.data).resolve()),
        "imgsz": settings.imgsz,
        "epochs": settings.epochs,
        "batch": settings.batch,
        "device": "cpu",
        "workers": settings.workers,
        "seed": settings.seed,
        "deterministic": True,
        "project": str(out),
        "name": settings.name,
        "exist_ok": True,
        # Random initialisation, or the given weights (ultralytics loads them through `pretrained`).
        "pretrained": str(Path(settings.init_weights).resolve()) if settings.init_weights else False,
        "optimizer": settings.optimizer,
        "amp": False,
        "plots": False,
        "patience": settings.patience,
        "close_mosaic": settings.close_mosaic,
        "verbose": True,
    }
    if settings.time_hours:
        kwargs["time"] = settings.time_hours
    if settings.lr0 is not None:
        kwargs["lr0"] = settings.lr0
    if settings.warmup_epochs is not None:
        kwargs["warmup_epochs"] = settings.warmup_epochs
    model.train(**kwargs)
    best = run_dir / "weights" / "best.pt"
    onnx_path = export_onnx(best, settings.export_hw)
    metrics = {}
    try:
        res = YOLO(str(best)).val(data=kwargs["data"], split="test", imgsz=settings.imgsz, device="cpu",
                                  batch=settings.batch, plots=False, project=str(out), name=f"{settings.name}_test",
                                  exist_ok=True)
        metrics = {"ultralytics_test_map50": float(res.box.map50), "ultralytics_test_recall": float(res.box.mr),
                   "ultralytics_test_precision": float(res.box.mp)}
    except Exception as exc:  # the test split is optional for training
        metrics = {"ultralytics_test_error": str(exc)}  # type: ignore[dict-item]
    result = TrainResult(best_pt=best, onnx=onnx_path, metrics=metrics, seconds=time.perf_counter() - t0)
    (run_dir / "lapwrench_train.json").write_text(json.dumps(
        {"settings": asdict(settings), "metrics": metrics, "seconds": result.seconds,
         "onnx": str(onnx_path)}, indent=1) + "\n")
    return result


def export_onnx(weights: str | os.PathLike[str], input_hw: tuple[int, int], opset: int = 17) -> Path:
    """Export ultralytics weights to ONNX with a static ``(height, width)`` input, simplified."""
    from ultralytics import YOLO

    path = YOLO(str(weights)).export(format="onnx", imgsz=list(input_hw), opset=opset, simplify=True,
                                     dynamic=False, half=False, device="cpu")
    return Path(path)
