"""The simulated world's variations (issue 14): validation, the scaled hands and trocar, the corrupted
detector, and that every scenario feels them while the default variation changes nothing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.perception.detection import Detection
from lapwrench.sim.hard_push import ConstantPush
from lapwrench.sim.loop import ClosedLoop, Trace
from lapwrench.sim.results import DEFAULT_OPTIONS, ScenarioOptions, ScenarioResult
from lapwrench.sim.scenarios import grip, rcm_disturbance
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.surgeon import HandGuide, HousingDisturbance, SpeedDrivenHand
from lapwrench.sim.variation import DETECTION_LATENCY, RANGES, CorruptedDetector, WorldVariation
from lapwrench.sim.world import CONTROL_DT

CFG = load()
WALL_CLOCK = {"real_time_factor", "loop_compute_p50_us", "loop_compute_p99_us", "loop_over_budget_cycles"}


# --------------------------------------------------------------------------- the dataclass


def test_defaults_are_todays_world() -> None:
    v = WorldVariation()
    assert v.detector_latency_s == DETECTION_LATENCY
    assert v.incision_shift_mm == 10.0
    assert DEFAULT_OPTIONS.world == v and ScenarioOptions().world == v
    assert v.surgeon_is_default and not v.detector_corrupted


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("trocar_stiffness", math.nan, "world.trocar_stiffness must be a number from 0.1 to 10 (a scale on the wall's"
                                       " 1 N/mm at the incision: 0.1-10 N/mm), got nan"),
        ("surgeon_force", 0.0, "world.surgeon_force must be a number from 0.1 to 5"),
        ("surgeon_grip", -1.0, "world.surgeon_grip must be a number from 0.1 to 5"),
        ("surgeon_speed", math.inf, "world.surgeon_speed must be a number from 0.1 to 5"),
        ("incision_shift_mm", -2.0, "world.incision_shift_mm must be a number from 0 to 30"),
        ("detector_latency_s", math.nan, "world.detector_latency_s must be a number from 0 to 1"),
        ("detector_noise_px", -0.5, "world.detector_noise_px must be a number from 0 to 100"),
        ("detector_dropout", 1.0, "world.detector_dropout must be a number from 0 to 1 (a probability, 1 (no"
                                  " detection ever) excluded), got 1.0"),
        ("detector_dropout", -0.1, "world.detector_dropout must be a number from 0 to 1"),
        ("surgeon_force", "2", "world.surgeon_force must be a number from 0.1 to 5 (a scale on the scripted pushes of"
                               " up to 30 N: up to 150 N), got '2'"),
        ("surgeon_force", True, "got True"),
        ("detector_noise_px", None, "world.detector_noise_px must be a number from 0 to 100 (σ of the point noise on a"
                                    " 640 x 480 image), got None"),
        # beyond any physical world: refused, not simulated (a push of 1e300 N, an integer beyond any float)
        ("surgeon_force", 1e300, "world.surgeon_force must be a number from 0.1 to 5 (a scale on the scripted pushes"
                                 " of up to 30 N: up to 150 N), got 1e+300"),
        ("surgeon_speed", 5.01, "world.surgeon_speed must be a number from 0.1 to 5"),
        ("surgeon_grip", 1e-300, "world.surgeon_grip must be a number from 0.1 to 5"),
        ("trocar_stiffness", 10**400, "got an integer of 401 digits"),
        ("incision_shift_mm", 30.5, "world.incision_shift_mm must be a number from 0 to 30"),
        ("detector_latency_s", 3600, "world.detector_latency_s must be a number from 0 to 1"),
        ("detector_noise_px", 1e9, "world.detector_noise_px must be a number from 0 to 100"),
    ],
)
def test_bad_values_raise_one_line_naming_the_field(field: str, value: object, words: str) -> None:
    with pytest.raises(ValueError, match=r"^[^\n]+$") as err:
        WorldVariation.from_dict({field: value})
    assert words in str(err.value)


def test_every_range_holds_the_default_and_its_own_ends() -> None:
    """The ranges are inclusive (but for dropout's 1) and hold today's world; each has its reason."""
    for name, (lo, hi, why) in RANGES.items():
        assert lo <= getattr(WorldVariation(), name) <= hi and why
        WorldVariation.from_dict({name: lo})
        if name != "detector_dropout":
            WorldVariation.from_dict({name: hi})
    assert set(RANGES) == set(WorldVariation.FIELDS)


def test_from_dict_refuses_unknown_keys_and_lists_the_known_ones() -> None:
    with pytest.raises(ValueError, match=r"^[^\n]+$") as err:
        WorldVariation.from_dict({"surgeon_force": 2.0, "trocar_stifness": 2.0})
    assert "'trocar_stifness'" in str(err.value)
    assert all(name in str(err.value) for name in WorldVariation.FIELDS)
    with pytest.raises(ValueError, match="world must be a mapping"):
        WorldVariation.from_dict([("surgeon_force", 2.0)])  # type: ignore[arg-type]


def test_round_trip_and_ints_become_floats() -> None:
    v = WorldVariation.from_dict({"surgeon_force": 2, "detector_dropout": 0.25, "incision_shift_mm": 5})
    d = v.to_dict()
    assert list(d) == list(WorldVariation.FIELDS)
    assert d["surgeon_force"] == 2.0 and isinstance(d["surgeon_force"], float)
    assert WorldVariation.from_dict(d) == v
    assert hash(v) == hash(WorldVariation(surgeon_force=2.0, detector_dropout=0.25, incision_shift_mm=5.0))
    assert WorldVariation.from_dict({}) == WorldVariation()


# --------------------------------------------------------------------------- hands and trocar


def test_default_variation_returns_the_hand_itself() -> None:
    hand = HandGuide(np.array([0.0, 0.1, -1.0]), grip_force=17.0)
    assert WorldVariation().hand(hand) is hand


def test_hands_scale_by_force_speed_and_grip() -> None:
    v = WorldVariation(surgeon_force=2.0, surgeon_speed=0.5, surgeon_grip=1.5)
    axis = np.array([0.0, 0.1, -1.0])
    forced = v.hand(HandGuide(axis, grip_force=20.0, max_force=12.0, gain=60.0, integral_gain=25.0))
    assert (forced.grip_force, forced.max_force, forced.gain, forced.integral_gain) == (30.0, 24.0, 30.0, 12.5)
    assert forced.max_speed is None
    sped = v.hand(HandGuide(axis, grip_force=20.0, max_force=25.0, max_speed=0.25))
    assert (sped.max_speed, sped.max_force, sped.gain, sped.integral_gain) == (0.125, 50.0, 60.0, 25.0)
    assert np.allclose(sped.target_axis, axis / np.linalg.norm(axis))
    speed = v.hand(SpeedDrivenHand(np.array([1.0, 0.0, 0.0]), speed=1.0, grip_force=30.0, max_force=30.0))
    assert (speed.speed, speed.max_force, speed.grip_force, speed.gain) == (0.5, 60.0, 45.0, 60.0)
    push = v.hand(ConstantPush("roll", np.array([0.0, 0.0, 1.0]), 1.0, 30.0, 1.5))
    assert (push.magnitude, push.grip_force, push.duration) == (2.0, 45.0, 1.5)


def test_trocar_stiffness_scales_the_wall_only() -> None:
    sc = SceneConfig.from_config(CFG)
    assert WorldVariation().scene(sc) is sc
    stiff = WorldVariation(trocar_stiffness=3.0).scene(sc)
    assert stiff.phantom.wall_stiffness == pytest.approx(3.0 * sc.phantom.wall_stiffness)
    assert stiff.phantom.housing_stiffness == sc.phantom.housing_stiffness and stiff.scope == sc.scope


def housing_push_force(world: WorldVariation, ticks: int = 600) -> float:
    """Largest trocar force (N) while the housing is pushed 5 mm from t = 0, no RCM adaptation."""
    loop = ClosedLoop(CFG.replace(adaptive_rcm={"enabled": False}), seed=0, world=world)
    dist = HousingDisturbance(start=0.0, shift=(0.0, 0.005))
    trace = Trace()
    for _ in range(ticks):
        res = loop.step(0.0, before_physics=lambda t: dist.apply(loop.world, t))
        loop.record(trace, res)
    return float(np.linalg.norm(trace["contact_force"], axis=1).max())


def test_a_stiffer_trocar_carries_more_force_for_the_same_shift() -> None:
    soft, stiff = housing_push_force(WorldVariation()), housing_push_force(WorldVariation(trocar_stiffness=2.0))
    assert soft > 1.0  # the push really loaded the trocar
    assert stiff > 1.3 * soft


def mean_delta(world: WorldVariation, ticks: int = 300) -> float:
    """Mean grip gain δ while a scaled 17 N hand grips the handle (the view target is far away)."""
    loop = ClosedLoop(CFG, seed=0, world=world)
    _, d0 = loop.world.shaft_axis()
    hand = world.hand(HandGuide(d0 + np.array([0.3, 0.0, 0.0]), grip_force=17.0, max_force=0.5))
    deltas = [loop.step(hand.apply(loop.world, loop.t, CONTROL_DT)).delta for _ in range(ticks)]
    return float(np.mean(deltas[ticks // 2:]))


def test_surgeon_grip_raises_delta() -> None:
    base, firm = mean_delta(WorldVariation()), mean_delta(WorldVariation(surgeon_grip=1.5))
    assert base > 0.5
    assert firm > base + 0.3


# --------------------------------------------------------------------------- the detector


class FixedDetector:
    """Two instruments at fixed places in every frame."""

    name = "fixed"
    test_time_flip = True

    def detect(self, image: np.ndarray) -> list[Detection]:
        return [
            Detection(box=(90.0, 40.0, 110.0, 60.0), score=0.9, class_id=0, point=(100.0, 50.0), keypoint=(95.0, 45.0)),
            Detection(box=(290.0, 190.0, 310.0, 210.0), score=0.8, class_id=0, point=(300.0, 200.0)),
        ]


IMAGE = np.zeros((240, 320, 3), np.uint8)


def test_no_corruption_passes_detections_and_attributes_through() -> None:
    det = CorruptedDetector(FixedDetector(), dropout=0.0, noise_px=0.0, seed=1)
    assert all(det.detect(IMAGE) == FixedDetector().detect(IMAGE) for _ in range(50))
    assert det.name == "fixed" and det.test_time_flip is True


def test_dropout_loses_that_share_of_frames_reproducibly() -> None:
    def lost(seed: int) -> list[bool]:
        det = CorruptedDetector(FixedDetector(), dropout=0.3, seed=seed)
        return [not det.detect(IMAGE) for _ in range(4000)]

    frames = lost(7)
    assert np.mean(frames) == pytest.approx(0.3, abs=0.03)
    assert lost(7) == frames and lost(8) != frames


def test_noise_moves_point_box_and_keypoint_together_with_sigma() -> None:
    det = CorruptedDetector(FixedDetector(), noise_px=2.0, seed=3)
    shifts = []
    for _ in range(2000):
        d = det.detect(IMAGE)[0]
        du, dv = d.point[0] - 100.0, d.point[1] - 50.0
        assert d.center == pytest.approx(d.point) and d.keypoint == pytest.approx((95.0 + du, 45.0 + dv))
        assert (d.width, d.height, d.score) == pytest.approx((20.0, 20.0, 0.9))
        shifts.append((du, dv))
    s = np.array(shifts)
    assert np.abs(s.mean(axis=0)).max() < 0.15
    assert s.std(axis=0) == pytest.approx([2.0, 2.0], rel=0.08)


def test_corruption_arguments_are_checked() -> None:
    with pytest.raises(ValueError, match="dropout"):
        CorruptedDetector(FixedDetector(), dropout=1.0)
    with pytest.raises(ValueError, match="noise_px"):
        CorruptedDetector(FixedDetector(), noise_px=math.nan)


def test_the_loop_takes_latency_and_corruption_from_the_world() -> None:
    plain = ClosedLoop(CFG, detector="projected")
    assert plain.detection is not None and plain.detection.latency == DETECTION_LATENCY
    assert not isinstance(plain.detection.detector, CorruptedDetector)
    world = WorldVariation(detector_latency_s=0.1, detector_dropout=0.2, detector_noise_px=1.5)
    loop = ClosedLoop(CFG, detector="projected", world=world)
    assert loop.detection is not None and loop.detection.latency == 0.1
    assert isinstance(loop.detection.detector, CorruptedDetector)
    assert "p = 0.2" in loop.detector_description and "1.5 px" in loop.detector_description
    explicit = ClosedLoop(CFG, detector="projected", detection_latency=0.0, world=world)
    assert explicit.detection is not None and explicit.detection.latency == 0.0


# --------------------------------------------------------------------------- through the scenarios


def physical_metrics(res: ScenarioResult) -> list[dict[str, object]]:
    """Each run's metrics without the wall-clock ones (which differ from run to run)."""
    return [{k: v for k, v in r.metrics.items() if k not in WALL_CLOCK} for r in res.runs]


@pytest.fixture(scope="module")
def disturbance_default() -> ScenarioResult:
    return rcm_disturbance(CFG, ScenarioOptions(time_scale=0.1))


def test_default_world_changes_no_figure(disturbance_default: ScenarioResult) -> None:
    explicit = rcm_disturbance(CFG, ScenarioOptions(time_scale=0.1, world=WorldVariation()))
    assert physical_metrics(explicit) == physical_metrics(disturbance_default)
    for a, b in zip(explicit.runs, disturbance_default.runs, strict=True):
        assert np.array_equal(a.trace["contact_force"], b.trace["contact_force"])


def test_a_larger_incision_shift_moves_the_rcm_further(disturbance_default: ScenarioResult) -> None:
    big = rcm_disturbance(CFG, ScenarioOptions(time_scale=0.1, world=WorldVariation(incision_shift_mm=15.0)))
    base, more = disturbance_default.runs[0].metrics, big.runs[0].metrics  # with adaptation
    assert float(more["rcm_shift_mm"]) > float(base["rcm_shift_mm"]) + 2.0  # type: ignore[arg-type]
    assert float(big.runs[1].metrics["force_final_N"]) > float(  # type: ignore[arg-type]
        disturbance_default.runs[1].metrics["force_final_N"])  # type: ignore[arg-type]


@pytest.mark.slow
def test_surgeon_grip_raises_delta_at_every_grip_level() -> None:
    base = grip(CFG, ScenarioOptions(time_scale=0.2))
    firm = grip(CFG, ScenarioOptions(time_scale=0.2, world=WorldVariation(surgeon_grip=1.3)))
    assert [r.metrics["grip_force_N"] for r in firm.runs] == pytest.approx([39.0, 22.1, 6.5])
    for b, f in zip(base.metrics["delta_mean"], firm.metrics["delta_mean"], strict=True):  # type: ignore[call-overload]
        assert f > b + 0.05
