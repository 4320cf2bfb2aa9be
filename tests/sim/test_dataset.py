"""The synthetic YOLO dataset rendered by the simulation world: layout, label validity, determinism."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers import make_renderable_world

from lapwrench.perception.dataset import DatasetConfig, DatasetSummary, dataset_matches
from lapwrench.perception.evaluate import read_yolo_split
from lapwrench.sim.dataset import FrameLabeller, generate_dataset
from lapwrench.sim.world import SimWorld

W, H = 640, 480


@pytest.fixture(scope="module")
def world() -> Iterator[SimWorld]:
    w = make_renderable_world()
    yield w
    w.close()


@pytest.fixture(scope="module")
def tiny(world: SimWorld, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, DatasetConfig, DatasetSummary]:
    root = tmp_path_factory.mktemp("ds")
    cfg = DatasetConfig(n_train=4, n_val=2, n_test=3, seed=3)
    return root, cfg, generate_dataset(root, cfg, world=world)


def test_layout_and_data_yaml(tiny: tuple[Path, DatasetConfig, DatasetSummary]) -> None:
    root, cfg, summary = tiny
    assert summary.images == {"train": 4, "val": 2, "test": 3}
    data = yaml.safe_load((root / "data.yaml").read_text())
    assert data["names"] == {0: "instrument"} and data["nc"] == 1
    assert data["path"] == str(root.resolve())
    for split, n in cfg.split_sizes().items():
        imgs = sorted((root / "images" / split).glob("*.jpg"))
        labels = sorted((root / "labels" / split).glob("*.txt"))
        assert len(imgs) == len(labels) == n
        assert [p.stem for p in imgs] == [p.stem for p in labels]
        meta = (root / "meta" / f"{split}.jsonl").read_text().splitlines()
        assert len(meta) == n
    assert dataset_matches(root, cfg, "test")
    assert not dataset_matches(root, DatasetConfig(n_train=4, n_val=2, n_test=3, seed=4), "test")


def test_labels_are_valid_and_inside_the_image(tiny: tuple[Path, DatasetConfig, DatasetSummary]) -> None:
    root, _cfg, summary = tiny
    n_boxes = 0
    for split in ("train", "val", "test"):
        for lbl in (root / "labels" / split).glob("*.txt"):
            for line in lbl.read_text().splitlines():
                parts = line.split()
                assert len(parts) == 5 and parts[0] == "0"
                cx, cy, w, h = map(float, parts[1:])
                assert 0 < w <= 1 and 0 < h <= 1
                assert cx - w / 2 >= -1e-6 and cx + w / 2 <= 1 + 1e-6
                assert cy - h / 2 >= -1e-6 and cy + h / 2 <= 1 + 1e-6
                assert w * W >= 4 and h * H >= 4
                n_boxes += 1
    assert n_boxes == sum(summary.boxes.values()) > 0
    truths = read_yolo_split(root, "train")
    assert len(truths) == 4 and all(t.boxes.shape[1] == 4 for t in truths)


def test_boxes_cover_the_projected_tips(tiny: tuple[Path, DatasetConfig, DatasetSummary]) -> None:
    """A labelled instrument's jaw box holds (or nearly holds) its projected jaw tip."""
    root, _cfg, _ = tiny
    checked = 0
    for split in ("train", "val", "test"):
        for line in (root / "meta" / f"{split}.jsonl").read_text().splitlines():
            m = json.loads(line)
            for tip, idx in zip(m["tips_uv"], m["box_index"], strict=True):
                if idx < 0 or not (0 <= tip[0] < W and 0 <= tip[1] < H):
                    continue
                x0, y0, x1, y1 = m["boxes_xyxy"][idx]
                pad = 0.25 * max(x1 - x0, y1 - y0)
                assert x0 - pad <= tip[0] <= x1 + pad and y0 - pad <= tip[1] <= y1 + pad
                checked += 1
    assert checked > 0


def test_deterministic_and_splits_regenerate_alone(
    tiny: tuple[Path, DatasetConfig, DatasetSummary], world: SimWorld, tmp_path: Path
) -> None:
    root, cfg, _ = tiny
    generate_dataset(tmp_path, cfg, splits=["test"], world=world)
    for name in sorted(p.name for p in (root / "labels" / "test").glob("*.txt")):
        assert (tmp_path / "labels" / "test" / name).read_text() == (root / "labels" / "test" / name).read_text()
    assert not (tmp_path / "images" / "train").exists()


def test_labeller_handles_occlusion_by_segmentation(world: SimWorld) -> None:
    lab = FrameLabeller(world, DatasetConfig(instrument_prob=1.0, border_prob=0.0))
    try:
        frame = lab.render(np.random.default_rng(11), degrade=False)
        assert frame.image.shape == (H, W, 3) and frame.image.dtype == np.uint8
        # No geom ids at all -> nothing visible -> no labels.
        boxes, owners = lab.labels_from_segmentation(np.full((H, W), -1, np.int32))
        assert boxes.shape == (0, 4) and owners.size == 0
        # A few pixels of a jaw are below min_visible_px -> not labelled.
        ids = np.full((H, W), -1, np.int32)
        ids[10:13, 10:13] = lab.jaw_geoms[0][0]
        assert lab.labels_from_segmentation(ids)[0].shape == (0, 4)
        ids[100:120, 200:230] = lab.jaw_geoms[1][0]
        boxes, owners = lab.labels_from_segmentation(ids)
        assert boxes.tolist() == [[200.0, 100.0, 230.0, 120.0]] and owners.tolist() == [1]
    finally:
        lab.close()
        world.reset()


def test_unknown_split(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown split"):
        generate_dataset(tmp_path, DatasetConfig(n_train=1, n_val=0, n_test=0), splits=["bogus"])
