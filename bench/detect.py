"""Detector benchmark: ms per 640x480 frame and mAP50/recall on the held-out synthetic test split.

Usage::

    MUJOCO_GL=egl python bench/detect.py [--frames 100] [--threads 2] [--onnx MODEL.onnx]
                                         [--data out/datasets/instruments] [--test-images 100] [--pt best.pt]

The held-out test split is the simulator's (lapwrench.sim.dataset): if ``--data`` does not
hold a test split generated with ``--seed``/``--test-images``, the bench renders one (seed 0 and
100 images by default; about 15 s). With the same seed, its images are the first images of the
training dataset's test split (each image's randomness depends only on seed, split and index),
so the shipped model is never scored on training data.

Backends:

- ``onnx``: :class:`OnnxYoloDetector` with ``--onnx`` (default: the shipped model,
  ``src/lapwrench/data/models/instruments.onnx``, run with its ``SHIPPED_MODEL_OPTIONS``, i.e. the
  mirrored second pass unless ``--test-time-flip off``;
  if that is missing, a GENERATED untrained stand-in, whose time is pipeline overhead only).
- ``classical``: :class:`ClassicalDetector`, scored on the split with ``box="jaws"`` (the jaw
  region the dataset labels). It was tuned on frames drawn by :func:`draw_instrument_scene`, where
  it is also scored (shaft + jaw boxes), and does poorly on the rendered scene.
- ``ultralytics``: only with ``--pt`` and the ultralytics extra installed.

Timing: median wall time of ``detect`` per 640x480 frame (letterbox, inference, decode, NMS
included), on test-split frames, with onnxruntime on ``--threads`` threads. Each time is also
given as a ratio against a reference measured in the same run (``cv2.resize`` to 640x640 +
``cv2.cvtColor``), so results from different machines compare.

Accuracy: :func:`lapwrench.perception.evaluate.evaluate_detector`, the same for every backend:
mAP50 over all detections (detector score threshold 0.01), recall/precision at score 0.25.

The last line is one JSON object with unit-suffixed keys.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2
import numpy as np

from lapwrench.perception import (
    SHIPPED_MODEL,
    SHIPPED_MODEL_OPTIONS,
    BackendUnavailableError,
    ClassicalDetector,
    ClassicalParams,
    Detector,
    DetectorConfig,
    ModelError,
    OnnxYoloDetector,
    UltralyticsDetector,
)
from lapwrench.perception.boxes import box_iou
from lapwrench.perception.dataset import DatasetConfig, dataset_matches
from lapwrench.perception.evaluate import evaluate_detector, read_yolo_split
from lapwrench.perception.synthetic import draw_instrument_scene, make_tiny_conv_yolo_onnx
from lapwrench.sim.dataset import generate_dataset

W, H = 640, 480
ROOT = Path(__file__).resolve().parent.parent
EVAL_SCORE = 0.01
OPERATING_SCORE = 0.25


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


def ensure_test_split(root: Path, n: int, seed: int) -> Path:
    """The held-out test split under ``root``, rendered if missing or generated differently."""
    cfg = DatasetConfig(n_train=0, n_val=0, n_test=n, seed=seed)
    if dataset_matches(root, cfg, "test"):
        return root
    if (root / "config.json").is_file() and (root / "images" / "test").is_dir():
        # A larger split with the same seed and ranges (e.g. the training dataset's): use its first n.
        saved = json.loads((root / "config.json").read_text())
        want = json.loads(json.dumps(asdict(cfg)))
        same = all(saved.get(k) == v for k, v in want.items() if not k.startswith("n_"))
        if same and saved.get("n_test", 0) >= n and len(read_yolo_split(root, "test", (W, H))) >= n:
            return root
    root = ROOT / "out" / "datasets" / f"bench-test-seed{seed}-n{n}"
    if not dataset_matches(root, cfg, "test"):
        print(f"rendering the held-out test split ({n} images, seed {seed}) into {root} ...", flush=True)
        generate_dataset(root, cfg, splits=["test"])
    return root


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=100, help="timed frames per backend")
    ap.add_argument("--threads", type=int, default=2, help="onnxruntime intra-op threads")
    ap.add_argument("--onnx", type=Path, default=None,
                    help=f"a YOLO ONNX export (default: {SHIPPED_MODEL.relative_to(ROOT)}, else a generated stand-in)")
    ap.add_argument("--input-size", type=int, default=None, help="ONNX input size for dynamic models")
    ap.add_argument("--test-time-flip", choices=["shipped", "on", "off"], default="shipped",
                    help="mirrored second pass of the ONNX model: as the shipped model runs (default), on or off")
    ap.add_argument("--pt", type=Path, help="ultralytics .pt weights (needs the train extra)")
    ap.add_argument("--pt-imgsz", type=int, default=320,
                    help="ultralytics inference size; the shipped model was trained at 320 (default: %(default)s)")
    ap.add_argument("--data", type=Path, default=ROOT / "out" / "datasets" / "instruments",
                    help="dataset root holding the test split (rendered if missing)")
    ap.add_argument("--test-images", type=int, default=100, help="held-out test images scored")
    ap.add_argument("--seed", type=int, default=0, help="dataset seed of the test split")
    ap.add_argument("--accuracy-frames", type=int, default=60, help="drawn scenes for classical P/R")
    args = ap.parse_args(argv)

    data = ensure_test_split(args.data, args.test_images, args.seed)
    truths = read_yolo_split(data, "test", (W, H))[: args.test_images]
    frames = [cv2.cvtColor(cv2.imread(str(t.image)), cv2.COLOR_BGR2RGB) for t in truths[:20]]
    cfg = DetectorConfig(frame_size=(W, H), color_order="rgb", score_threshold=OPERATING_SCORE)
    eval_cfg = DetectorConfig(frame_size=(W, H), color_order="rgb", score_threshold=EVAL_SCORE)
    result: dict[str, object] = {"frame": f"{W}x{H}", "threads_count": args.threads,
                                 "test_images_count": len(truths), "test_seed": args.seed,
                                 "test_ground_truth_count": int(sum(len(t.boxes) for t in truths))}
    print(f"held-out test split: {data} ({len(truths)} images, "
          f"{result['test_ground_truth_count']} instrument boxes)")

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

    def accuracy(name: str, det: Detector) -> None:
        t0 = time.perf_counter()
        r = evaluate_detector(det, data, "test", limit=args.test_images, score_threshold=OPERATING_SCORE)
        result[f"{name}_test_map50_fraction"] = round(r.map50, 4)
        result[f"{name}_test_recall_fraction"] = round(r.recall, 4)
        result[f"{name}_test_precision_fraction"] = round(r.precision, 4)
        print(f"{name:12s} held-out test: mAP50 {r.map50:.4f}, recall {r.recall:.4f}, precision {r.precision:.4f} "
              f"at score {OPERATING_SCORE} ({r.n_images} images, {time.perf_counter() - t0:.0f} s)")

    # ONNX.
    with tempfile.TemporaryDirectory() as tmp:
        model = args.onnx if args.onnx is not None else (SHIPPED_MODEL if SHIPPED_MODEL.is_file() else None)
        if model is None:
            model = make_tiny_conv_yolo_onnx(Path(tmp) / "tiny_standin.onnx", num_classes=1, names=["instrument"])
            note = "[GENERATED untrained stand-in model: pipeline overhead, not a real YOLO]"
            result["onnx_model"] = "generated tiny untrained stand-in (make_tiny_conv_yolo_onnx)"
        else:
            note = f"[{model}]"
            result["onnx_model"] = str(model)
        shipped_flip = bool(SHIPPED_MODEL_OPTIONS.get("test_time_flip")) and model == SHIPPED_MODEL
        flip = args.test_time_flip == "on" or (args.test_time_flip == "shipped" and shipped_flip)
        result["onnx_test_time_flip"] = flip
        if flip:
            note += " [mirrored second pass]"
        try:
            onnx_det = OnnxYoloDetector(model, cfg, num_threads=args.threads, input_size=args.input_size,
                                        test_time_flip=flip)
            input_hw = onnx_det.input_shape_for((H, W))
            result["onnx_input_hw_px"] = list(input_hw)
            report("onnx", time_ms(onnx_det.detect, frames, args.frames), f"input {input_hw[1]}x{input_hw[0]} {note}")
            accuracy("onnx", OnnxYoloDetector(model, eval_cfg, num_threads=args.threads, input_size=args.input_size,
                                              test_time_flip=flip))
        except ModelError as exc:
            print(f"onnx         skipped: {exc}")

    # Classical.
    classical = ClassicalDetector(cfg)
    report("classical", time_ms(classical.detect, frames, args.frames), "[weight-free OpenCV]")
    accuracy("classical", ClassicalDetector(eval_cfg, ClassicalParams(box="jaws")))
    prec, rec, tip = classical_accuracy(ClassicalDetector(DetectorConfig(frame_size=(W, H))), args.accuracy_frames)
    result["classical_drawn_precision_fraction"] = round(prec, 3)
    result["classical_drawn_recall_fraction"] = round(rec, 3)
    result["classical_drawn_tip_median_px"] = round(tip, 2)
    print(f"classical on {args.accuracy_frames} drawn scenes (its own scene type, shaft+jaw boxes): precision "
          f"{prec:.3f}, recall {rec:.3f}, median tip error {tip:.1f} px")

    # ultralytics.
    if args.pt is not None:
        try:
            ul = UltralyticsDetector(args.pt, cfg, imgsz=args.pt_imgsz)
            report("ultralytics", time_ms(ul.detect, frames, args.frames), f"[{args.pt}]")
            accuracy("ultralytics", UltralyticsDetector(args.pt, eval_cfg, imgsz=args.pt_imgsz))
        except (BackendUnavailableError, ModelError) as exc:
            print(f"ultralytics  skipped: {exc}")
    else:
        print("ultralytics  skipped: no --pt weights given")

    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
