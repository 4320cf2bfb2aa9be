"""Command-line entry points of the perception tools: dataset, train, calibrate.

The lead's ``lapwrench`` CLI wires these as subcommands; each has an ``add_*_arguments(parser)``
helper and a ``*_main(args) -> int`` function. ``python -m lapwrench.perception.cli {dataset,train,
calibrate} ...`` runs them standalone (``scripts/train_detector.sh`` does so for training).
"""

from __future__ import annotations

import argparse
import glob
import os
import sys
from pathlib import Path

from lapwrench.cli_types import (
    ArgumentParser,
    int_in,
    nonnegative_float,
    nonnegative_int,
    output_dir,
    output_file,
    positive_float,
    quote,
    writable_dir_problem,
    writable_file_problem,
)

DEFAULT_DATASET = "out/datasets/instruments"
MAX_IMAGES = 10_000_000  # per split
MAX_SEED = 2**32 - 1


# --------------------------------------------------------------------------------------------
# dataset


def add_dataset_arguments(parser: argparse.ArgumentParser) -> None:
    images = int_in(0, MAX_IMAGES)
    parser.add_argument("--out", type=output_dir, default=DEFAULT_DATASET, help="dataset root (default: %(default)s)")
    parser.add_argument("--train", type=images, default=800, help="training images (default: %(default)s)")
    parser.add_argument("--val", type=images, default=100, help="validation images (default: %(default)s)")
    parser.add_argument("--test", type=images, default=200, help="held-out test images (default: %(default)s)")
    parser.add_argument("--seed", type=int_in(0, MAX_SEED), default=0, help="random seed (default: %(default)s)")
    parser.add_argument("--splits", type=_splits, default="train,val,test",
                        help="comma-separated splits to (re)generate: train, val, test (default: %(default)s)")


def _splits(text: str) -> str:
    """A non-empty comma-separated subset of train, val, test."""
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names or any(n not in ("train", "val", "test") for n in names):
        raise argparse.ArgumentTypeError(f"must be comma-separated names from train, val, test, got {quote(text)}")
    return ",".join(names)


def dataset_main(args: argparse.Namespace) -> int:
    """Render the synthetic YOLO dataset (needs MuJoCo rendering: MUJOCO_GL=egl when headless)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from lapwrench.perception.dataset import DatasetConfig
    from lapwrench.sim.dataset import generate_dataset  # the rendering needs the simulator

    problem = writable_dir_problem(args.out)
    if problem:
        print(f"lapwrench dataset: --out {quote(args.out)} {problem}", file=sys.stderr)
        return 2
    try:
        cfg = DatasetConfig(n_train=args.train, n_val=args.val, n_test=args.test, seed=args.seed)
        splits = [s.strip() for s in args.splits.split(",") if s.strip()]

        def progress(split: str, done: int, total: int) -> None:
            if done == total or done % 100 == 0:
                print(f"  {split}: {done}/{total}", file=sys.stderr)

        summary = generate_dataset(args.out, cfg, splits=splits, progress=progress)
    except ValueError as exc:
        print(f"lapwrench dataset: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # the folder became unwritable, or the disk is full
        print(f"lapwrench dataset: cannot write the dataset to {quote(args.out)}: {exc.strerror or exc}",
              file=sys.stderr)
        return 2
    print(f"dataset: {summary.root} ({summary.seconds:.0f} s)")
    for s in summary.images:
        print(f"  {s}: {summary.images[s]} images, {summary.boxes[s]} boxes")
    print(f"data file: {summary.data_yaml}")
    return 0


# --------------------------------------------------------------------------------------------
# train


def add_train_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", default=f"{DEFAULT_DATASET}/data.yaml", help="data.yaml (default: %(default)s)")
    parser.add_argument("--out", type=output_dir, default="out/train",
                        help="run directory root (default: %(default)s)")
    parser.add_argument("--name", type=_run_name, default="instruments", help="run name (default: %(default)s)")
    parser.add_argument("--scale", choices=("p", "u", "n"), default="n",
                        help="YOLO11 scale: p (pico), u, n (default: %(default)s)")
    parser.add_argument("--imgsz", type=int_in(32, 4096), default=320,
                        help="training image size, 32 to 4096 (default: %(default)s)")
    parser.add_argument("--epochs", type=int_in(1, 100_000), default=60, help="epochs (default: %(default)s)")
    parser.add_argument("--time-hours", type=positive_float, default=None,
                        help="wall-time budget; ultralytics fits the epochs into it")
    parser.add_argument("--batch", type=int_in(1, 4096), default=16, help="batch size (default: %(default)s)")
    parser.add_argument("--seed", type=int_in(0, MAX_SEED), default=0, help="random seed (default: %(default)s)")
    parser.add_argument("--workers", type=int_in(0, 256), default=2,
                        help="data loader workers, 0: in the main process (default: %(default)s)")
    parser.add_argument("--threads", type=int_in(1, 1024), default=2, help="torch CPU threads (default: %(default)s)")
    parser.add_argument("--export-hw", type=_height_width, default="256x320",
                        help="ONNX input HEIGHTxWIDTH, multiples of 32 (default: %(default)s)")
    parser.add_argument("--init-weights", default=None,
                        help="start from an earlier run's weights (e.g. out/train/NAME/weights/best.pt)")
    parser.add_argument("--optimizer", default="auto", help="ultralytics optimizer (default: %(default)s)")
    parser.add_argument("--lr0", type=positive_float, default=None,
                        help="initial learning rate (ultralytics default; ignored with --optimizer auto)")
    parser.add_argument("--warmup-epochs", type=nonnegative_float, default=None,
                        help="warm-up epochs (ultralytics default)")
    parser.add_argument("--close-mosaic", type=nonnegative_int, default=10,
                        help="final epochs without mosaic augmentation (default: %(default)s)")
    parser.add_argument("--ship", type=_output_path, default=None,
                        help="also copy the exported ONNX here (e.g. src/lapwrench/data/models/instruments.onnx)")


def _output_path(text: str) -> Path:
    return Path(output_file(text))


def _run_name(text: str) -> str:
    """A run name is one folder name under ``--out``."""
    if not text.strip() or "/" in text or "\\" in text or text in (".", "..") or "\0" in text or len(text) > 200:
        raise argparse.ArgumentTypeError(f"must be a plain folder name, got {quote(text)}")
    return text


def _height_width(text: str) -> str:
    """``HEIGHTxWIDTH`` in pixels, both multiples of 32 from 32 to 4096 (YOLO's stride)."""
    try:
        h, w = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be HEIGHTxWIDTH, e.g. 256x320, got {quote(text)}") from None
    if not all(32 <= v <= 4096 and v % 32 == 0 for v in (h, w)):
        raise argparse.ArgumentTypeError(f"must be multiples of 32 from 32 to 4096, got {quote(text)}")
    return f"{h}x{w}"


def train_main(args: argparse.Namespace) -> int:
    """Train on the CPU (torch + ultralytics from the training venv) and export ONNX."""
    try:
        from lapwrench.perception.train import TrainSettings, train
        h, w = (int(x) for x in args.export_hw.lower().split("x"))
        settings = TrainSettings(data=args.data, out_dir=args.out, name=args.name, scale=args.scale,
                                 imgsz=args.imgsz, epochs=args.epochs, batch=args.batch, seed=args.seed,
                                 workers=args.workers, export_hw=(h, w), threads=args.threads,
                                 time_hours=args.time_hours, init_weights=args.init_weights, lr0=args.lr0,
                                 warmup_epochs=args.warmup_epochs, close_mosaic=args.close_mosaic,
                                 optimizer=args.optimizer)
        if not Path(args.data).is_file():
            print(f"lapwrench train: --data {quote(args.data)} not found; generate the dataset first (dataset"
                  " subcommand)", file=sys.stderr)
            return 2
        if args.init_weights is not None and not Path(args.init_weights).is_file():
            print(f"lapwrench train: --init-weights {quote(args.init_weights)} not found", file=sys.stderr)
            return 2
        result = train(settings)
    except ImportError as exc:
        print(f"lapwrench train: training needs torch and ultralytics (scripts/train_detector.sh setup): {exc}",
              file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f"lapwrench train: {exc}", file=sys.stderr)
        return 2
    print(f"best weights: {result.best_pt}")
    print(f"ONNX: {result.onnx}")
    print(f"metrics: {result.metrics} ({result.seconds / 60:.1f} min)")
    if args.ship is not None:
        import shutil

        args.ship.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(result.onnx, args.ship)
        print(f"shipped: {args.ship}")
    return 0


# --------------------------------------------------------------------------------------------
# calibrate


def _board(text: str) -> tuple[int, int]:
    """``COLSxROWS`` inner corners of the checkerboard, each from 2 to 100."""
    try:
        cols, rows = (int(x) for x in text.lower().split("x"))
    except ValueError:
        cols = rows = 0
    if not (2 <= cols <= 100 and 2 <= rows <= 100):
        raise argparse.ArgumentTypeError(
            f"board must be COLSxROWS inner corners (2 to 100 each), e.g. 9x6, got {quote(text)}"
        )
    return cols, rows


def add_calibrate_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("images", nargs="+", help="checkerboard images: files or glob patterns (quoted)")
    parser.add_argument("--board", type=_board, default=(9, 6), help="inner corners COLSxROWS (default: 9x6)")
    parser.add_argument("--square", type=positive_float, default=0.025,
                        help="square edge in metres (default: %(default)s)")
    parser.add_argument("--out", type=_output_path, default=Path("intrinsics.yaml"),
                        help="intrinsics YAML to write (default: %(default)s)")
    parser.add_argument("--min-views", type=int_in(1, 100_000), default=3,
                        help="fewest usable views (default: %(default)s)")
    parser.add_argument("--fix-k3", action="store_true", help="hold the k3 distortion term at zero")


def calibrate_main(args: argparse.Namespace) -> int:
    """Calibrate from checkerboard images; write a config-loadable ``camera:`` YAML + details file.

    ``--out`` (e.g. ``intrinsics.yaml``) holds only the ``camera:`` section, so ``lapwrench.config.load``
    accepts it as a configuration file and its keys can be merged into any configuration. The
    distortion coefficients, RMS error and views go to ``<out stem>.calibration.yaml`` beside it
    (read both back with :func:`lapwrench.perception.read_intrinsics_yaml`).
    """
    from lapwrench.perception.calibration import CalibrationError, calibrate_from_images, write_intrinsics_yaml

    out = Path(args.out)
    for target in (out, out.with_name(out.stem + ".calibration.yaml")):
        problem = writable_file_problem(target)
        if problem:
            print(f"lapwrench calibrate: --out {quote(str(target))} {problem}", file=sys.stderr)
            return 2
    paths: list[str] = []
    for pattern in args.images:
        matches = sorted(glob.glob(pattern))
        paths.extend(matches if matches else [pattern])
    try:
        result = calibrate_from_images(paths, board=args.board, square_size=args.square, min_views=args.min_views,
                                       fix_k3=args.fix_k3)
    except CalibrationError as exc:
        print(f"lapwrench calibrate: {exc}", file=sys.stderr)
        return 2
    try:
        out, details = write_intrinsics_yaml(result, args.out, split=True)
    except OSError as exc:
        print(f"lapwrench calibrate: cannot write {quote(str(args.out))}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(f"fx={result.fx:.3f} fy={result.fy:.3f} u0={result.u0:.3f} v0={result.v0:.3f} "
          f"({result.width}x{result.height}), RMS reprojection error {result.rms:.4f} px, "
          f"{len(result.used)} views used, {len(result.rejected)} rejected")
    print(f"wrote {out} (camera: section) and {details} (distortion, RMS, views)")
    print(f"use it: copy the 'camera:' section of {out} into your configuration YAML, or load {out} "
          "itself as the configuration (all other sections keep their defaults)")
    return 0


# --------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m lapwrench.perception.cli", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    for name, add, fn, help_ in (
        ("dataset", add_dataset_arguments, dataset_main, "render the synthetic YOLO dataset"),
        ("train", add_train_arguments, train_main, "train a small YOLO on the CPU and export ONNX"),
        ("calibrate", add_calibrate_arguments, calibrate_main, "camera intrinsics from checkerboard images"),
    ):
        p = sub.add_parser(name, help=help_, description=fn.__doc__)
        add(p)
        p.set_defaults(func=fn)
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
