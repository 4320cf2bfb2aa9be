"""Detector benchmark: ms per 640x480 frame for each available backend.

Usage::

    python bench/detect.py [--frames 100] [--threads 2] [--onnx model.onnx] [--pt best.pt]

Backends:

- ``onnx``: :class:`OnnxYoloDetector`. Without ``--onnx`` there is no trained model yet, so the
  bench GENERATES a tiny untrained stand-in (:func:`make_tiny_conv_yolo_onnx`: four stride-2 convs,
  YOLOv8-shaped output, dynamic input, 640x480 frames run at 640x480). Its time is the pipeline
  overhead (letterbox, onnxruntime call, decode, NMS) plus a very small network; it says nothing
  about a real YOLO's cost or accuracy.
- ``classical``: :class:`ClassicalDetector`, plus its precision/recall on frames drawn by
  :func:`draw_instrument_scene` (OpenCV drawings, not the simulator's held-out split).
- ``ultralytics``: only with ``--pt`` and the ultralytics extra installed.

Each time is also printed as a ratio against a reference measured in the same run
(``cv2.resize`` of the frame to 640x640 + ``cv2.cvtColor``), so results from different machines
compare. The last line is one JSON object.

mAP50/recall on the held-out synthetic test split are NOT measured yet: the dataset generator and
the trained model do not exist (TODO, issue 4 items 2-3). The JSON carries ``null`` for them.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from lapwrench.perception import (
    BackendUnavailableError,
    ClassicalDetector,
    DetectorConfig,
    ModelError,
    OnnxYoloDetector,
    UltralyticsDetector,
)
from lapwrench.perception.boxes import box_iou
from lapwrench.perception.synthetic import draw_instrument_scene, make_tiny_conv_yolo_onnx

W, H = 640, 480


def time_ms(fn: Callable[[np.ndarray], object], frames: list[np.ndarray], n: int, warmup: int = 5) -> list[float]:
    """Per-call wall times (ms) of ``fn`` over ``n`` frames (cycled), after ``warmup`` calls."""
    for i in range(warmup):
        fn(frames[i % len(frames)])
    out = []
    for i in range(n):
        f = frames[i % len(frames)]
        t0 = time.perf_counter()
        fn(f)
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def p90(xs: list[float]) -> float:
    return float(np.percentile(xs, 90))


def classical_accuracy(det: ClassicalDetector, n: int) -> tuple[float, float, float]:
    """Precision, recall (IoU >= 0.5) and median tip error (px) on ``n`` drawn scenes."""
    tp = fp = fn = 0
    tips: list[float] = []
    for seed in range(1000, 1000 + n):
        img, truth = draw_instrument_scene(n_instruments=1 + seed % 3, seed=seed,
                                           blur=1.0 if seed % 3 == 0 else 0.0, noise=6.0 if seed % 2 else 0.0)
        dets = det.detect(img)
        used: set[int] = set()
        for g in truth:
            cands = [(box_iou(np.array(g.box), np.array([d.box]))[0], i) for i, d in enumerate(dets) if i not in used]
            iou, i = max(cands, default=(0.0, -1))
            if iou >= 0.5:
                used.add(i)
                kp = dets[i].keypoint or dets[i].point
                tips.append(float(np.hypot(kp[0] - g.tip[0], kp[1] - g.tip[1])))
            else:
                fn += 1
        tp += len(used)
        fp += len(dets) - len(used)
    return tp / max(tp + fp, 1), tp / max(tp + fn, 1), float(np.median(tips)) if tips else float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=100, help="timed frames per backend")
    ap.add_argument("--threads", type=int, default=2, help="onnxruntime intra-op threads")
    ap.add_argument("--onnx", type=Path, help="a YOLO ONNX export (default: generated untrained stand-in)")
    ap.add_argument("--input-size", type=int, default=None, help="ONNX input size for dynamic models")
    ap.add_argument("--pt", type=Path, help="ultralytics .pt weights (needs the train extra)")
    ap.add_argument("--accuracy-frames", type=int, default=60, help="drawn scenes for classical P/R")
    args = ap.parse_args(argv)

    frames = [draw_instrument_scene((W, H), n_instruments=2, seed=s)[0] for s in range(20)]
    cfg = DetectorConfig(frame_size=(W, H), color_order="rgb")
    result: dict[str, object] = {"frame": f"{W}x{H}", "threads": args.threads}

    def reference(f: np.ndarray) -> object:
        return cv2.cvtColor(cv2.resize(f, (640, 640), interpolation=cv2.INTER_LINEAR), cv2.COLOR_RGB2BGR)

    ref = time_ms(reference, frames, max(args.frames, 200))
    ref_ms = statistics.median(ref)
    result["reference_ms"] = round(ref_ms, 4)
    print(f"reference (cv2.resize 640x640 + cvtColor): {ref_ms:.3f} ms")

    def report(name: str, times: list[float], note: str) -> None:
        med = statistics.median(times)
        result[f"{name}_ms_per_frame"] = round(med, 3)
        result[f"{name}_p90_ms"] = round(p90(times), 3)
        result[f"{name}_vs_reference_ratio"] = round(med / ref_ms, 2)
        print(f"{name:12s} {med:8.2f} ms/frame (p90 {p90(times):.2f})  = {med / ref_ms:6.1f} x reference  {note}")

    # ONNX.
    with tempfile.TemporaryDirectory() as tmp:
        if args.onnx is None:
            model = make_tiny_conv_yolo_onnx(Path(tmp) / "tiny_standin.onnx", num_classes=1, names=["instrument"])
            note = "[GENERATED untrained stand-in model: pipeline overhead, not a real YOLO]"
            result["onnx_model"] = "generated tiny untrained stand-in (make_tiny_conv_yolo_onnx)"
        else:
            model, note = args.onnx, f"[{args.onnx}]"
            result["onnx_model"] = str(args.onnx)
        try:
            onnx_det = OnnxYoloDetector(model, cfg, num_threads=args.threads, input_size=args.input_size)
            input_hw = onnx_det.input_shape_for((H, W))
            result["onnx_input_hw"] = list(input_hw)
            report("onnx", time_ms(onnx_det.detect, frames, args.frames), f"input {input_hw[1]}x{input_hw[0]} {note}")
        except ModelError as exc:
            print(f"onnx         skipped: {exc}")

    # Classical.
    classical = ClassicalDetector(cfg)
    report("classical", time_ms(classical.detect, frames, args.frames), "[weight-free OpenCV]")
    prec, rec, tip = classical_accuracy(classical, args.accuracy_frames)
    result["classical_drawn_precision"] = round(prec, 3)
    result["classical_drawn_recall"] = round(rec, 3)
    result["classical_drawn_tip_median_px"] = round(tip, 2)
    print(f"classical on {args.accuracy_frames} drawn scenes (not the sim split): precision {prec:.3f}, "
          f"recall {rec:.3f}, median tip error {tip:.1f} px")

    # ultralytics.
    if args.pt is not None:
        try:
            ul = UltralyticsDetector(args.pt, cfg)
            report("ultralytics", time_ms(ul.detect, frames, args.frames), f"[{args.pt}]")
        except (BackendUnavailableError, ModelError) as exc:
            print(f"ultralytics  skipped: {exc}")
    else:
        print("ultralytics  skipped: no --pt weights given")

    print("TODO mAP50/recall on the held-out synthetic test split: not measured; the sim dataset generator "
          "and a trained model do not exist yet (issue 4 items 2-3).")
    result["map50_heldout"] = None
    result["recall_heldout"] = None
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
