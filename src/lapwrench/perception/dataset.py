"""The synthetic YOLO-format instrument dataset: its configuration, labels and files (issue 4, item 2).

The images are rendered by the simulation (:func:`lapwrench.sim.dataset.generate_dataset`; see that
module for how poses, instruments, lighting and degradations are drawn). This module holds what
perception needs without the simulator: :class:`DatasetConfig`, the label format
(:func:`yolo_label_lines`), the ultralytics data file and :func:`dataset_matches`.

Everything is deterministic from ``seed``: sample ``i`` of split ``s`` uses the generator
``numpy.random.default_rng([seed, split_index, i])``, so a split (e.g. the held-out test split) can
be regenerated alone.

Layout written::

    out/data.yaml                         # ultralytics data file (absolute path, names)
    out/images/{train,val,test}/NNNNNN.jpg
    out/labels/{train,val,test}/NNNNNN.txt  # "class cx cy w h" normalised, one line per box
    out/meta/{split}.jsonl                  # per image: jaw tips in pixels, visibility, pose
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

CLASS_NAMES: tuple[str, ...] = ("instrument",)
SPLITS: tuple[str, ...] = ("train", "val", "test")


@dataclass(frozen=True)
class DatasetConfig:
    """What :func:`lapwrench.sim.dataset.generate_dataset` renders. Sizes are images per split."""

    n_train: int = 600
    n_val: int = 100
    n_test: int = 150
    seed: int = 0
    tilt_max_deg: float = 18.0
    roll_max_deg: float = 60.0
    insertion_range: tuple[float, float] = (-0.03, 0.015)
    """Change of the insertion depth (m) from the default pose (positive: deeper)."""
    instrument_prob: float = 0.85
    border_prob: float = 0.3
    """Probability that an instrument tip is aimed near or beyond the image border."""
    tip_depth_range: tuple[float, float] = (0.03, 0.12)
    """Distance (m) of the jaw tip from the camera along its viewing ray; capped at the tissue
    surface seen along that ray (8 mm in front of it, or in 1 of 10 cases 4 mm into it)."""
    min_visible_px: int = 40
    min_box_side: int = 4
    blur_prob: float = 0.3
    motion_blur_prob: float = 0.15
    noise_prob: float = 0.5
    noise_sigma_max: float = 8.0
    jpeg_quality: tuple[int, int] = (80, 97)

    def __post_init__(self) -> None:
        for name in ("n_train", "n_val", "n_test"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.n_train + self.n_val + self.n_test == 0:
            raise ValueError("the dataset would be empty: all split sizes are 0")
        for name in ("instrument_prob", "border_prob", "blur_prob", "motion_blur_prob", "noise_prob"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)}")
        lo, hi = self.tip_depth_range
        if not 0.0 < lo < hi:
            raise ValueError(f"tip_depth_range must be 0 < near < far, got {self.tip_depth_range}")

    def split_sizes(self) -> dict[str, int]:
        return {"train": self.n_train, "val": self.n_val, "test": self.n_test}


@dataclass(frozen=True)
class LabelledFrame:
    """One rendered frame and its labels.

    ``boxes`` are xyxy pixels (visible jaw pixels), ``classes`` their class ids; ``tips`` the
    projected jaw tip (u, v) of each *present* instrument and ``tip_visible`` whether that
    instrument got a box (``box_index[i]`` is its box row, -1 when it has none).
    """

    image: np.ndarray
    boxes: np.ndarray
    classes: np.ndarray
    tips: np.ndarray
    tip_visible: np.ndarray
    box_index: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class DatasetSummary:
    root: Path
    data_yaml: Path
    images: dict[str, int]
    boxes: dict[str, int]
    seconds: float


def yolo_label_lines(boxes: np.ndarray, classes: np.ndarray, size: tuple[int, int]) -> list[str]:
    """``"cls cx cy w h"`` lines (normalised to [0, 1]) for xyxy pixel boxes in a ``(w, h)`` image."""
    w, h = size
    lines = []
    for (x0, y0, x1, y1), c in zip(np.asarray(boxes).reshape(-1, 4), np.asarray(classes).reshape(-1), strict=True):
        x0, x1 = min(max(x0, 0.0), w), min(max(x1, 0.0), w)
        y0, y1 = min(max(y0, 0.0), h), min(max(y1, 0.0), h)
        cx, cy, bw, bh = (x0 + x1) / 2 / w, (y0 + y1) / 2 / h, (x1 - x0) / w, (y1 - y0) / h
        lines.append(f"{int(c)} {cx:.6f} {cy:.6f} {bw:.6f} {bh:.6f}")
    return lines


def write_data_yaml(root: Path, splits: Sequence[str] = SPLITS, names: Sequence[str] = CLASS_NAMES) -> Path:
    """The ultralytics data file (absolute dataset path)."""
    import yaml

    data = {"path": str(root.resolve()), **{s: f"images/{s}" for s in splits},
            "names": dict(enumerate(names)), "nc": len(names)}
    out = root / "data.yaml"
    out.write_text("# lapwrench synthetic instrument dataset (lapwrench.perception.dataset)\n"
                   + yaml.safe_dump(data, sort_keys=False))
    return out


def dataset_matches(root: str | os.PathLike[str], config: DatasetConfig, split: str) -> bool:
    """Whether ``root`` holds ``split`` generated with ``config`` (same seed, sizes and ranges)."""
    p = Path(root) / "config.json"
    if not p.is_file():
        return False
    try:
        saved = json.loads(p.read_text())
    except json.JSONDecodeError:
        return False
    want = json.loads(json.dumps(asdict(config)))
    n = config.split_sizes()[split]
    imgs = Path(root) / "images" / split
    return saved == want and imgs.is_dir() and len(list(imgs.glob("*.jpg"))) == n
