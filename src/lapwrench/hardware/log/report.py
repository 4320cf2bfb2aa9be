"""``lapwrench log-report``: PNG plots of a run log (RCM error, wrenches, mode, joint commands, and
the cues' telemetry when the log has any), ``summary.json`` (with the logger's drop counts, the
topics and the telemetry fields) and ``events.json``.

A truncated log (the run was killed before it closed its log) is read as far as it goes: one line
on stderr, ``lapwrench log-report: run.mcap is truncated (no summary/footer); read 1547 cycles up to
t=1.546 s``, the report of what was read (``"truncated"`` in summary.json) and exit code 0. A log
that cannot be read at all (missing, a directory, empty, not MCAP, corrupt, or cut before its
first cycle) gives one line on stderr and exit code 2, never a traceback."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from lapwrench.cli_types import output_dir
from lapwrench.hardware.log.reader import LogContents, LogFileError, load_log
from lapwrench.hardware.log.topics import CYCLE_TOPIC

_QUIET_EVENTS = ("start", "deadline_miss", "log_dropped")


def _arr(cycles: list[dict[str, Any]], key: str, n: int) -> np.ndarray:
    out = np.full((len(cycles), n), np.nan)
    for i, c in enumerate(cycles):
        v = c.get(key)
        if v is not None:
            row = np.array([np.nan if x is None else x for x in v], dtype=float)[:n]
            out[i, : row.size] = row
    return out


def _col(cycles: list[dict[str, Any]], key: str) -> np.ndarray:
    """One scalar field of every cycle, ``None`` → NaN."""
    return np.array([np.nan if c.get(key) is None else c[key] for c in cycles], dtype=float)


def _plot_rcm(plt: Any, t: np.ndarray, cycles: list[dict[str, Any]], events: list[dict[str, Any]], out: Path) -> Path:
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t, 1e3 * _col(cycles, "rcm_error"), label="at the reference (controller)")
    meas = _col(cycles, "rcm_error_measured")
    if np.isfinite(meas).any():
        ax.plot(t, 1e3 * meas, label="from the measured joints")
    for e in events:
        if e.get("kind") not in _QUIET_EVENTS and isinstance(e.get("time"), int | float):
            ax.axvline(e["time"], color="r", lw=0.6, alpha=0.5)
    ax.set(xlabel="time (s)", ylabel="RCM error (mm)", title="RCM error (red lines: supervisor events)")
    ax.legend()
    ax.grid(alpha=0.3)
    return _save(fig, out / "rcm_error.png")


def _plot_wrenches(plt: Any, t: np.ndarray, cycles: list[dict[str, Any]], out: Path) -> Path:
    names = sorted({k for c in cycles for k in c.get("wrenches", {})})
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name in names:
        w = np.array(
            [[np.nan if x is None else x for x in (c["wrenches"].get(name) or [None] * 6)] for c in cycles], dtype=float
        )
        axes[0].plot(t, np.linalg.norm(w[:, 3:], axis=1), label=name)
        axes[1].plot(t, np.linalg.norm(w[:, :3], axis=1), label=name)
    ft = _arr(cycles, "ft_force", 3)
    axes[0].plot(t, np.linalg.norm(ft, axis=1), "k:", lw=0.8, label="F/T |F| (input)")
    axes[0].set(ylabel="|force| (N)", title="Wrenches")
    axes[1].set(xlabel="time (s)", ylabel="|moment| (N m)")
    for a in axes:
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    return _save(fig, out / "wrenches.png")


def _plot_modes(plt: Any, t: np.ndarray, cycles: list[dict[str, Any]], out: Path) -> Path:
    modes = ["idle", "tracking", "handle", "handle+tracking", "handle-dominant"]
    sup = ["running", "stopping", "holding"]
    fig, axes = plt.subplots(2, 1, figsize=(9, 4.5), sharex=True)
    axes[0].step(t, [modes.index(c["mode"]) if c["mode"] in modes else -1 for c in cycles], where="post")
    axes[0].set_yticks(range(len(modes)), modes)
    axes[0].set(title="Controller mode")
    axes[1].step(t, [sup.index(c["supervisor"]) if c["supervisor"] in sup else -1 for c in cycles], where="post")
    axes[1].set_yticks(range(len(sup)), sup)
    alarm = np.array([c["alarm"] for c in cycles], dtype=bool)
    if alarm.any():
        axes[1].fill_between(t, -0.5, 2.5, where=alarm, color="r", alpha=0.15, label="alarm")
        axes[1].legend(fontsize=8)
    axes[1].set(xlabel="time (s)", title="Supervisor")
    return _save(fig, out / "mode.png")


def _joint_count(cycles: list[dict[str, Any]]) -> int:
    """The arm's joint count as the log records it: the length of its joint vectors (at least 1)."""
    return max((len(c.get(key) or ()) for c in cycles for key in ("q", "q_cmd")), default=0) or 1


def _plot_joints(plt: Any, t: np.ndarray, cycles: list[dict[str, Any]], out: Path) -> Path:
    n = _joint_count(cycles)
    q_cmd = _arr(cycles, "q_cmd", n)
    q = _arr(cycles, "q", n)
    fig, grid = plt.subplots(n, 1, figsize=(9, 11), sharex=True, squeeze=False)
    axes = grid[:, 0]
    for j in range(n):
        axes[j].plot(t, q_cmd[:, j], label="command")
        axes[j].plot(t, q[:, j], "--", label="measured")
        axes[j].set_ylabel(f"q{j + 1} (rad)")
        axes[j].grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[0].set_title("Joint commands")
    axes[-1].set_xlabel("time (s)")
    return _save(fig, out / "joint_commands.png")


def telemetry_fields(cycles: list[dict[str, Any]]) -> dict[str, list[str]]:
    """cue → its telemetry field names, as the log's cycles carry them (first seen first)."""
    out: dict[str, list[str]] = {}
    for c in cycles:
        for cue, values in (c.get("telemetry") or {}).items():
            known = out.setdefault(cue, [])
            known.extend(f for f in values if f not in known)
    return out


def _plot_telemetry(plt: Any, t: np.ndarray, cycles: list[dict[str, Any]], out: Path) -> Path | None:
    """One panel per cue, one line per telemetry field (None: the log has no telemetry)."""
    fields = telemetry_fields(cycles)
    if not fields:
        return None
    fig, grid = plt.subplots(len(fields), 1, figsize=(9, 2.5 * len(fields) + 0.5), sharex=True, squeeze=False)
    for ax, (cue, names) in zip(grid[:, 0], fields.items(), strict=True):
        for name in names:
            y = [((c.get("telemetry") or {}).get(cue) or {}).get(name) for c in cycles]
            ax.plot(t, np.array([np.nan if v is None else v for v in y], dtype=float), label=name)
        ax.set(title=f"cue {cue}: telemetry")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    grid[-1, 0].set_xlabel("time (s)")
    return _save(fig, out / "cue_telemetry.png")


def _nan_stat(fn: Any, x: np.ndarray, scale: float = 1.0) -> float | None:
    return float(scale * fn(x[np.isfinite(x)])) if np.isfinite(x).any() else None


def _summary(log: LogContents, t: np.ndarray) -> dict[str, Any]:
    cycles = log.cycles
    compute = _col(cycles, "compute_us")
    return {
        "cycles": len(cycles),
        "duration_s": float(t[-1] - t[0]),
        "rcm_error_max_mm": _nan_stat(np.max, _col(cycles, "rcm_error"), 1e3),
        "rcm_error_measured_max_mm": _nan_stat(np.max, _col(cycles, "rcm_error_measured"), 1e3),
        "compute_p50_us": _nan_stat(lambda x: np.percentile(x, 50), compute),
        "compute_p99_us": _nan_stat(lambda x: np.percentile(x, 99), compute),
        "events": len(log.events),
        "telemetry": telemetry_fields(cycles),
        "truncated": None if log.truncated is None else dataclasses.asdict(log.truncated),
        "log_dropped": None if log.stats is None else log.stats.get("dropped"),
        "log_stats": log.stats,
        "topics": {k: {"schema": v.schema, "messages": v.messages} for k, v in sorted(log.topics.items())},
    }


def make_report(path: str | Path, out: str | Path, *, allow_truncated: bool = True) -> list[Path]:
    """Write the report PNGs (and summary.json, events.json) for a log into ``out``; a truncated
    log is reported as far as it goes (unless not ``allow_truncated``)."""
    return write_report(load_log(path, allow_truncated=allow_truncated), path, out)


def write_report(log: LogContents, path: str | Path, out: str | Path) -> list[Path]:
    """The report of a log already read (:func:`~lapwrench.hardware.log.reader.load_log`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cycles = [c for c in log.cycles if c.get("t") is not None]
    if not cycles:
        if log.truncated is not None:
            raise LogFileError(
                f"{path}: truncated MCAP file ({log.truncated.size} bytes, {log.truncated.missing})"
                f" with no complete {CYCLE_TOPIC} message"
            )
        raise LogFileError(f"{path}: no {CYCLE_TOPIC} messages")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t = _col(cycles, "t")
    files = [
        _plot_rcm(plt, t, cycles, log.events, out),
        _plot_wrenches(plt, t, cycles, out),
        _plot_modes(plt, t, cycles, out),
        _plot_joints(plt, t, cycles, out),
    ]
    telemetry = _plot_telemetry(plt, t, cycles, out)
    if telemetry is not None:
        files.append(telemetry)
    (out / "summary.json").write_text(json.dumps(_summary(log, t), indent=2))
    (out / "events.json").write_text(json.dumps(log.events, indent=2))
    return [*files, out / "summary.json", out / "events.json"]


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def truncation_note(path: str | Path, log: LogContents) -> str | None:
    """The line that says a log is truncated and how much of it was read (``None``: complete)."""
    if log.truncated is None:
        return None
    ts = [c["t"] for c in log.cycles if isinstance(c.get("t"), int | float)]
    upto = f" up to t={max(ts):.3f} s" if ts else ""
    return f"lapwrench log-report: {path} is truncated ({log.truncated.missing}); read {len(log.cycles)} cycles{upto}"


def log_report_main(args: argparse.Namespace) -> int:
    """``lapwrench log-report LOG --out DIR``: plots of a run log. Returns the exit code: 0 (also
    for a truncated log, reported as far as it goes, with one line on stderr), 2 for a log that
    cannot be read or a report that cannot be written (one line on stderr)."""
    path = Path(args.log)
    try:
        log = load_log(path, allow_truncated=True)
        files = write_report(log, path, args.out)
    except LogFileError as exc:
        print(f"lapwrench log-report: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # the report folder, matplotlib: one line, never a traceback
        print(f"lapwrench log-report: cannot report {path}: {type(exc).__name__}: {str(exc)[:120]}", file=sys.stderr)
        return 2
    note = truncation_note(path, log)
    if note is not None:
        print(note, file=sys.stderr)
    for f in files:
        print(f)
    if log.stats is not None:
        print(f"logger: {log.stats.get('cycles')} cycles written, {log.stats.get('dropped')} dropped")
    return 0


def add_log_report_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``lapwrench log-report``."""
    parser.add_argument("log", help="an MCAP run log (lapwrench run --log)")
    parser.add_argument("--out", default="log-report", type=output_dir,
                        help="folder for the PNG plots (checked before the log is read)")
