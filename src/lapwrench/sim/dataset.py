"""Rendering the synthetic instrument dataset with the simulation world (issue 4, item 2).

The dataset's configuration, label format and layout are :mod:`lapwrench.perception.dataset`'s
(perception does not import the simulator). Each sample is one 640x480 laparoscope frame of
:class:`lapwrench.sim.world.SimWorld` with labels from the projected scene geometry:

- **Box** = the visible pixels of the instrument's **jaws** (the two jaw geoms), taken from MuJoCo's
  segmentation rendering of the same view. This is the distal tip region the tracking uses: its
  centre lies on the jaws, about 1 cm behind the jaw tip, so the default ``TrackingPoint.CENTER``
  of a detection is an image point of the tip region (eq 9/11). Occlusion (tissue, the other
  instrument) and the image border are handled by construction: only pixels that are actually
  drawn count, so a box is clipped to the image and shrinks to the visible part. A jaw region with
  fewer than ``min_visible_px`` visible pixels (or a side under ``min_box_side`` px) is not labelled.
- **Scope pose**: random pivots of the laparoscope about the incision (tilt up to
  ``tilt_max_deg``), roll about its axis and insertion changes, solved to joint configurations by
  damped least squares from the default pose, so the shaft always passes through the trocar.
- **Instruments**: each present with probability ``instrument_prob``; its jaw tip placed on a
  random viewing ray at a random depth, sometimes near or beyond the image border (partly out of
  view), random roll; the shaft always through its port.
- **Lighting**: scope light and room light intensity, room light direction, headlight ambient, a
  tissue colour tint.
- **Image degradations** (OpenCV): Gaussian blur, motion blur, Gaussian noise, JPEG quality.

The frame labeller lives here, with the simulator it drives; the scope poses are solved by
:class:`lapwrench.sim.poser.ScopePoser`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from lapwrench.perception.dataset import (
    SPLITS,
    DatasetConfig,
    DatasetSummary,
    LabelledFrame,
    write_data_yaml,
    yolo_label_lines,
)
from lapwrench.sim.poser import ScopePoser

# the dataset's types are re-exported: callers that render need only this module
__all__ = ["DatasetConfig", "DatasetSummary", "FrameLabeller", "LabelledFrame", "generate_dataset"]


# --------------------------------------------------------------------------------------------
# Rendering one labelled frame


class FrameLabeller:
    """Renders labelled frames of one :class:`SimWorld` (RGB + segmentation of the same view)."""

    def __init__(self, world: Any, config: DatasetConfig | None = None) -> None:
        import mujoco

        from lapwrench.sim.scene.names import CAMERA_NAME, INSTRUMENT_BODIES

        self._mj = mujoco
        self.world = world
        self.config = config or DatasetConfig()
        self.camera = world.scene.config.camera
        m = world.model
        self.jaw_geoms: list[np.ndarray] = []
        for body in INSTRUMENT_BODIES:
            bid = m.body(body).id
            ids = [g for g in range(m.ngeom) if m.geom_bodyid[g] == bid and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX]
            if not ids:
                raise RuntimeError(f"instrument body {body!r} has no jaw (box) geoms")
            self.jaw_geoms.append(np.asarray(ids))
        self.camera_name = CAMERA_NAME
        self._seg = mujoco.Renderer(m, height=self.camera.height, width=self.camera.width)
        self._seg.enable_segmentation_rendering()
        self._vopt = mujoco.MjvOption()
        self._vopt.geomgroup[1] = 0  # the arm is never in the scope view (as SimWorld.render)
        self.poser = ScopePoser(world)
        self._light_scope = m.light("scope_light").id
        self._light_room = m.light("room").id
        self._base = {
            "scope_diffuse": m.light_diffuse[self._light_scope].copy(),
            "room_diffuse": m.light_diffuse[self._light_room].copy(),
            "room_dir": m.light_dir[self._light_room].copy(),
            "head_ambient": np.array(m.vis.headlight.ambient, float),
            "head_diffuse": np.array(m.vis.headlight.diffuse, float),
            "tissue_rgba": m.mat_rgba[m.material("tissue").id].copy(),
            "organ_rgba": m.mat_rgba[m.material("organ").id].copy(),
        }

    def close(self) -> None:
        self._seg.close()

    # -- scene randomisation

    def _randomise_lighting(self, rng: np.random.Generator) -> dict[str, float]:
        m, b = self.world.model, self._base
        s_scope = float(rng.uniform(0.45, 1.25))
        s_room = float(rng.uniform(0.2, 1.4))
        amb = float(rng.uniform(0.1, 0.4))
        m.light_diffuse[self._light_scope] = b["scope_diffuse"] * s_scope
        m.light_diffuse[self._light_room] = b["room_diffuse"] * s_room
        d = b["room_dir"] + rng.normal(0.0, 0.35, 3)
        d[2] = -abs(d[2]) - 0.3
        m.light_dir[self._light_room] = d / np.linalg.norm(d)
        m.vis.headlight.ambient[:] = [amb] * 3
        m.vis.headlight.diffuse[:] = b["head_diffuse"] * float(rng.uniform(0.5, 1.3))
        tint = rng.uniform([0.85, 0.8, 0.8], [1.1, 1.1, 1.1])
        for key, mat in (("tissue_rgba", "tissue"), ("organ_rgba", "organ")):
            rgba = b[key].copy()
            rgba[:3] = np.clip(rgba[:3] * tint, 0.0, 1.0)
            m.mat_rgba[m.material(mat).id] = rgba
        return {"scope_light": s_scope, "room_light": s_room, "ambient": amb}

    def _pose_scope(self, rng: np.random.Generator) -> dict[str, float]:
        cfg = self.config
        tmax = math.radians(cfg.tilt_max_deg)
        for _ in range(10):
            r = tmax * math.sqrt(rng.uniform())
            a = rng.uniform(0, 2 * math.pi)
            tx, ty = r * math.cos(a), r * math.sin(a)
            roll = math.radians(rng.uniform(-cfg.roll_max_deg, cfg.roll_max_deg))
            ins = float(rng.uniform(*cfg.insertion_range))
            q = self.poser.configuration(tx, ty, roll, ins)
            if q is not None:
                self.world.reset(q)
                return {"tilt_x": tx, "tilt_y": ty, "roll": roll, "insertion": ins}
        self.world.reset()
        return {"tilt_x": 0.0, "tilt_y": 0.0, "roll": 0.0, "insertion": 0.0}

    def _tissue_distance(self, origin: np.ndarray, direction: np.ndarray) -> float:
        """Distance along a viewing ray to the first scene surface (instruments retracted)."""
        geomid = np.zeros(1, np.int32)
        groups = np.array([1, 0, 1, 1, 1, 1], np.uint8)  # not the arm/scope (group 1)
        dist = self._mj.mj_ray(self.world.model, self.world.data, origin, direction, groups, 1, -1, geomid)
        return float(dist) if dist >= 0 else math.inf

    def _place_instruments(self, rng: np.random.Generator) -> list[bool]:
        cfg, cam, w = self.config, self.camera, self.world
        n = len(self.jaw_geoms)
        for i in range(n):  # retract both, so the rays below see the tissue only
            w.set_instrument_tip(i, w.port_position(i) + np.array([0.0, 0.0, 0.01]), 0.0)
        self._mj.mj_forward(w.model, w.data)
        p_c, R_c = w.frame_pose("lap_C")
        present = []
        for i in range(n):
            if rng.uniform() >= cfg.instrument_prob:
                present.append(False)
                continue
            if rng.uniform() < cfg.border_prob:
                side = int(rng.integers(0, 4))
                t = rng.uniform(0.0, 1.0)
                off = rng.uniform(-40.0, 60.0)  # px beyond (+) or inside (-) the border
                u, v = [(t * cam.width, -off), (t * cam.width, cam.height + off), (-off, t * cam.height),
                        (cam.width + off, t * cam.height)][side]
            else:
                u, v = rng.uniform([40.0, 40.0], [cam.width - 40.0, cam.height - 40.0])
            ray = R_c @ np.array([(u - cam.u0) / cam.fx, (v - cam.v0) / cam.fy, 1.0])
            ray /= np.linalg.norm(ray)
            near, far = cfg.tip_depth_range
            # Mostly in front of the tissue; sometimes touching or dipping into it (occlusion).
            margin = 0.008 if rng.uniform() > 0.1 else -0.004
            far = min(far, self._tissue_distance(p_c, ray) - margin)
            dist = float(rng.uniform(near, far)) if far > near else near
            w.set_instrument_tip(i, p_c + dist * ray, float(rng.uniform(-math.pi, math.pi)))
            present.append(True)
        self._mj.mj_forward(w.model, w.data)
        return present

    # -- labels

    def _segment(self) -> np.ndarray:
        self._seg.update_scene(self.world.data, camera=self.camera_name, scene_option=self._vopt)
        seg = self._seg.render()
        ids = seg[..., 0].copy()
        ids[seg[..., 1] != int(self._mj.mjtObj.mjOBJ_GEOM)] = -1
        return ids

    def labels_from_segmentation(self, geom_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Visible-pixel jaw boxes (xyxy) and their instrument index from a geom-id image."""
        cfg = self.config
        boxes, owners = [], []
        for i, ids in enumerate(self.jaw_geoms):
            mask = np.isin(geom_ids, ids)
            n = int(mask.sum())
            if n < cfg.min_visible_px:
                continue
            ys, xs = np.nonzero(mask)
            box = (float(xs.min()), float(ys.min()), float(xs.max() + 1), float(ys.max() + 1))
            if box[2] - box[0] < cfg.min_box_side or box[3] - box[1] < cfg.min_box_side:
                continue
            boxes.append(box)
            owners.append(i)
        return np.asarray(boxes, np.float64).reshape(-1, 4), np.asarray(owners, np.int64)

    def _degrade(self, img: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, dict[str, float]]:
        cfg = self.config
        info: dict[str, float] = {}
        if rng.uniform() < cfg.blur_prob:
            s = float(rng.uniform(0.6, 1.8))
            img = cv2.GaussianBlur(img, (0, 0), s)
            info["blur_sigma"] = s
        if rng.uniform() < cfg.motion_blur_prob:
            n = int(rng.integers(5, 12))
            line = np.zeros((n, n), np.float32)
            line[n // 2, :] = 1.0 / n
            rot = cv2.getRotationMatrix2D(((n - 1) / 2.0, (n - 1) / 2.0), float(rng.uniform(0, 180)), 1.0)
            k: np.ndarray = cv2.warpAffine(line, rot, (n, n))  # float32, as the line
            k /= max(float(k.sum()), 1e-6)
            img = cv2.filter2D(img, -1, k)
            info["motion_blur_px"] = n
        if rng.uniform() < cfg.noise_prob:
            s = float(rng.uniform(1.0, cfg.noise_sigma_max))
            img = np.clip(img.astype(np.float32) + rng.normal(0.0, s, img.shape), 0, 255).astype(np.uint8)
            info["noise_sigma"] = s
        return img, info

    def render(self, rng: np.random.Generator, *, degrade: bool = True) -> LabelledFrame:
        """Randomise the scene with ``rng``, render it and label it."""
        info: dict[str, Any] = {}
        info.update(self._pose_scope(rng))
        info.update(self._randomise_lighting(rng))
        present = self._place_instruments(rng)
        image = self.world.render()
        boxes, owners = self.labels_from_segmentation(self._segment())
        if degrade:
            image, deg = self._degrade(image, rng)
            info.update(deg)
        tips, visible, index = [], [], []
        for i, here in enumerate(present):
            if not here:
                continue
            uv, _z = self.world.project_to_image(self.world.instrument_tip(i))
            tips.append(uv)
            rows = np.flatnonzero(owners == i)
            visible.append(bool(rows.size))
            index.append(int(rows[0]) if rows.size else -1)
        return LabelledFrame(
            image=image,
            boxes=boxes,
            classes=np.zeros(len(boxes), np.int64),
            tips=np.asarray(tips, np.float64).reshape(-1, 2),
            tip_visible=np.asarray(visible, bool),
            box_index=np.asarray(index, np.int64),
            info=info,
        )


# --------------------------------------------------------------------------------------------
# Writing the dataset


def generate_dataset(
    out_dir: str | os.PathLike[str],
    config: DatasetConfig | None = None,
    *,
    splits: Sequence[str] = SPLITS,
    world: Any = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> DatasetSummary:
    """Render a YOLO-format dataset into ``out_dir`` (see the module docstring).

    Args:
        out_dir: dataset root; existing files of the generated splits are overwritten.
        config: sizes, seed and randomisation ranges.
        splits: which splits to (re)generate; the rest of the layout is left alone.
        world: a :class:`SimWorld` to render with (default: a new one on the default scene). Its
            model's lights and tissue colours are modified.
        progress: called as ``progress(split, done, total)``.
    """
    import time

    cfg = config or DatasetConfig()
    root = Path(out_dir)
    unknown = set(splits) - set(SPLITS)
    if unknown:
        raise ValueError(f"unknown split(s) {sorted(unknown)}; choose from {SPLITS}")
    t0 = time.perf_counter()
    own_world = world is None
    if own_world:
        from lapwrench.sim.world import SimWorld

        world = SimWorld()
    labeller = FrameLabeller(world, cfg)
    size = (labeller.camera.width, labeller.camera.height)
    n_img: dict[str, int] = {}
    n_box: dict[str, int] = {}
    try:
        for split in splits:
            s_idx = SPLITS.index(split)
            total = cfg.split_sizes()[split]
            img_dir, lbl_dir, meta_dir = root / "images" / split, root / "labels" / split, root / "meta"
            for d in (img_dir, lbl_dir, meta_dir):
                d.mkdir(parents=True, exist_ok=True)
            for old in list(img_dir.glob("*.jpg")) + list(lbl_dir.glob("*.txt")):
                old.unlink()
            boxes_total = 0
            with (meta_dir / f"{split}.jsonl").open("w") as meta:
                for i in range(total):
                    rng = np.random.default_rng([cfg.seed, s_idx, i])
                    frame = labeller.render(rng)
                    stem = f"{i:06d}"
                    q = int(rng.integers(cfg.jpeg_quality[0], cfg.jpeg_quality[1] + 1))
                    ok = cv2.imwrite(str(img_dir / f"{stem}.jpg"), cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR),
                                     [cv2.IMWRITE_JPEG_QUALITY, q])
                    if not ok:
                        raise OSError(f"could not write {img_dir / stem}.jpg")
                    lines = yolo_label_lines(frame.boxes, frame.classes, size)
                    (lbl_dir / f"{stem}.txt").write_text("\n".join(lines) + ("\n" if lines else ""))
                    boxes_total += len(lines)
                    meta.write(json.dumps({
                        "image": f"images/{split}/{stem}.jpg",
                        "boxes_xyxy": np.round(frame.boxes, 2).tolist(),
                        "tips_uv": np.round(frame.tips, 2).tolist(),
                        "tip_visible": frame.tip_visible.tolist(),
                        "box_index": frame.box_index.tolist(),
                        "jpeg_quality": q,
                        **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in frame.info.items()},
                    }) + "\n")
                    if progress is not None:
                        progress(split, i + 1, total)
            n_img[split] = total
            n_box[split] = boxes_total
        data_yaml = write_data_yaml(root)
        (root / "config.json").write_text(json.dumps(asdict(cfg), indent=1) + "\n")
    finally:
        labeller.close()
        if own_world:
            world.close()
    return DatasetSummary(root=root, data_yaml=data_yaml, images=n_img, boxes=n_box,
                          seconds=time.perf_counter() - t0)
