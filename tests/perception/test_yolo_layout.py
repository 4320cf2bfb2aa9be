"""The pure YOLO output-layout inference."""

from __future__ import annotations

from typing import Any

import pytest

from lapwrench.perception import (
    OutputLayout,
    infer_layout,
)


@pytest.mark.parametrize(
    ("outputs", "kwargs", "layout", "nc"),
    [
        ([("output0", (1, 84, 8400))], {}, OutputLayout.YOLOV8, 80),
        ([("output0", (1, 5, 6300))], {}, OutputLayout.YOLOV8, 1),
        ([("output", (1, 25200, 85))], {}, OutputLayout.YOLOV5, 80),
        ([("output", (1, 25200, 6))], {}, OutputLayout.YOLOV5, 1),
        # YOLOv7 raw export with the three per-level grids as extra outputs.
        ([("output", (1, 25200, 7)), ("g1", (1, 3, 80, 80, 7)), ("g2", (1, 3, 40, 40, 7))], {},
         OutputLayout.YOLOV5, 2),
        ([("output", (12, 7))], {}, OutputLayout.YOLOV7_E2E, None),
        ([("output", (0, 7))], {}, OutputLayout.YOLOV7_E2E, None),
        ([("num_dets", (1, 1)), ("det_boxes", (1, 100, 4)), ("det_scores", (1, 100)),
          ("det_classes", (1, 100))], {}, OutputLayout.YOLOV7_E2E_SPLIT, None),
        # Same by shape only, unnamed outputs.
        ([("a", (1, 1)), ("b", (1, 100, 4)), ("c", (1, 100)), ("d", (1, 100))], {},
         OutputLayout.YOLOV7_E2E_SPLIT, None),
        # Tiny ambiguous shapes settled by num_classes.
        ([("o", (1, 6, 6))], {"num_classes": 2}, OutputLayout.YOLOV8, 2),
        ([("o", (1, 7, 6))], {"num_classes": 1}, OutputLayout.YOLOV5, 1),
        ([("output0", (1, 300, 6))], {"end2end": True}, OutputLayout.E2E_XYXY_SCORE_CLS, None),
    ],
)
def test_infer_layout(
    outputs: list[tuple[str, tuple[int, ...]]], kwargs: dict[str, Any], layout: OutputLayout, nc: int | None
) -> None:
    info = infer_layout(outputs, **kwargs)
    assert info.layout is layout
    assert info.num_classes == nc


def test_infer_layout_split_output_order() -> None:
    outs = [("det_classes", (1, 50)), ("det_scores", (1, 50)), ("det_boxes", (1, 50, 4)), ("num_dets", (1, 1))]
    assert infer_layout(outs).outputs == (3, 2, 1, 0)


@pytest.mark.parametrize(
    ("outputs", "kwargs"),
    [
        ([("o", (1, 6, 6))], {}),
        ([("o", (1, 84, 8400))], {"num_classes": 3}),
        ([("o", (2, 84, 8400))], {}),
        ([("o", (10, 6))], {}),
        ([("o", (1, 100, 7))], {"end2end": True}),
    ],
)
def test_infer_layout_rejects(outputs: list[tuple[str, tuple[int, ...]]], kwargs: dict[str, Any]) -> None:
    with pytest.raises(ValueError):
        infer_layout(outputs, **kwargs)
