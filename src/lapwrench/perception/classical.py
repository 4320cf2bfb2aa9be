"""Weight-free OpenCV instrument detector for the synthetic scene (fallback backend).

The lapwrench scene has dark, unsaturated instrument shafts with light metallic jaws over pink/red
tissue. The detector:

1. thresholds low saturation and low value in HSV (the shafts; tissue, even in shadow, stays
   saturated);
2. opens the mask (removes speckles and thin vessels) and closes it (bridges the shaft sheen);
3. keeps connected components that are large (``min_area_fraction`` of the frame) and elongated
   (principal-axis ratio >= ``min_elongation``): small dark speckles fail both;
4. attaches bright, unsaturated components (the jaws) only where they touch a kept shaft, so bright
   specular speckles on the tissue are never detections on their own;
5. reports the box of shaft + jaws and the tip: the end of the component along its principal axis
   that lies in the image interior (the other end enters from the border).

The tip is :attr:`Detection.keypoint`; select it as the tracking point with
``TrackingPointRule(TrackingPoint.KEYPOINT)``. Scores are heuristic (elongation, jaws found), not
calibrated probabilities.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lapwrench.perception.detection import (
    Detection,
    DetectorConfig,
    Point,
    finalize,
    validate_frame,
)


@dataclass(frozen=True)
class ClassicalParams:
    """Thresholds of :class:`ClassicalDetector` (HSV in OpenCV's 0-255 scale for S and V).

    Attributes:
        shaft_max_value: shaft pixels have V below this.
        shaft_chroma_slope, shaft_chroma_offset: shaft pixels have chroma ``max(R,G,B) - min(R,G,B)``
            below ``slope * V + offset``. Tissue chroma grows with brightness (saturation ~0.5);
            a grey shaft's chroma is only noise. Plain HSV saturation is unstable on near-black
            pixels (noise of a few levels gives S ~ 0.4), chroma is not.
        smooth_px: box-filter size applied before thresholding (suppresses sensor noise).
        jaw_max_saturation: jaw pixels have S below this.
        jaw_min_value: jaw pixels have V above this.
        open_px: opening kernel diameter (removes speckles thinner than this).
        close_px: closing kernel diameter.
        min_area_fraction: minimum shaft component area as a fraction of the frame area.
        min_elongation: minimum ratio of principal-axis standard deviations.
        max_jaw_area_ratio: a bright component larger than this times the shaft area is not a jaw.
        border_px: an axis end within this distance of the border is the entry end.
        work_scale: process a resized copy (``0.5`` halves each side); boxes are scaled back.
            Thresholds in pixels (``open_px``, ``close_px``, ``border_px``) apply at work scale.
        max_instruments_per_component: at most this many straight bands split from one blob.
        ransac_hypotheses: line hypotheses per band when splitting crossing instruments.
        box: ``"instrument"`` reports the box of shaft + jaws; ``"jaws"`` the box of the jaws
            touching the shaft only (the tip region, as the simulator dataset labels it;
            instruments with no jaws found are then not reported).
    """

    shaft_max_value: int = 115
    shaft_chroma_slope: float = 0.25
    shaft_chroma_offset: float = 8.0
    smooth_px: int = 3
    jaw_max_saturation: int = 60
    jaw_min_value: int = 135
    open_px: int = 5
    close_px: int = 7
    min_area_fraction: float = 0.0015
    min_elongation: float = 3.0
    max_jaw_area_ratio: float = 0.6
    border_px: float = 6.0
    work_scale: float = 0.5
    max_instruments_per_component: int = 3
    ransac_hypotheses: int = 64
    box: str = "instrument"

    def __post_init__(self) -> None:
        if self.box not in ("instrument", "jaws"):
            raise ValueError(f"box must be 'instrument' or 'jaws', got {self.box!r}")


class ClassicalDetector:
    """HSV threshold + morphology + connected components instrument detector.

    Args:
        config: shared detector settings (frame size, colour order, tracking point, score
            threshold, ...). There is no box NMS: components are disjoint by construction, and the
            boxes of crossing diagonal instruments overlap heavily without being duplicates.
        params: the image-processing thresholds.
    """

    CLASS_NAME = "instrument"

    def __init__(self, config: DetectorConfig | None = None, params: ClassicalParams | None = None) -> None:
        self.config = config or DetectorConfig()
        self.params = params or ClassicalParams()
        p = self.params
        if not 0.0 < p.work_scale <= 1.0:
            raise ValueError(f"work_scale must lie in (0, 1], got {p.work_scale}")
        self._open = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (p.open_px, p.open_px))
        self._close = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (p.close_px, p.close_px))
        self._touch = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))

    def masks(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cleaned shaft mask and raw jaw mask (uint8 0/255) of a validated frame at work scale."""
        p = self.params
        if p.work_scale < 1.0:
            image = cv2.resize(image, None, fx=p.work_scale, fy=p.work_scale, interpolation=cv2.INTER_AREA)
        if p.smooth_px > 1:
            image = cv2.blur(image, (p.smooth_px, p.smooth_px))
        code = cv2.COLOR_RGB2HSV if self.config.color_order == "rgb" else cv2.COLOR_BGR2HSV
        hsv = cv2.cvtColor(np.ascontiguousarray(image), code)
        s, v = hsv[..., 1], hsv[..., 2]
        vf = v.astype(np.float32)
        chroma = s.astype(np.float32) * vf * np.float32(1.0 / 255.0)
        dark_grey = (vf < p.shaft_max_value) & (chroma < p.shaft_chroma_slope * vf + p.shaft_chroma_offset)
        shaft: np.ndarray = dark_grey.astype(np.uint8) * 255
        shaft = cv2.morphologyEx(shaft, cv2.MORPH_OPEN, self._open)
        shaft = cv2.morphologyEx(shaft, cv2.MORPH_CLOSE, self._close)
        jaw = ((s < p.jaw_max_saturation) & (v > p.jaw_min_value)).astype(np.uint8) * 255
        return shaft, jaw

    def detect(self, image: np.ndarray) -> list[Detection]:
        """Instruments in one ``H x W x 3`` uint8 frame, best score first.

        Raises:
            FrameError: the frame is empty, not colour, not uint8 or not the configured size.
        """
        image = validate_frame(image, self.config.frame_size)
        p = self.params
        h, w = image.shape[:2]
        shaft, jaw = self.masks(image)
        hs, ws = shaft.shape
        scale = ws / w
        min_area = p.min_area_fraction * hs * ws
        n, labels, stats, _ = cv2.connectedComponentsWithStats(shaft, connectivity=8)
        jaw_labels: np.ndarray | None = None
        jaw_stats: np.ndarray | None = None

        boxes: list[tuple[float, float, float, float]] = []
        scores: list[float] = []
        tips: list[Point] = []
        for k in range(1, n):
            x, y, bw, bh, area = (int(c) for c in stats[k])
            if area < min_area:
                continue
            comp = (labels[y:y + bh, x:x + bw] == k).astype(np.uint8)
            ys, xs = np.nonzero(comp)
            comp_pts = np.c_[xs + x, ys + y].astype(np.float64)
            dist = cv2.distanceTransform(comp, cv2.DIST_L2, 3)
            width = max(2.0, float(np.percentile(dist[comp > 0], 90)) / 0.45)
            for pts in self._split_lines(comp_pts, width, min_area):
                mean = pts.mean(axis=0)
                evals, evecs = np.linalg.eigh(np.cov((pts - mean).T))
                elong = float(np.sqrt(evals[1] / max(evals[0], 1e-9)))
                if elong < p.min_elongation:
                    continue
                if jaw_labels is None:
                    _, jaw_labels, jaw_stats, _ = cv2.connectedComponentsWithStats(jaw, connectivity=8)
                assert jaw_stats is not None
                jaw_pts = self._touching_jaws(pts, len(pts), jaw_labels, jaw_stats)
                all_pts = np.vstack([pts, jaw_pts]) if jaw_pts is not None else pts
                if p.box == "jaws" and jaw_pts is None:
                    continue
                tip = self._tip(all_pts, mean, evecs[:, 1], (ws, hs), jaw_pts)
                box_pts = jaw_pts if p.box == "jaws" and jaw_pts is not None else all_pts  # jaws: not None (above)
                bx0, by0 = box_pts.min(axis=0)
                bx1, by1 = box_pts.max(axis=0) + 1.0
                boxes.append((bx0 / scale, by0 / scale, bx1 / scale, by1 / scale))
                tips.append((float(tip[0]) / scale, float(tip[1]) / scale))
                shape_score = min(1.0, (elong - p.min_elongation) / p.min_elongation)
                scores.append(0.5 + 0.3 * shape_score + (0.2 if jaw_pts is not None else 0.0))

        if not boxes:
            return []
        if self.config.classes is not None and 0 not in self.config.classes:
            return []
        b = np.asarray(boxes)
        sc = np.asarray(scores)
        keep = np.nonzero(sc >= self.config.score_threshold)[0]
        return finalize(b[keep], sc[keep], np.zeros(len(keep), np.int64), (w, h), self.config,
                        [self.CLASS_NAME], keypoints=[tips[int(i)] for i in keep])

    def _split_lines(self, pts: np.ndarray, width: float, min_area: float) -> list[np.ndarray]:
        """Split a shaft component into straight bands (crossing instruments merge into one blob).

        A component whose pixels nearly all lie in one band of the estimated shaft ``width`` around
        its principal axis is one instrument. Otherwise bands are peeled off by RANSAC line fits;
        pixels at a crossing belong to both bands.
        """
        p = self.params
        band = 0.5 * width + 2.0
        mean = pts.mean(axis=0)
        _, evecs = np.linalg.eigh(np.cov((pts - mean).T))
        if np.mean(self._line_distance(pts, mean, evecs[:, 1]) <= band) >= 0.95:
            return [pts]
        rng = np.random.default_rng(0)
        out: list[np.ndarray] = []
        remaining = np.ones(len(pts), bool)
        for _ in range(p.max_instruments_per_component):
            rest = pts[remaining]
            if len(rest) < min_area:
                break
            sample = rest[rng.choice(len(rest), size=min(len(rest), 600), replace=False)]
            i, j = rng.integers(0, len(sample), (2, p.ransac_hypotheses))
            d = sample[j] - sample[i]
            norm = np.hypot(d[:, 0], d[:, 1])
            ok = norm > 3.0 * width
            if not ok.any():
                break
            origins, dirs = sample[i][ok], d[ok] / norm[ok, None]
            rel = sample[None, :, :] - origins[:, None, :]
            perp = np.abs(rel[..., 0] * dirs[:, None, 1] - rel[..., 1] * dirs[:, None, 0])
            best = int(np.argmax((perp <= band).sum(axis=1)))
            inl = sample[perp[best] <= band]
            c = inl.mean(axis=0)
            _, ev = np.linalg.eigh(np.cov((inl - c).T))
            member = self._line_distance(pts, c, ev[:, 1]) <= band
            if (member & remaining).sum() < 0.5 * min_area:
                break
            out.append(pts[member])
            remaining &= ~member
        return out

    @staticmethod
    def _line_distance(pts: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
        rel = pts - origin
        return np.abs(rel[:, 0] * direction[1] - rel[:, 1] * direction[0])

    def _touching_jaws(self, pts: np.ndarray, area: int, jaw_labels: np.ndarray,
                       jaw_stats: np.ndarray) -> np.ndarray | None:
        """Pixels of the bright (jaw) components touching the shaft pixels ``pts``, or ``None``."""
        hs, ws = jaw_labels.shape
        m = 4
        x0, y0 = max(int(pts[:, 0].min()) - m, 0), max(int(pts[:, 1].min()) - m, 0)
        x1, y1 = min(int(pts[:, 0].max()) + m + 1, ws), min(int(pts[:, 1].max()) + m + 1, hs)
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        mask[pts[:, 1].astype(int) - y0, pts[:, 0].astype(int) - x0] = 1
        near = cv2.dilate(mask, self._touch) > 0
        touching = np.unique(jaw_labels[y0:y1, x0:x1][near])
        found = []
        for j in touching[touching > 0]:
            jx, jy, jw, jh, ja = (int(c) for c in jaw_stats[j])
            if ja > self.params.max_jaw_area_ratio * area:
                continue
            jys, jxs = np.nonzero(jaw_labels[jy:jy + jh, jx:jx + jw] == j)
            found.append(np.c_[jxs + jx, jys + jy].astype(np.float64))
        return np.vstack(found) if found else None

    def _tip(self, pts: np.ndarray, mean: np.ndarray, axis: np.ndarray, size: tuple[int, int],
             jaw_pts: np.ndarray | None) -> np.ndarray:
        """The axis end of ``pts`` in the image interior (the instrument tip)."""
        w, h = size
        proj = (pts - mean) @ axis
        lo, hi = proj.min(), proj.max()
        band = max(2.0, 0.02 * (hi - lo))
        ends = [pts[proj <= lo + band].mean(axis=0), pts[proj >= hi - band].mean(axis=0)]
        margin = [min(e[0], e[1], w - 1 - e[0], h - 1 - e[1]) for e in ends]
        at_border = [m <= self.params.border_px for m in margin]
        if at_border[0] != at_border[1]:
            return ends[1] if at_border[0] else ends[0]
        if jaw_pts is not None:
            jc = jaw_pts.mean(axis=0)
            return min(ends, key=lambda e: float(np.hypot(*(e - jc))))
        c = np.array([w / 2.0, h / 2.0])
        if all(at_border):  # crosses the view: the end deeper inside wins
            return max(ends, key=lambda e: min(e[0], e[1], w - 1 - e[0], h - 1 - e[1]))
        return min(ends, key=lambda e: float(np.hypot(*(e - c))))
