"""The dataset configuration and the YOLO label lines."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from lapwrench.perception.dataset import DatasetConfig, yolo_label_lines

W, H = 640, 480


def test_label_lines_roundtrip() -> None:
    boxes = np.array([[10.0, 20.0, 110.0, 70.0], [-5.0, 400.0, 50.0, 500.0]])
    lines = yolo_label_lines(boxes, np.zeros(2, int), (W, H))
    assert lines[0].startswith("0 0.093750 0.093750 0.156250 0.104167")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_train": -1}, "n_train"),
        ({"n_train": 0, "n_val": 0, "n_test": 0}, "empty"),
        ({"blur_prob": 1.5}, "blur_prob"),
        ({"tip_depth_range": (0.1, 0.05)}, "tip_depth_range"),
    ],
)
def test_bad_config(kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        DatasetConfig(**kwargs)
