"""Scenarios of the two cues beyond the paper (issue 13), each run with and without its cue.

- ``zoom``: two instruments work over the tissue, first at a moderate distance from each other,
  then far apart, then close together; the zoom cue (:mod:`lapwrench.wrenches.zoom`) moves the
  scope in and out to keep their spread in the image inside its band. Metric: the share of the
  tracking time (both instruments detected; no hand on the handle in this script) with the
  detected spread in the band, the quantity the cue regulates; the same share for the instrument
  tips projected by the simulator is reported beside it.
- ``keep-out``: a 20 N push on the handle drives the scope tip toward a keep-out zone
  (:mod:`lapwrench.wrenches.keep_out`): a sphere beside the tip under a lateral push (the tip
  moves opposite to the handle about the trocar), and a plane below the tip under an axial push
  into the body. Metric: the tip's smallest signed distance to the zone, which must stay >= 0
  with the cue and goes negative without it.

The keep-out distance is that of the simulated scope tip (its MuJoCo frame), not of the
controller's model at the reference; both scenarios report the physical RCM error. Durations
scale with ``time_scale`` like the paper's scenarios; the targets hold at full scale (a shorter
push may not reach the zone, faster instruments outrun the zoom).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lapwrench.config import Config
from lapwrench.sim.hard_push import ConstantPush
from lapwrench.sim.loop import ClosedLoop, Trace
from lapwrench.sim.results import DEFAULT_OPTIONS, Run, ScenarioOptions, ScenarioResult, number, run_metrics
from lapwrench.sim.scene.build import build_scene
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.world import CONTROL_DT, SimWorld
from lapwrench.wrenches.keep_out import plane_distance, sphere_distance
from lapwrench.wrenches.zoom import ZoomParams, in_band, instrument_spread

TISSUE_DEPTH = 0.145  # m below the incision: the phantom's tissue surface (as in sim/scenarios.py)
FRAME_C = "lap_C"

# zoom: the instruments' separation (m) at the script's times (s, full time scale); cosine blends
ZOOM_SCRIPT = ((0.0, 0.035), (1.5, 0.035), (3.5, 0.055), (5.5, 0.055), (7.5, 0.025), (10.0, 0.025))
ZOOM_TARGET = 0.8  # share of the tracking time in the band (issue 13)
ZOOM_SETTLE_S = 1.0  # s at the start while the first detections arrive and the cue first acts

# keep-out: a 20 N push (issue 13) held PUSH_S, then SETTLE_S without the hand
PUSH_N = 20.0
GRIP_FORCE = 30.0  # N on the tactile model: grip gain δ ≈ 2, the hard-push scenario's firm grip
PUSH_S = 4.5
SETTLE_S = 0.5
SPHERE_RADIUS = 0.02  # m
SPHERE_GAP = 0.01  # m from the tip to the sphere at the start
PLANE_GAP = 0.015  # m from the tip to the plane at the start


def _progress(opts: ScenarioOptions, loop: ClosedLoop) -> None:
    if opts.progress and round(loop.t * 1000) % 100 == 0:
        opts.progress(0.1)


# --------------------------------------------------------------------------- zoom


def separation(t: float, script: tuple[tuple[float, float], ...] = ZOOM_SCRIPT) -> float:
    """The instruments' separation (m) at ``t`` (s): the script's values blended with a cosine."""
    for (t0, s0), (t1, s1) in itertools.pairwise(script):
        if t < t1:
            x = max(0.0, (t - t0) / (t1 - t0))
            return s0 + (s1 - s0) * (0.5 - 0.5 * math.cos(math.pi * x))
    return script[-1][1]


def _place_instruments(loop: ClosedLoop, t: float, time_scale: float) -> None:
    """Both tips on the tissue below the incision, ``separation`` apart along y, with a slow sway."""
    centre = loop.world.incision_rest_position() + np.array([0.0, 0.0, -TISSUE_DEPTH])
    half = 0.5 * separation(t / time_scale)
    sway = 0.004 * math.sin(2 * math.pi * 0.3 * t / time_scale)
    loop.world.set_instrument_tip(0, centre + np.array([sway, half, 0.0]))
    loop.world.set_instrument_tip(1, centre + np.array([sway, -half, 0.0]))


def true_spread(loop: ClosedLoop) -> float:
    """The spread (zoom's measure) of the simulated instrument tips projected into the image; NaN
    unless both are in front of the camera and inside the image."""
    world, cam = loop.world, loop.cfg.camera
    tips = np.array([world.instrument_tip(i) for i in range(world.n_instruments)])
    uv, depth = world.project_to_image(tips)
    seen = (depth > 0.005) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
    return instrument_spread(uv[seen], cam.width, cam.height) if seen.all() else math.nan


def seen_spread(loop: ClosedLoop) -> float:
    """The spread of the instruments the detector reports now (what the zoom cue regulates: for a
    box detector the box centres, which lie further apart than the tips); NaN without two."""
    if loop.detection is None:
        return math.nan
    cam = loop.cfg.camera
    return instrument_spread(np.asarray(loop.detection.observation(loop.t).points, float).reshape(-1, 2),
                             cam.width, cam.height)


def _band_share(spread: np.ndarray, t: np.ndarray, start: float, band: tuple[float, float]) -> tuple[float, float]:
    """(tracking time (s): ticks from ``start`` on with a spread, share of it with the spread in the band)."""
    tracking = np.isfinite(spread) & (t >= start)
    inside = np.array([in_band(x, band) for x in spread[tracking]])
    return float(tracking.sum() * CONTROL_DT), (float(inside.mean()) if inside.size else math.nan)


def zoom_run(label: str, cfg: Config, opts: ScenarioOptions, band: tuple[float, float]) -> Run:
    """One run of the zoom script. Its tracking time: from ``ZOOM_SETTLE_S`` on, while the detector
    reports both instruments; ``in_band_fraction`` is the share of it with their detected spread in
    the band (``tip_in_band_fraction``: the same for the projected tips, from the simulator)."""
    loop = ClosedLoop(cfg, seed=opts.seed, detector=opts.detector, world=opts.world,
                      detector_threads=opts.detector_threads, render_in_background=opts.render_in_background)
    trace = Trace()
    duration = ZOOM_SCRIPT[-1][0] * opts.time_scale
    t0 = time.perf_counter()
    try:
        while loop.t < duration:
            _place_instruments(loop, loop.t, opts.time_scale)
            res = loop.step(0.0)
            loop.record(trace, res, spread=seen_spread(loop), tip_spread=true_spread(loop))
            _progress(opts, loop)
    finally:
        loop.close()  # the render process (render_in_background) and the GL contexts end with the run
    m = run_metrics(loop, trace, time.perf_counter() - t0)
    s, t, start = trace["spread"], trace["t"], ZOOM_SETTLE_S * opts.time_scale
    m["tracking_time_s"], m["in_band_fraction"] = _band_share(s, t, start, band)
    m["tip_tracking_time_s"], m["tip_in_band_fraction"] = _band_share(trace["tip_spread"], t, start, band)
    m["spread_min"] = float(np.nanmin(s)) if np.isfinite(s).any() else None
    m["spread_max"] = float(np.nanmax(s)) if np.isfinite(s).any() else None
    m["instrument_source"] = loop.detector_description
    return Run(label, trace, m)


def zoom(cfg: Config, opts: ScenarioOptions = DEFAULT_OPTIONS) -> ScenarioResult:
    """The zoom cue keeps two instruments' spread in its band while they move apart and together
    (module docstring); the same script without the cue for comparison."""
    entry = next((e for e in cfg.cues if e.type == "zoom" and e.enabled), None)
    with_cfg = cfg if entry is not None else cfg.replace(cues={"zoom": {}})
    params: ZoomParams = next(e.params for e in with_cfg.cues if e.type == "zoom" and e.enabled)
    name = next(e.name for e in with_cfg.cues if e.type == "zoom" and e.enabled)
    without_cfg = with_cfg.replace(cues={name: {"enabled": False}})
    runs = [zoom_run("with zoom", with_cfg, opts, params.band), zoom_run("without zoom", without_cfg, opts,
                                                                          params.band)]
    w, wo = runs[0].metrics, runs[1].metrics
    share = w["in_band_fraction"]  # NaN (a float) without any tracking time
    frac = share if isinstance(share, float) and not math.isnan(share) else None
    return ScenarioResult(
        "zoom",
        runs,
        {
            "band": list(params.band),
            "in_band_fraction": frac,
            "in_band_fraction_without_cue": wo["in_band_fraction"],
            "tip_in_band_fraction": w["tip_in_band_fraction"],
            "tracking_time_s": w["tracking_time_s"],
            "rcm_error_max_mm": w["rcm_error_max_mm"],
            "target": ZOOM_TARGET,
            "target_met": bool(frac is not None and frac >= ZOOM_TARGET),
        },
        instrument_source=str(w["instrument_source"]),
    )


# --------------------------------------------------------------------------- keep-out


@dataclass(frozen=True)
class KeepOutCase:
    """One keep-out run: the zone (a ``cues.keep_out`` entry) and the push that drives the tip at it."""

    label: str
    zone: dict[str, object]
    push: ConstantPush
    cue: bool

    def distance(self, world: SimWorld) -> float:
        """Signed distance (m) of the simulated scope tip to the zone, positive outside."""
        p = world.frame_pose(FRAME_C)[0]
        z = self.zone
        if z["shape"] == "sphere":
            return sphere_distance(p, np.asarray(z["center"]), float(z["radius"]))[0]  # type: ignore[arg-type]
        return plane_distance(p, np.asarray(z["point"]), np.asarray(z["normal"]))[0]


def start_pose(cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """(scope tip p_C, shaft direction d_z) of the simulated scope at its start pose, {B}."""
    world = SimWorld(build_scene(SceneConfig.from_config(cfg)))
    try:
        world.reset()
        return world.frame_pose(FRAME_C)[0], world.shaft_axis()[1]
    finally:
        world.close()


def keep_out_cases(cfg: Config, push_s: float) -> list[KeepOutCase]:
    """A sphere beside the tip with the handle pushed the other way (the tip swings toward it about
    the trocar), and a plane below the tip with the handle pushed in along the shaft; each with and
    without the cue."""
    p_C, d_z = start_pose(cfg)
    side = np.array([1.0, 0.0, 0.0])
    side -= (side @ d_z) * d_z
    side /= np.linalg.norm(side)
    centre = p_C - side * (SPHERE_RADIUS + SPHERE_GAP)  # the tip moves to -side under a +side push
    sphere: dict[str, object] = {"shape": "sphere", "center": [float(x) for x in centre], "radius": SPHERE_RADIUS}
    plane: dict[str, object] = {
        "shape": "plane", "point": [float(x) for x in p_C + PLANE_GAP * d_z], "normal": [float(x) for x in -d_z]
    }
    lateral = ConstantPush("lateral", side, PUSH_N, GRIP_FORCE, push_s)
    axial = ConstantPush("axial", d_z, PUSH_N, GRIP_FORCE, push_s)
    return [
        KeepOutCase(f"{name} {'with' if cue else 'without'} keep-out", zone, push, cue)
        for name, zone, push in (("sphere, lateral push", sphere, lateral), ("plane, axial push", plane, axial))
        for cue in (True, False)
    ]


def _keep_out_run(cfg: Config, case: KeepOutCase, opts: ScenarioOptions, duration: float) -> Run:
    entry = {**case.zone, "enabled": case.cue}
    loop = ClosedLoop(cfg.replace(cues={"keep_out": entry}), seed=opts.seed, world=opts.world)
    push = opts.world.hand(case.push)  # the surgeon's push and grip
    for i in range(loop.world.n_instruments):  # withdrawn into their ports: out of the view
        loop.world.set_instrument_tip(i, loop.world.port_position(i) + np.array([0.0, 0.0, -0.02]))
    trace = Trace()
    t0 = time.perf_counter()
    while loop.t < duration:
        grip = push.apply(loop.world, loop.t, CONTROL_DT)
        res = loop.step(grip)
        loop.record(trace, res, distance=case.distance(loop.world))
        _progress(opts, loop)
    m = run_metrics(loop, trace, time.perf_counter() - t0)
    d = trace["distance"]
    m["distance_start_mm"] = float(d[0] * 1e3)
    m["distance_min_mm"] = float(d.min() * 1e3)
    m["entered_zone"] = bool(d.min() < 0.0)
    return Run(case.label, trace, m)


def keep_out(cfg: Config, opts: ScenarioOptions = DEFAULT_OPTIONS) -> ScenarioResult:
    """20 N pushes toward a keep-out sphere and a keep-out plane, with and without the cue."""
    push_s, settle_s = PUSH_S * opts.time_scale, SETTLE_S * opts.time_scale
    runs = [_keep_out_run(cfg, c, opts, push_s + settle_s) for c in keep_out_cases(cfg, push_s)]
    with_cue = [r.metrics for r in runs if "with keep-out" in r.label]
    without = [r.metrics for r in runs if "without keep-out" in r.label]
    return ScenarioResult(
        "keep-out",
        runs,
        {
            "push_N": PUSH_N,
            "distance_min_mm": min(number(m, "distance_min_mm") for m in with_cue),
            "distance_min_without_cue_mm": min(number(m, "distance_min_mm") for m in without),
            "rcm_error_max_mm": max(number(m, "rcm_error_max_mm") for m in with_cue),
            "target_met": not any(m["entered_zone"] for m in with_cue),
            "entered_without_cue": all(bool(m["entered_zone"]) for m in without),
        },
    )


SCENARIOS: dict[str, Callable[[Config, ScenarioOptions], ScenarioResult]] = {"zoom": zoom, "keep-out": keep_out}
SIM_SECONDS = {"zoom": 2 * ZOOM_SCRIPT[-1][0], "keep-out": 4 * (PUSH_S + SETTLE_S)}


# --------------------------------------------------------------------------- plots and report lines


def plot(name: str, res: ScenarioResult, out: Path) -> list[str]:
    """The scenario's figure (PNG in ``out``): zoom, the spread against its band and the insertion,
    with and without the cue; keep-out, the tip's signed distance to the zone in every run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if name == "zoom":
        fig, (a0, a1) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
        band = res.metrics["band"]
        a0.axhspan(band[0], band[1], color="#8fd694", alpha=0.4, label="band")  # type: ignore[index]
        for run in res.runs:
            a0.plot(run.trace["t"], run.trace["spread"], label=run.label)
            a1.plot(run.trace["t"], run.trace["insertion_depth"] * 1e3, label=run.label)
        a0.set(ylabel="spread / image diagonal", title="zoom: instruments' spread in the image")
        a1.set(ylabel="flange to incision (mm)", xlabel="time (s)")
        a0.legend(fontsize=8)
        a1.legend(fontsize=8)
    else:
        fig, a0 = plt.subplots(1, 1, figsize=(10, 4.5))
        for run in res.runs:
            a0.plot(run.trace["t"], run.trace["distance"] * 1e3, label=run.label)
        a0.axhline(0.0, color="k", lw=1)
        a0.set(xlabel="time (s)", ylabel="tip to zone (mm, < 0 inside)",
               title=f"keep-out: {PUSH_N:.0f} N push toward the zone")
        a0.legend(fontsize=8)
    fig.tight_layout()
    path = out / f"{name.replace('-', '_')}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [path.name]


def _fmt(x: object, nd: int = 2) -> str:
    return "n/a" if x is None else f"{x:.{nd}f}" if isinstance(x, float) else str(x)


def report_lines(name: str, res: ScenarioResult, figures: list[str]) -> list[str]:
    """The scenario's section of the demo report (Markdown lines)."""
    if name == "zoom":
        head = "| run | in band | spread min | spread max | RCM max mm |"
    else:
        head = "| run | start mm | min mm | entered | RCM max mm |"
    title = "Zoom cue" if name == "zoom" else "Keep-out cue"
    L = [f"## {title} (issue 13)", "", head, "|---|---|---|---|---|"]
    for run in res.runs:
        m = run.metrics
        cells = ((m["in_band_fraction"], m["spread_min"], m["spread_max"]) if name == "zoom"
                 else (m["distance_start_mm"], m["distance_min_mm"], m["entered_zone"]))
        L.append(f"| {run.label} | " + " | ".join(_fmt(c) for c in cells) + f" | {_fmt(m['rcm_error_max_mm'])} |")
    summary = res.metrics
    target = (f"Target: spread in the band {summary['band']} at least {ZOOM_TARGET:.0%} of the tracking time"
              if name == "zoom" else f"Target: the tip never enters the zone under a {PUSH_N:.0f} N push")
    L += ["", f"{target}. Met: **{summary['target_met']}**."]
    if name == "keep-out":
        L.append(f"Without the cue the tip enters the zone in every run: **{summary['entered_without_cue']}**.")
    L.append("")
    return L + [f"![{name}]({f})" for f in figures] + [""]
