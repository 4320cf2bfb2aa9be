"""The demo's figures: one plot per paper scenario, every cue's wrench and telemetry, the snapshot strip.

Each ``plot_*`` writes PNGs into the report folder and returns their file names (the report
(:mod:`lapwrench.sim.report`) links them).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from lapwrench.config import Config
from lapwrench.sim.results import ScenarioResult, number
from lapwrench.sim.video import annotate_frame

MODES = ["idle", "tracking", "handle", "handle+tracking", "handle-dominant"]
MODE_COLORS = {
    "idle": "#dddddd",
    "tracking": "#8fd694",
    "handle": "#8fb8ff",
    "handle+tracking": "#ffd27f",
    "handle-dominant": "#ff8f8f",
}


def _save(fig: plt.Figure, path: Path) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def _mode_band(ax: plt.Axes, t: np.ndarray, modes: np.ndarray) -> None:
    start = 0
    for k in range(1, len(modes) + 1):
        if k == len(modes) or modes[k] != modes[start]:
            ax.axvspan(t[start], t[min(k, len(t) - 1)], color=MODE_COLORS[str(modes[start])], lw=0)
            start = k
    ax.set_yticks([])
    handles = [plt.Rectangle((0, 0), 1, 1, color=MODE_COLORS[m]) for m in MODES]
    ax.legend(handles, MODES, loc="upper center", ncol=5, fontsize=7, bbox_to_anchor=(0.5, -0.75), frameon=False)


def plot_grip(res: ScenarioResult, out: Path) -> list[str]:
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    for run in res.runs:
        tr = run.trace
        ax[0].plot(tr["t"], tr["delta"], label=f"{run.label} (δ̄={run.metrics['delta_mean']:.2f})")
        ax[1].plot(tr["t"], tr["view_error_deg"], label=run.label)
    ax[0].set(xlabel="time (s)", ylabel="grip gain δ (eq 7)", title="δ profiles (paper Fig. 4c)")
    ax[1].set(xlabel="time (s)", ylabel="view error (deg)", title="same 10° view adjustment")
    ax[0].legend(fontsize=8)
    ax[1].legend(fontsize=8)
    ours = [r.metrics["completion_time_s"] or np.nan for r in res.runs]
    x = np.arange(3)
    ax[2].bar(x - 0.2, ours, 0.4, label="lapwrench (sim)")
    ax[2].bar(x + 0.2, res.metrics["paper"]["completion_s"], 0.4, label="paper (phantom)")  # type: ignore[index]
    ax[2].set_xticks(x, [r.label for r in res.runs])
    ax[2].set(ylabel="completion time (s)", title="completion time vs grip")
    ax[2].legend(fontsize=8)
    return [_save(fig, out / "grip.png")]


def plot_disturbance(res: ScenarioResult, out: Path) -> list[str]:
    fig, ax = plt.subplots(1, 2, figsize=(12, 4))
    for run in res.runs:
        tr = run.trace
        ax[0].plot(tr["t"], np.linalg.norm(tr["contact_force"], axis=1), label=run.label)
    ax[0].axvline(3.6, ls="--", c="k", lw=1, label="load applied (3.6 s)")
    ax[0].axhline(5.0, ls=":", c="r", lw=1, label="5 N activation threshold")
    ax[0].set(xlabel="time (s)", ylabel="incision-wall contact force |ΔF| (N)", title="paper Fig. 5c")
    ax[0].legend(fontsize=8)
    tr = res.runs[0].trace
    pR = tr["p_R"] * 1e3
    inc = tr["incision"] * 1e3
    ax[1].plot(pR[:, 1], pR[:, 2], "b-", label="adaptive RCM point p_R")
    ax[1].plot(inc[:, 1], inc[:, 2], "k:", label="incision (physical)")
    for k, c in ((0, "g"), (len(tr["t"]) - 1, "r")):
        p, d = tr["p_E"][k] * 1e3, tr["d_z"][k]
        seg = np.array([p, p + 290 * d])
        ax[1].plot(seg[:, 1], seg[:, 2], c, lw=2, label="initial axis" if c == "g" else "final axis")
    ax[1].set(xlabel="y (mm)", ylabel="z (mm)", title="scope axes and RCM point (Fig. 5b), with adaptation")
    ax[1].set_xlim(inc[0, 1] - 15.0, inc[0, 1] + 25.0)
    ax[1].legend(fontsize=8)
    return [_save(fig, out / "rcm_disturbance.png")]


PAPER_FIGURES = {"needle-search": "paper Fig. 7b", "workflow": "paper Fig. 9"}
"""The paper's figure each tracking scenario reproduces."""


def tracking_title(name: str) -> str:
    """The title of a tracking scenario's wrench panel, naming the paper's figure when there is one."""
    fig = PAPER_FIGURES.get(name)
    return f"{name}: applied wrenches" + (f" ({fig})" if fig else "")


def scaled_to_peak(values: np.ndarray) -> tuple[np.ndarray, float]:
    """``values`` divided by their largest finite magnitude, and that magnitude (1 when there is none):
    telemetry fields of different units share one panel by shape, their peaks named in the legend."""
    v = np.asarray(values, dtype=float)
    finite = np.abs(v[np.isfinite(v)])
    peak = float(finite.max()) if finite.size else 0.0
    return (v / peak if peak > 0 else v), (peak if peak > 0 else 1.0)


def plot_tracking_run(res: ScenarioResult, out: Path, stem: str) -> list[str]:
    tr = res.runs[0].trace
    t = tr["t"]
    fig = plt.figure(figsize=(13, 7.5))
    gs = fig.add_gridspec(3, 2, width_ratios=[2.2, 1], height_ratios=[2, 2, 0.5])
    a0 = fig.add_subplot(gs[0, 0])
    a0.plot(t, np.linalg.norm(tr["W_h"][:, 3:], axis=1), label="|F_h| (handle, eq 6)")
    a0.plot(t, np.linalg.norm(tr["W_c"][:, 3:], axis=1), label="|F_c| (tracking, eq 8)")
    a0.set(ylabel="wrench force (N)", title=tracking_title(res.name))
    a0.legend(fontsize=8)
    a1 = fig.add_subplot(gs[1, 0], sharex=a0)
    a1.plot(t, tr["rcm_error_phys"] * 1e3, label="physical RCM error (mm)")
    a1.plot(t, tr["pixel_error"] / 100.0, label="instrument distance to centre (100 px)")
    a1.set(ylabel="mm  |  100 px")
    a1.legend(fontsize=8)
    a2 = fig.add_subplot(gs[2, 0], sharex=a0)
    _mode_band(a2, t, tr["mode"])
    a2.set_xlabel("time (s)")
    a3 = fig.add_subplot(gs[:, 1], projection="3d")
    step = max(1, len(t) // 60)
    for k in range(0, len(t), step):
        p, d = tr["p_E"][k], tr["d_z"][k]
        seg = np.array([p, p + 0.29 * d]) * 1e3
        a3.plot(seg[:, 0], seg[:, 1], seg[:, 2], color=plt.cm.viridis(k / len(t)), lw=0.8)
    for k, c in ((0, "g"), (len(t) - 1, "r")):
        p, d = tr["p_E"][k], tr["d_z"][k]
        seg = np.array([p, p + 0.29 * d]) * 1e3
        a3.plot(seg[:, 0], seg[:, 1], seg[:, 2], color=c, lw=2.5)
    f = tr["incision"].mean(axis=0) * 1e3
    a3.scatter([f[0]], [f[1]], [f[2]], c="k", s=30)
    a3.set(title="scope axes (green start, red end), fulcrum", xlabel="x (mm)", ylabel="y (mm)", zlabel="z (mm)")
    return [_save(fig, out / f"{stem}.png")]


def cue_columns(trace: object) -> tuple[list[str], list[str]]:
    """The cue wrench columns (``cue:<name>``) and telemetry columns (``cue:<name>.<field>``) of a trace."""
    names = [k for k in getattr(trace, "columns", {}) if k.startswith("cue:")]
    return [k for k in names if "." not in k], [k for k in names if "." in k]


def plot_cues(res: ScenarioResult, out: Path, stem: str) -> list[str]:
    """Every cue's force |F| (and its telemetry, if it has any), one row per run: whatever cues the
    configuration ran, with no code per cue."""
    runs = [r for r in res.runs if cue_columns(r.trace)[0]][:6]
    if not runs:
        return []
    with_telemetry = any(cue_columns(r.trace)[1] for r in runs)
    fig, axes = plt.subplots(len(runs), 2 if with_telemetry else 1, figsize=(13 if with_telemetry else 9,
                             2.6 * len(runs)), squeeze=False)
    for row, run in zip(axes, runs, strict=True):
        tr = run.trace
        t = tr["t"]
        wrenches, telemetry = cue_columns(tr)
        for key in wrenches:
            row[0].plot(t, np.linalg.norm(tr[key][:, 3:], axis=1), label=key.removeprefix("cue:"), lw=1)
        row[0].set(ylabel="|F| (N)", title=f"{res.name} / {run.label}: every cue's force")
        row[0].legend(fontsize=7, ncol=3)
        if with_telemetry:
            for key in telemetry:
                scaled, peak = scaled_to_peak(tr[key])
                row[1].plot(t, scaled, label=f"{key.removeprefix('cue:')} (peak {peak:.3g})", lw=1)
            row[1].set(title="cue telemetry, each field over its peak |value|", ylabel="value / peak")
            if telemetry:
                row[1].legend(fontsize=7)
            else:
                row[1].text(0.5, 0.5, "no telemetry in this run", ha="center", va="center",
                            transform=row[1].transAxes, color="0.4")
                row[1].set(xticks=[], yticks=[], ylabel="")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    return [_save(fig, out / f"{stem}_cues.png")]


def plot_hard_push(res: ScenarioResult, out: Path) -> list[str]:
    """Physical RCM error, trocar force and tip-depth change (mm) vs time, every hard-push run."""
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    kinds = sorted({str(r.metrics["kind"]) for r in res.runs})
    colors = {k: f"C{i}" for i, k in enumerate(kinds)}
    for run in res.runs:
        if "t" not in run.trace:
            continue
        tr, c = run.trace, colors[str(run.metrics["kind"])]
        ax[0].plot(tr["t"], tr["rcm_error_phys"] * 1e3, c=c, lw=0.8)
        ax[1].plot(tr["t"], np.linalg.norm(tr["contact_force"], axis=1), c=c, lw=0.8)
        ax[2].plot(tr["t"], (tr["tip_depth"] - tr["tip_depth"][0]) * 1e3, c=c, lw=0.8)
    tg: dict[str, float] = res.metrics["targets"]  # type: ignore[assignment]
    ax[0].axhline(tg["rcm_error_max_mm"], ls=":", c="r", lw=1)
    ax[1].axhline(tg["trocar_force_max_N"], ls=":", c="r", lw=1)
    d0 = number(res.runs[0].metrics, "tip_depth_start_mm") if res.runs else 0.0
    for k in ("tip_depth_min_mm", "tip_depth_max_mm"):
        ax[2].axhline(tg[k] - d0, ls=":", c="r", lw=1)
    ax[0].set(xlabel="time (s)", ylabel="physical RCM error (mm)", title="RCM error (target dotted)")
    ax[1].set(xlabel="time (s)", ylabel="trocar force |F| (N)", title="trocar force (target dotted)")
    ax[2].set(xlabel="time (s)", ylabel="tip depth change (mm, + = deeper)", title="depth (envelope range dotted)")
    handles = [plt.Line2D([], [], c=colors[k]) for k in kinds]
    ax[2].legend(handles, kinds, fontsize=8)
    return [_save(fig, out / "hard_push.png")]


def snapshot_strip(snapshots: list[tuple[np.ndarray, str]], cfg: Config, path: Path, n: int = 6) -> str:
    idx = np.linspace(0, len(snapshots) - 1, min(n, len(snapshots))).astype(int)
    fig, ax = plt.subplots(1, len(idx), figsize=(3 * len(idx), 2.6))
    for a, i in zip(np.atleast_1d(ax), idx, strict=True):
        frame, label = snapshots[i]
        a.imshow(annotate_frame(frame, cfg, label))
        a.axis("off")
    return _save(fig, path)
