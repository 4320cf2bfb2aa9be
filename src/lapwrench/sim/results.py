"""What a scenario run returns and the physical metrics every run reports.

:class:`ScenarioResult` (its :class:`Run` s with their traces and metrics), the
:class:`ScenarioOptions` every scenario takes, and :func:`run_metrics`. Shared by the scenarios
(:mod:`lapwrench.sim.scenarios`, :mod:`lapwrench.sim.hard_push`) and the report
(:mod:`lapwrench.sim.report`), below all three.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lapwrench.robot.limits import limit_usage
from lapwrench.sim.loop import ClosedLoop, Trace
from lapwrench.sim.variation import WorldVariation
from lapwrench.sim.world import CONTROL_DT

Metric = float | str | None  # one metric of a run: a number, a text (its kind, an alarm), None (not defined)


@dataclass
class Run:
    """One closed-loop run of a scenario: its label, its trace and its metrics."""

    label: str
    trace: Trace
    metrics: dict[str, Metric]


def number(metrics: Mapping[str, Metric], key: str) -> float:
    """The metric ``key`` as a float; TypeError if it holds text or None (not defined in this run)."""
    v = metrics[key]
    if v is None or isinstance(v, str):
        raise TypeError(f"metric {key!r} is not a number: {v!r}")
    return float(v)


@dataclass
class ScenarioResult:
    """A scenario's runs, its summary metrics, snapshot frames and where its instrument points came from."""

    name: str
    runs: list[Run]
    metrics: dict[str, object]
    frames: list[tuple[np.ndarray, str]] = field(default_factory=list)  # (frame, label) snapshots
    figures: list[str] = field(default_factory=list)  # its report's figure files (the demo draws them)
    instrument_source: str = ""


@dataclass(frozen=True)
class ScenarioOptions:
    """How a scenario runs: seed, time scale, video output, progress callback, detector and the
    world's variation (surgeon, trocar, incision shift, detector corruption; default: none)."""

    seed: int = 0
    time_scale: float = 1.0
    video_dir: Path | None = None  # write the laparoscope view of the tracking scenarios here
    frames: bool = True  # keep the laparoscope view's frames (the snapshot strip); False: none drawn for it
    progress: Callable[[float], None] | None = None  # called with simulated seconds advanced
    detector: str = "shipped"  # "shipped", "classical", "projected" or a model path
    detector_threads: int | None = None  # onnxruntime threads of an ONNX detector (None: its default)
    render_in_background: bool = False  # draw the camera's frames in a child process (a core to spare)
    world: WorldVariation = field(default_factory=WorldVariation)  # the default world: no variation


DEFAULT_OPTIONS = ScenarioOptions()
"""The options a scenario runs with when given none (frozen, so one shared instance is safe)."""


def loop_compute_metrics(loop: ClosedLoop) -> dict[str, float | int]:
    """The control loop's own figures over the run: compute time per cycle (wall clock, from the
    robot's read to the command) and the cycles over the supervisor's 800 µs budget. The simulated
    robot waits for the loop, so these are reported, not enforced (a real robot enforces them)."""
    c = np.asarray(loop.compute_us)
    if not c.size:
        return {}
    return {
        "loop_compute_p50_us": float(np.percentile(c, 50)),
        "loop_compute_p99_us": float(np.percentile(c, 99)),
        "loop_over_budget_cycles": int(np.sum(c > loop.supervisor.cfg.cycle_budget * 1e6)),
    }


def run_metrics(loop: ClosedLoop, trace: Trace, wall: float, track_index: int | None = None) -> dict[str, Metric]:
    """Physical metrics of one run."""
    F = np.linalg.norm(trace["contact_force"], axis=1)
    phys = trace["rcm_error_phys"] * 1e3
    usage = limit_usage(trace["q_ref"], CONTROL_DT, loop.model.limits, loop.q0)
    sim_time = float(trace["t"][-1] + CONTROL_DT)
    m: dict[str, Metric] = {
        "duration_s": sim_time,
        "rcm_error_max_mm": float(phys.max()),
        "rcm_error_rms_mm": float(np.sqrt(np.mean(phys**2))),
        "rcm_controller_error_max_mm": float(trace["rcm_error_ctrl"].max() * 1e3),
        "trocar_force_max_N": float(F.max()),
        "trocar_time_above_5N_s": float(np.sum(F > 5.0) * CONTROL_DT),
        "limit_velocity_usage": usage["velocity"],
        "limit_acceleration_usage": usage["acceleration"],
        "limit_jerk_usage": usage["jerk"],
        "limit_position_excess": usage["position_excess"],
        "references_inside_limits": bool(
            max(usage["velocity"], usage["acceleration"], usage["jerk"]) <= 1.0 and usage["position_excess"] == 0.0
        ),
        "real_time_factor": sim_time / wall if wall > 0 else None,
        "insertion_drift_mm": float(np.ptp(trace["insertion_depth"]) * 1e3),
    }
    m.update(loop_compute_metrics(loop))
    if "pixel_error" in trace:
        px = trace["pixel_error"]
        seen = px[np.isfinite(px)]
        m["tracking_error_median_px"] = float(np.median(seen)) if seen.size else None
        m["tracking_error_p90_px"] = float(np.percentile(seen, 90)) if seen.size else None
        m["instrument_visible_fraction"] = float(seen.size / px.size)
    return m
