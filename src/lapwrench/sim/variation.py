"""Variations of the simulated world a study sweeps: the surgeon, the trocar, the incision shift and
the detector (issue 14).

:class:`WorldVariation` holds the scales and sizes; its defaults are today's world exactly, so a
scenario run with the default variation gives the same figures, bit for bit. It reaches every
scenario through :attr:`lapwrench.sim.results.ScenarioOptions.world` and every
:class:`~lapwrench.sim.loop.ClosedLoop` through its ``world`` argument:

- the scripted hands scale through :meth:`WorldVariation.hand` (one place for the arithmetic);
- the trocar's lateral stiffness scales ``PhantomConfig.wall_stiffness`` (:meth:`WorldVariation.scene`);
- the detector is wrapped in :class:`CorruptedDetector` when dropout or noise is asked for.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar, TypeVar

import numpy as np

from lapwrench.perception.detection import Detection, Detector
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.surgeon import HandGuide

H = TypeVar("H")

# Modelled capture-to-use delay of a detection (s): one frame period at 25 fps. The shipped model's
# inference (two passes) is 9 ms in bench/detect.py and about 17 ms inside the simulated loop
# (sharing the CPU with physics and rendering); the rest stands for exposure, transfer, scheduling.
DETECTION_LATENCY = 0.04

RANGES: dict[str, tuple[float, float, str]] = {
    "surgeon_force": (0.1, 5.0, "a scale on the scripted pushes of up to 30 N: up to 150 N"),
    "surgeon_speed": (0.1, 5.0, "a scale on how fast the hand moves the scope (up to 1 rad/s) and builds its push"),
    "surgeon_grip": (0.1, 5.0, "a scale on the grip forces of 5, 17 and 30 N: 0.5-150 N"),
    "trocar_stiffness": (0.1, 10.0, "a scale on the wall's 1 N/mm at the incision: 0.1-10 N/mm"),
    "incision_shift_mm": (0.0, 30.0, "Fig. 5's housing shift, 10 mm; 30 mm pulls 30 N on the default wall"),
    "detector_latency_s": (0.0, 1.0, "one frame, 0.04 s, by default; a second is 25 frames behind"),
    "detector_dropout": (0.0, 1.0, "a probability, 1 (no detection ever) excluded"),
    "detector_noise_px": (0.0, 100.0, "σ of the point noise on a 640 x 480 image"),
}
"""Each field's allowed values, ``(lowest, highest, why)``: wide enough for any surgeon, wall and camera a
study might ask about, narrow enough that a run still describes one (a push of 10^300 N, or a wall
stiffness of 0, stops a simulation without saying anything). ``detector_dropout`` excludes its highest."""


@dataclass(frozen=True)
class WorldVariation:
    """How the simulated world differs from the default one (issue 14's world variations). Every field
    has a range (:data:`RANGES`); a value outside it is a one-line ValueError naming the field.

    Attributes:
        surgeon_force: scale on every scripted hand's push (``HandGuide.max_force``,
            ``SpeedDrivenHand.max_force``, the hard-push and keep-out magnitudes, N or N m).
        surgeon_speed: scale on the hand's speed (``HandGuide.max_speed`` of a speed-driven hand,
            ``gain``/``integral_gain`` of a force-driven one, ``SpeedDrivenHand.speed``).
        surgeon_grip: scale on every hand's grip force (N): the tactile model turns it into δ.
        trocar_stiffness: scale on ``PhantomConfig.wall_stiffness``, the wall's lateral stiffness at
            the incision.
        incision_shift_mm: size (mm) of the housing shift of the rcm-disturbance scenario (Fig. 5).
        detector_latency_s: capture-to-use latency (s) of the simulated detector
            (:data:`DETECTION_LATENCY` by default).
        detector_dropout: probability in [0, 1) that a frame's detections are all lost.
        detector_noise_px: σ (px) of the Gaussian noise on each detection's image point.
    """

    surgeon_force: float = 1.0
    surgeon_speed: float = 1.0
    surgeon_grip: float = 1.0
    trocar_stiffness: float = 1.0
    incision_shift_mm: float = 10.0
    detector_latency_s: float = DETECTION_LATENCY
    detector_dropout: float = 0.0
    detector_noise_px: float = 0.0

    FIELDS: ClassVar[tuple[str, ...]]  # the field names, in order (set below the class)

    def __post_init__(self) -> None:
        """Check every field (one-line ValueError naming it) and store it as a float, so equal
        variations compare, hash and serialise equal whether given as int or float."""
        for name in self.FIELDS:
            value = getattr(self, name)
            lo, hi, why = RANGES[name]
            allowed = f"world.{name} must be a number from {lo:g} to {hi:g}"
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{allowed} ({why}), got {repr(value)[:40]}")
            try:
                value = float(value)
            except OverflowError:  # an int beyond any float
                raise ValueError(f"{allowed} ({why}), got an integer of {len(str(abs(value)))} digits") from None
            if not (lo <= value <= hi) or (name == "detector_dropout" and value == hi):  # NaN fails the test
                raise ValueError(f"{allowed} ({why}), got {value!r}")
            object.__setattr__(self, name, value)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> WorldVariation:
        """The variation a study spec's ``world`` mapping describes; missing keys keep their default.

        Raises:
            ValueError: ``d`` is not a mapping, has a key that is not a field (the message lists
                the known ones), or a value out of range.
        """
        if not isinstance(d, Mapping):
            raise ValueError(f"world must be a mapping of {', '.join(cls.FIELDS)}, got {d!r}")
        unknown = sorted(str(k) for k in d if k not in cls.FIELDS)
        if unknown:
            raise ValueError(f"world: unknown key {unknown[0]!r} (known: {', '.join(cls.FIELDS)})")
        return cls(**dict(d))

    def to_dict(self) -> dict[str, float]:
        """Every field by name (floats): what a study row and a run's hash record."""
        return {name: getattr(self, name) for name in self.FIELDS}

    @property
    def surgeon_is_default(self) -> bool:
        """Whether the hands are today's (every surgeon scale 1)."""
        return self.surgeon_force == self.surgeon_speed == self.surgeon_grip == 1.0

    @property
    def detector_corrupted(self) -> bool:
        """Whether the detector's output is degraded (dropout or noise asked for)."""
        return self.detector_dropout > 0.0 or self.detector_noise_px > 0.0

    def hand(self, hand: H) -> H:
        """A copy of a scripted hand (a dataclass: ``HandGuide``, ``SpeedDrivenHand``,
        ``ConstantPush``) with this surgeon's force, speed and grip; ``hand`` itself when every
        surgeon scale is 1 (so default runs stay bit-identical).

        By field: ``grip_force`` × surgeon_grip; ``max_force`` and ``magnitude`` (a constant push,
        N or N m) × surgeon_force; the speed × surgeon_speed, which for a force-driven
        :class:`HandGuide` (no ``max_speed``) means its ``gain`` and ``integral_gain`` (how fast its
        push grows), for a speed-driven one ``max_speed``, and ``speed`` for a ``SpeedDrivenHand``.
        """
        if self.surgeon_is_default:
            return hand
        names = {f.name for f in fields(hand)}  # type: ignore[arg-type]
        changes: dict[str, object] = {}
        for name, scale in (("grip_force", self.surgeon_grip), ("max_force", self.surgeon_force),
                            ("magnitude", self.surgeon_force)):
            if name in names:
                changes[name] = getattr(hand, name) * scale
        if isinstance(hand, HandGuide):
            if hand.max_speed is None:  # force-driven: its push grows faster
                changes["gain"] = hand.gain * self.surgeon_speed
                changes["integral_gain"] = hand.integral_gain * self.surgeon_speed
            else:
                changes["max_speed"] = hand.max_speed * self.surgeon_speed
        elif "speed" in names:
            changes["speed"] = getattr(hand, "speed") * self.surgeon_speed  # noqa: B009
        return replace(hand, **changes)  # type: ignore[type-var]

    def scene(self, sc: SceneConfig) -> SceneConfig:
        """``sc`` with the trocar's lateral stiffness (``phantom.wall_stiffness``) scaled; ``sc``
        itself at scale 1."""
        if self.trocar_stiffness == 1.0:
            return sc
        ph = sc.phantom
        return replace(sc, phantom=replace(ph, wall_stiffness=ph.wall_stiffness * self.trocar_stiffness))

    def describe_detector(self) -> str:
        """What the corruption does, for the report's detector line ("" when none)."""
        if not self.detector_corrupted:
            return ""
        return (f" (corrupted: frames dropped with p = {self.detector_dropout:g}, "
                f"point noise σ = {self.detector_noise_px:g} px)")


WorldVariation.FIELDS = tuple(f.name for f in fields(WorldVariation))


class CorruptedDetector:
    """A :class:`~lapwrench.perception.detection.Detector` whose output is degraded like a worse
    camera or model: with probability ``dropout`` a frame yields no detections at all; otherwise each
    detection's point (its box and keypoint shifted the same) gets Gaussian noise of σ ``noise_px``.

    Seeded (``seed``: an int or a :class:`numpy.random.SeedSequence`), so a run is reproducible. The
    wrapped detector runs on every frame (its compute time stays measured). Other attributes
    (``name``, ``test_time_flip``, ...) are the wrapped detector's.
    """

    def __init__(self, detector: Detector, dropout: float = 0.0, noise_px: float = 0.0,
                 seed: int | np.random.SeedSequence = 0) -> None:
        if not (0.0 <= dropout < 1.0):
            raise ValueError(f"dropout must lie in [0, 1), got {dropout!r}")
        if not (math.isfinite(noise_px) and noise_px >= 0.0):
            raise ValueError(f"noise_px must be a finite number >= 0, got {noise_px!r}")
        self.detector = detector
        self.dropout = float(dropout)
        self.noise_px = float(noise_px)
        self.rng = np.random.default_rng(seed)

    def __getattr__(self, name: str) -> Any:
        """The wrapped detector's attribute (only called for names this class does not have)."""
        if name == "detector":  # not yet set (e.g. while unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.detector, name)

    def detect(self, image: np.ndarray) -> list[Detection]:
        """The wrapped detector's detections of ``image``, dropped or noisy (class docstring)."""
        dets = list(self.detector.detect(image))
        if self.dropout > 0.0 and self.rng.random() < self.dropout:
            return []
        if self.noise_px == 0.0:
            return dets
        return [self._shifted(d, *self.rng.normal(0.0, self.noise_px, 2)) for d in dets]

    @staticmethod
    def _shifted(d: Detection, du: float, dv: float) -> Detection:
        """``d`` moved by (du, dv) px: point, box and keypoint alike."""
        x0, y0, x1, y1 = d.box
        kp = None if d.keypoint is None else (d.keypoint[0] + du, d.keypoint[1] + dv)
        return replace(d, point=(d.point[0] + du, d.point[1] + dv), box=(x0 + du, y0 + dv, x1 + du, y1 + dv),
                       keypoint=kp)
