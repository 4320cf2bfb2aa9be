"""Small synthetic scenario results for the report's and the plots' tests (tests/sim/test_report.py,
tests/sim/test_plots.py)."""

from __future__ import annotations

import numpy as np

from lapwrench.sim.loop import Trace
from lapwrench.sim.results import Run, ScenarioResult

N = 50  # ticks of a synthetic trace
META = {
    "seed": 7, "robot": "fr3", "physics_dt_ms": 0.5, "wall_s": 12.4, "sim_s": 30.0, "instrument_source": "classical"
}


def trace(n: int = N, **extra: np.ndarray) -> Trace:
    """A trace with the columns the plots read: a scope pivoting slowly about a fixed incision."""
    t = np.arange(n) * 1e-3
    s = np.linspace(0.0, 1.0, n)
    d_z = np.stack([np.zeros(n), np.sin(0.1 * s), np.cos(0.1 * s)], axis=1)
    cols = {
        "t": t,
        "delta": 1.0 + s,
        "view_error_deg": 10.0 * (1.0 - s),
        "contact_force": np.stack([np.zeros(n), 4.0 * s, np.ones(n)], axis=1),
        "p_R": np.tile([0.4, 0.0, 0.3], (n, 1)) + 1e-3 * s[:, None],
        "incision": np.tile([0.4, 0.0, 0.3], (n, 1)),
        "p_E": np.tile([0.4, 0.0, 0.1], (n, 1)),
        "d_z": d_z,
        "W_h": np.tile([0.0, 0.0, 0.0, 1.0, 2.0, 2.0], (n, 1)),
        "W_c": np.tile([0.0, 0.0, 0.0, 0.0, 4.0, 3.0], (n, 1)),
        "rcm_error_phys": 1e-3 * s,
        "pixel_error": np.where(s < 0.5, 80.0, np.nan),
        "mode": np.array(["tracking"] * (n // 2) + ["handle"] * (n - n // 2)),
        "tip_depth": 0.06 + 0.01 * s,
        **extra,
    }
    return Trace(columns=cols)  # type: ignore[arg-type]


def grip() -> ScenarioResult:
    runs = [
        Run(label, trace(), {"delta_mean": d, "completion_time_s": c, "rcm_error_max_mm": 0.5})
        for label, d, c in (("high", 2.0, 6.0), ("medium", 1.1, None), ("low", 0.3, 20.0))
    ]
    paper = {"delta": [2.01, 1.13, 0.28], "completion_s": [6.32, 11.0, 19.46]}
    return ScenarioResult("grip", runs, {"paper": paper, "completion_falls_as_delta_rises": False})


def disturbance() -> ScenarioResult:
    m = {"force_peak_after_load_N": 7.25, "force_back_below_5N_after_s": None, "force_final_N": 3.0,
         "rcm_shift_mm": 9.876}
    return ScenarioResult("rcm-disturbance", [Run("adaptive", trace(), m)], {"target_met": True})


def needle_search(**metrics: object) -> ScenarioResult:
    m = {
        "rcm_error_max_mm": 1.5, "rcm_error_rms_mm": 0.4, "trocar_force_max_N": 6.0, "insertion_drift_mm": 3.0,
        "references_inside_limits": True, "real_time_factor": 0.8,
        # 0.1 s flickers between the dwells are left out of the mode sequence
        "mode_timeline": [(0.0, "idle"), (1.0, "tracking"), (1.1, "handle"), (1.2, "tracking"), (3.0, "handle")],
        **metrics,
    }
    return ScenarioResult("needle-search", [Run("run", trace(), {})], m, instrument_source="classical")


def hard_push() -> ScenarioResult:
    def run(label: str, passed: bool, t: bool = True) -> Run:
        m = {
            "kind": label.split()[0], "delta_mean": 1.0, "rcm_error_max_mm": 2.0, "trocar_force_max_N": 30.0,
            "tilt_max_deg": 4.0, "depth_change_min_mm": -2.0, "depth_change_max_mm": 5.0, "tip_depth_min_mm": 58.0,
            "tip_depth_max_mm": 65.0, "tip_depth_start_mm": 60.0, "envelope_hit_ticks": 3,
            "envelope_walls": "depth_max×3" if passed else "", "alarm": None if passed else "hold at 0.500 s: rcm",
            "references_inside_limits": True, "passed": passed, "failed_targets": "" if passed else "RCM",
        }
        return Run(label, trace() if t else Trace(), m)

    targets = {"rcm_error_max_mm": 3.0, "trocar_force_max_N": 40.0, "tip_depth_min_mm": 30.0, "tip_depth_max_mm": 120.0}
    metrics = {"push_s": 2.0, "settle_s": 1.0, "targets": targets, "passed": 1, "runs": 3, "alarms": 1,
               "all_references_inside_limits": True, "still_moving": ["lateral 30 N"]}
    return ScenarioResult("hard-push", [run("lateral 30 N", True), run("axial 50 N", False),
                                        run("axial 80 N", False, t=False)], metrics)
