"""``lapwrench log-report``: PNG plots of a run log (RCM error, wrenches, mode, joint commands, and
the cues' telemetry when the log has any), ``summary.json`` (with the logger's drop counts, the
topics and the telemetry fields) and ``events.json``.

A truncated log (the run was killed before it closed its log) is read as far as it goes: one line
on stderr, ``lapwrench log-report: run.mcap is truncated (no summary/footer); read 1547 cycles up to
t=1.546 s``, the report of what was read (``"truncated"`` in summary.json) and exit code 0. A log
that cannot be read at all (missing, a directory, empty, not MCAP, corrupt, or cut before its
first cycle) gives one line on stderr and exit code 2, never a traceback.

A log's values are taken as they come, never trusted: a field that is not a number (text, an
integer beyond any float, a foreign program's layout) counts as missing, a cycle without a finite
time is left out, values beyond :data:`LARGEST` are drawn as gaps (an axis that spans them would
overflow), and summary.json and events.json hold ``null`` where the log has NaN or infinity (they
stay strict JSON). At most :data:`MAX_PANELS` joints, cues and wrenches are plotted (a damaged
vector of thousands would take hours to draw); summary.json's ``left_out_of_plots`` names the rest.

The report's files (:data:`REPORT_FILES`) of an earlier report in the same folder are removed first
and summary.json is written last, so a report cut short (Ctrl-C, a full disk) has no summary.json and
none of a report of another log is left beside it (its telemetry plot, say)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from lapwrench.cli_types import display_path, output_dir
from lapwrench.hardware.log.reader import LogContents, LogFileError, load_log
from lapwrench.hardware.log.topics import CYCLE_TOPIC

_QUIET_EVENTS = ("start", "deadline_miss", "log_dropped")
# summary.json is written last: a folder without it holds a report cut short (Ctrl-C, a full disk)
REPORT_FILES = ("summary.json", "events.json", "rcm_error.png", "wrenches.png", "mode.png", "joint_commands.png",
                "cue_telemetry.png")
LARGEST = 1e100  # beyond any quantity of a run: such a value is a corrupt record, drawn as a gap
MAX_PANELS = 16  # joints, cues, wrenches and telemetry fields plotted at most


def _num(x: object) -> float:
    """``x`` as a float if it is a real number (not a bool), else NaN (None, text, a list, an integer
    beyond any float)."""
    if isinstance(x, bool) or not isinstance(x, int | float):
        return math.nan
    try:
        return float(x)
    except OverflowError:
        return math.nan


def _mapping(c: dict[str, Any], key: str) -> dict[str, Any]:
    """``c[key]`` if it is a mapping, else an empty one."""
    v = c.get(key)
    return v if isinstance(v, dict) else {}


def _plottable(a: np.ndarray) -> np.ndarray:
    """``a`` with values that are not finite or beyond :data:`LARGEST` as NaN (gaps in a plot)."""
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(a) <= LARGEST, a, np.nan)


def _arr(cycles: list[dict[str, Any]], key: str, n: int) -> np.ndarray:
    """The first ``n`` values of a vector field of every cycle; missing or not numbers → NaN."""
    out = np.full((len(cycles), n), np.nan)
    for i, c in enumerate(cycles):
        v = c.get(key)
        if isinstance(v, list):
            row = [_num(x) for x in v[:n]]
            out[i, : len(row)] = row
    return out


def _col(cycles: list[dict[str, Any]], key: str) -> np.ndarray:
    """One scalar field of every cycle, ``None`` (or anything not a number) → NaN."""
    return np.array([_num(c.get(key)) for c in cycles], dtype=float)


def _time(c: dict[str, Any]) -> float:
    """A cycle's time if it is a number within :data:`LARGEST`, else NaN."""
    return float(_plottable(np.array(_num(c.get("t")))))


def _finite_json(value: Any) -> Any:
    """``value`` with every float that is not finite replaced by None (strict JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_json(v) for v in value]
    return value


def _plot_rcm(plt: Any, t: np.ndarray, cycles: list[dict[str, Any]], events: list[dict[str, Any]], out: Path) -> Path:
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t, _plottable(1e3 * _col(cycles, "rcm_error")), label="at the reference (controller)")
    meas = _plottable(1e3 * _col(cycles, "rcm_error_measured"))
    if np.isfinite(meas).any():
        ax.plot(t, meas, label="from the measured joints")
    for e in events:
        when = _time({"t": e.get("time")})
        if e.get("kind") not in _QUIET_EVENTS and math.isfinite(when):
            ax.axvline(when, color="r", lw=0.6, alpha=0.5)
    ax.set(xlabel="time (s)", ylabel="RCM error (mm)", title="RCM error (red lines: supervisor events)")
    ax.legend()
    ax.grid(alpha=0.3)
    return _save(fig, out / "rcm_error.png")


def _plot_wrenches(plt: Any, t: np.ndarray, cycles: list[dict[str, Any]], out: Path) -> Path:
    names = wrench_names(cycles)[:MAX_PANELS]
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name in names:
        w = _arr([{"w": _mapping(c, "wrenches").get(name)} for c in cycles], "w", 6)
        axes[0].plot(t, _plottable(np.linalg.norm(w[:, 3:], axis=1)), label=name)
        axes[1].plot(t, _plottable(np.linalg.norm(w[:, :3], axis=1)), label=name)
    ft = _arr(cycles, "ft_force", 3)
    axes[0].plot(t, _plottable(np.linalg.norm(ft, axis=1)), "k:", lw=0.8, label="F/T |F| (input)")
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
    axes[0].step(t, [_level(c.get("mode"), modes) for c in cycles], where="post")
    axes[0].set_yticks(range(len(modes)), modes)
    axes[0].set(title="Controller mode")
    axes[1].step(t, [_level(c.get("supervisor"), sup) for c in cycles], where="post")
    axes[1].set_yticks(range(len(sup)), sup)
    alarm = np.array([c.get("alarm") is True for c in cycles], dtype=bool)
    if alarm.any():
        axes[1].fill_between(t, -0.5, 2.5, where=alarm, color="r", alpha=0.15, label="alarm")
        axes[1].legend(fontsize=8)
    axes[1].set(xlabel="time (s)", title="Supervisor")
    return _save(fig, out / "mode.png")


def _level(value: object, names: list[str]) -> int:
    """The index of ``value`` among ``names``; -1 for anything else (absent, unknown, not text)."""
    return names.index(value) if isinstance(value, str) and value in names else -1


def _joint_count(cycles: list[dict[str, Any]]) -> int:
    """The arm's joint count as the log records it: the length of its joint vectors (at least 1)."""
    lengths = (len(v) for c in cycles for key in ("q", "q_cmd") if isinstance(v := c.get(key), list))
    return max(lengths, default=0) or 1


def _plot_joints(plt: Any, t: np.ndarray, cycles: list[dict[str, Any]], out: Path) -> Path:
    n = min(_joint_count(cycles), MAX_PANELS)
    q_cmd = _plottable(_arr(cycles, "q_cmd", n))
    q = _plottable(_arr(cycles, "q", n))
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
        for cue, values in _mapping(c, "telemetry").items():
            known = out.setdefault(cue, [])
            known.extend(f for f in (values if isinstance(values, dict) else ()) if f not in known)
    return out


def wrench_names(cycles: list[dict[str, Any]]) -> list[str]:
    """The names of the wrenches the log's cycles carry, sorted."""
    return sorted({k for c in cycles for k in _mapping(c, "wrenches")})


def _plot_telemetry(plt: Any, t: np.ndarray, cycles: list[dict[str, Any]], out: Path) -> Path | None:
    """One panel per cue, one line per telemetry field (None: the log has no telemetry)."""
    fields = dict(list(telemetry_fields(cycles).items())[:MAX_PANELS])
    if not fields:
        return None
    fig, grid = plt.subplots(len(fields), 1, figsize=(9, 2.5 * len(fields) + 0.5), sharex=True, squeeze=False)
    for ax, (cue, names) in zip(grid[:, 0], fields.items(), strict=True):
        for name in names[:MAX_PANELS]:
            y = [_mapping(_mapping(c, "telemetry"), cue).get(name) for c in cycles]
            ax.plot(t, _plottable(np.array([_num(v) for v in y], dtype=float)), label=name)
        ax.set(title=f"cue {cue}: telemetry")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    grid[-1, 0].set_xlabel("time (s)")
    return _save(fig, out / "cue_telemetry.png")


def _nan_stat(fn: Any, x: np.ndarray, scale: float = 1.0) -> float | None:
    """``scale * fn`` of the finite values of ``x``; None without any (or when it overflows)."""
    if not np.isfinite(x).any():
        return None
    with np.errstate(all="ignore"):
        value = float(scale * fn(x[np.isfinite(x)]))
    return value if math.isfinite(value) else None


def _left_out(cycles: list[dict[str, Any]]) -> list[str]:
    """What the plots leave out beyond :data:`MAX_PANELS`, in words."""
    counts = {"joints": _joint_count(cycles), "wrenches": len(wrench_names(cycles))}
    fields = telemetry_fields(cycles)
    counts["cues with telemetry"] = len(fields)
    counts.update({f"telemetry fields of cue {cue}": len(names) for cue, names in list(fields.items())[:MAX_PANELS]})
    return [f"{what} beyond the first {MAX_PANELS} (of {n})" for what, n in counts.items() if n > MAX_PANELS]


def _summary(log: LogContents, cycles: list[dict[str, Any]], t: np.ndarray) -> dict[str, Any]:
    compute = _col(cycles, "compute_us")
    return {
        "cycles": len(cycles),
        "duration_s": float(np.max(t) - np.min(t)),
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
        "left_out_of_plots": _left_out(cycles),
    }


def make_report(path: str | Path, out: str | Path, *, allow_truncated: bool = True) -> list[Path]:
    """Write the report PNGs (and summary.json, events.json) for a log into ``out``; a truncated
    log is reported as far as it goes (unless not ``allow_truncated``)."""
    return write_report(load_log(path, allow_truncated=allow_truncated), path, out)


def write_report(log: LogContents, path: str | Path, out: str | Path) -> list[Path]:
    """The report of a log already read (:func:`~lapwrench.hardware.log.reader.load_log`); the cycles
    without a usable time are left out (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cycles = [c for c in log.cycles if math.isfinite(_time(c))]
    if not cycles:
        if log.truncated is not None:
            raise LogFileError(
                f"{path}: truncated MCAP file ({log.truncated.size} bytes, {log.truncated.missing})"
                f" with no complete {CYCLE_TOPIC} message"
            )
        raise LogFileError(f"{path}: no {CYCLE_TOPIC} messages" + (" with a time" if log.cycles else ""))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name in REPORT_FILES:  # an earlier report's files: never beside this one's, even when it stops halfway
        (out / name).unlink(missing_ok=True)
    t = np.array([_time(c) for c in cycles])
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")  # numpy's overflow, matplotlib's empty legend: not the user's business
        files = [
            _plot_rcm(plt, t, cycles, log.events, out),
            _plot_wrenches(plt, t, cycles, out),
            _plot_modes(plt, t, cycles, out),
            _plot_joints(plt, t, cycles, out),
        ]
        telemetry = _plot_telemetry(plt, t, cycles, out)
        summary = _finite_json(_summary(log, cycles, t))
    if telemetry is not None:
        files.append(telemetry)
    (out / "events.json").write_text(json.dumps(_finite_json(log.events), indent=2, allow_nan=False))
    (out / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False))
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
    ts = [t for c in log.cycles if math.isfinite(t := _time(c))]
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
        print(display_path(f))
    if log.stats is not None:
        stats = _finite_json(log.stats)
        print(f"logger: {stats.get('cycles')} cycles written, {stats.get('dropped')} dropped")
    return 0


def add_log_report_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``lapwrench log-report``."""
    parser.add_argument("log", help="an MCAP run log (lapwrench run --log)")
    parser.add_argument("--out", default="log-report", type=output_dir,
                        help="folder for the PNG plots (checked before the log is read)")
