"""``lapwrench log-report``: PNG plots of a run log (RCM error, wrenches, mode, joint commands, and
the cues' telemetry when the log has any), ``summary.json`` (with the logger's drop counts, the
topics and the telemetry fields) and ``events.json``.

A truncated log (the run was killed before it closed its log) is read as far as it goes: one line
on stderr, ``lapwrench log-report: run.mcap is truncated (no summary/footer); read 1547 cycles up to
t=1.546 s``, the report of what was read (``"truncated"`` in summary.json) and exit code 0. A log
that cannot be read at all (missing, a directory, empty, not MCAP, corrupt, or cut before its
first cycle) gives one line on stderr and exit code 2, never a traceback.

The cycles are read one at a time into the few numbers the report draws (:mod:`.columns`: 0.7 kB a
cycle, where holding the cycles took 9.2 kB), never held whole: a log of 100 000 cycles is reported in
392 MB at peak, 1128 MB before (2026-12-03, on the same log, one after the other). A log's values are taken as
they come, never trusted: a field that is not a number (text, an integer beyond any float, a foreign
program's layout) counts as missing, a cycle without a session time is left out (and counted in
summary.json's ``cycles_without_time``), values beyond
:data:`~.columns.LARGEST` are drawn as gaps (an axis that spans them would overflow), and summary.json
and events.json hold ``null`` where the log has NaN or infinity (they stay strict JSON). At most
:data:`~.columns.MAX_PANELS` joints, cues and wrenches are plotted (a damaged vector of thousands would
take hours to draw); summary.json's ``left_out_of_plots`` names the rest.

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
from lapwrench.hardware.log.columns import (
    MAX_PANELS,
    MODES,
    SUPERVISOR,
    CycleColumns,
    cycle_time,
    plottable,
)
from lapwrench.hardware.log.reader import LogContents, LogFileError, load_log
from lapwrench.hardware.log.topics import CYCLE_TOPIC

_QUIET_EVENTS = ("start", "deadline_miss", "log_dropped", "log_bad_time")
# summary.json is written last: a folder without it holds a report cut short (Ctrl-C, a full disk)
REPORT_FILES = ("summary.json", "events.json", "rcm_error.png", "wrenches.png", "mode.png", "joint_commands.png",
                "cue_telemetry.png")


def _finite_json(value: Any) -> Any:
    """``value`` with every float that is not finite replaced by None (strict JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_json(v) for v in value]
    return value


def _plot_rcm(plt: Any, t: np.ndarray, cols: CycleColumns, events: list[dict[str, Any]], out: Path) -> Path:
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t, plottable(1e3 * cols.column("rcm_error")), label="at the reference (controller)")
    meas = plottable(1e3 * cols.column("rcm_error_measured"))
    if np.isfinite(meas).any():
        ax.plot(t, meas, label="from the measured joints")
    for e in events:
        when = cycle_time({"t": e.get("time")})
        if e.get("kind") not in _QUIET_EVENTS and math.isfinite(when):
            ax.axvline(when, color="r", lw=0.6, alpha=0.5)
    ax.set(xlabel="time (s)", ylabel="RCM error (mm)", title="RCM error (red lines: supervisor events)")
    ax.legend()
    ax.grid(alpha=0.3)
    return _save(fig, out / "rcm_error.png")


def _plot_wrenches(plt: Any, t: np.ndarray, cols: CycleColumns, out: Path) -> Path:
    names = sorted(cols.wrenches)[:MAX_PANELS]
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name in names:
        w = cols.matrix(f"wrench {name}", 6)
        axes[0].plot(t, plottable(np.linalg.norm(w[:, 3:], axis=1)), label=name)
        axes[1].plot(t, plottable(np.linalg.norm(w[:, :3], axis=1)), label=name)
    ft = cols.matrix("ft_force", 3)
    axes[0].plot(t, plottable(np.linalg.norm(ft, axis=1)), "k:", lw=0.8, label="F/T |F| (input)")
    axes[0].set(ylabel="|force| (N)", title="Wrenches")
    axes[1].set(xlabel="time (s)", ylabel="|moment| (N m)")
    for a in axes:
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    return _save(fig, out / "wrenches.png")


def _plot_modes(plt: Any, t: np.ndarray, cols: CycleColumns, out: Path) -> Path:
    fig, axes = plt.subplots(2, 1, figsize=(9, 4.5), sharex=True)
    axes[0].step(t, cols.column("mode").astype(int), where="post")
    axes[0].set_yticks(range(len(MODES)), MODES)
    axes[0].set(title="Controller mode")
    axes[1].step(t, cols.column("supervisor").astype(int), where="post")
    axes[1].set_yticks(range(len(SUPERVISOR)), SUPERVISOR)
    alarm = cols.column("alarm") == 1.0
    if alarm.any():
        axes[1].fill_between(t, -0.5, 2.5, where=alarm, color="r", alpha=0.15, label="alarm")
        axes[1].legend(fontsize=8)
    axes[1].set(xlabel="time (s)", title="Supervisor")
    return _save(fig, out / "mode.png")


def _joint_count(cols: CycleColumns) -> int:
    """The arm's joint count as the log records it: the length of its joint vectors (at least 1)."""
    return cols.joints or 1


def _plot_joints(plt: Any, t: np.ndarray, cols: CycleColumns, out: Path) -> Path:
    n = min(_joint_count(cols), MAX_PANELS)
    q_cmd = plottable(cols.matrix("q_cmd", n))
    q = plottable(cols.matrix("q", n))
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


def _plot_telemetry(plt: Any, t: np.ndarray, cols: CycleColumns, out: Path) -> Path | None:
    """One panel per cue, one line per telemetry field (None: the log has no telemetry)."""
    fields = dict(list(cols.telemetry.items())[:MAX_PANELS])
    if not fields:
        return None
    fig, grid = plt.subplots(len(fields), 1, figsize=(9, 2.5 * len(fields) + 0.5), sharex=True, squeeze=False)
    for ax, (cue, names) in zip(grid[:, 0], fields.items(), strict=True):
        for name in names[:MAX_PANELS]:
            ax.plot(t, plottable(cols.telemetry_values(cue, name)), label=name)
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


def _left_out(cols: CycleColumns) -> list[str]:
    """What the plots leave out beyond :data:`MAX_PANELS`, in words."""
    counts = {"joints": _joint_count(cols), "wrenches": len(cols.wrenches)}
    fields = cols.telemetry
    counts["cues with telemetry"] = len(fields)
    counts.update({f"telemetry fields of cue {cue}": len(names) for cue, names in list(fields.items())[:MAX_PANELS]})
    return [f"{what} beyond the first {MAX_PANELS} (of {n})" for what, n in counts.items() if n > MAX_PANELS]


def _summary(log: LogContents, cols: CycleColumns, t: np.ndarray) -> dict[str, Any]:
    compute = cols.column("compute_us")
    return {
        "cycles": cols.n,
        "cycles_without_time": cols.read - cols.n,  # left out: no session time (NaN, negative, text...)
        "duration_s": float(np.max(t) - np.min(t)),
        "rcm_error_max_mm": _nan_stat(np.max, cols.column("rcm_error"), 1e3),
        "rcm_error_measured_max_mm": _nan_stat(np.max, cols.column("rcm_error_measured"), 1e3),
        "compute_p50_us": _nan_stat(lambda x: np.percentile(x, 50), compute),
        "compute_p99_us": _nan_stat(lambda x: np.percentile(x, 99), compute),
        "events": len(log.events),
        "telemetry": cols.telemetry,
        "truncated": None if log.truncated is None else dataclasses.asdict(log.truncated),
        "log_dropped": None if log.stats is None else log.stats.get("dropped"),
        "log_stats": log.stats,
        "topics": {k: {"schema": v.schema, "messages": v.messages} for k, v in sorted(log.topics.items())},
        "left_out_of_plots": _left_out(cols),
    }


def read_for_report(path: str | Path, *, allow_truncated: bool = True) -> tuple[LogContents, CycleColumns]:
    """A log read for its report: the events, meta, stats and topics as :func:`load_log` gives them, the
    cycles only as :class:`CycleColumns` (never held whole; see :mod:`.columns`)."""
    cols = CycleColumns()
    return load_log(path, allow_truncated=allow_truncated, on_cycle=cols.add), cols


def make_report(path: str | Path, out: str | Path, *, allow_truncated: bool = True) -> list[Path]:
    """Write the report PNGs (and summary.json, events.json) for a log into ``out``; a truncated
    log is reported as far as it goes (unless not ``allow_truncated``)."""
    log, cols = read_for_report(path, allow_truncated=allow_truncated)
    return write_report(log, path, out, cols)


def write_report(log: LogContents, path: str | Path, out: str | Path, cols: CycleColumns | None = None) -> list[Path]:
    """The report of a log already read: by :func:`read_for_report` (its ``cols``), or by
    :func:`~lapwrench.hardware.log.reader.load_log` with its cycles. The cycles without a usable time
    are left out (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if cols is None:
        cols = CycleColumns()
        for c in log.cycles:
            cols.add(c)
    if not cols.n:
        if log.truncated is not None:
            raise LogFileError(
                f"{path}: truncated MCAP file ({log.truncated.size} bytes, {log.truncated.missing})"
                f" with no complete {CYCLE_TOPIC} message"
            )
        raise LogFileError(f"{path}: no {CYCLE_TOPIC} messages" + (" with a time" if cols.read else ""))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name in REPORT_FILES:  # an earlier report's files: never beside this one's, even when it stops halfway
        (out / name).unlink(missing_ok=True)
    t = cols.column("t")
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")  # numpy's overflow, matplotlib's empty legend: not the user's business
        files = [
            _plot_rcm(plt, t, cols, log.events, out),
            _plot_wrenches(plt, t, cols, out),
            _plot_modes(plt, t, cols, out),
            _plot_joints(plt, t, cols, out),
        ]
        telemetry = _plot_telemetry(plt, t, cols, out)
        summary = _finite_json(_summary(log, cols, t))
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


def truncation_note(path: str | Path, log: LogContents, cols: CycleColumns | None = None) -> str | None:
    """The line that says a log is truncated and how much of it was read (``None``: complete); ``cols``:
    the cycles as :func:`read_for_report` gathered them (else ``log.cycles``)."""
    if log.truncated is None:
        return None
    if cols is None:
        cols = CycleColumns()
        for c in log.cycles:
            cols.add(c)
    upto = f" up to t={np.max(cols.column('t')):.3f} s" if cols.n else ""
    return f"lapwrench log-report: {path} is truncated ({log.truncated.missing}); read {cols.read} cycles{upto}"


def log_report_main(args: argparse.Namespace) -> int:
    """``lapwrench log-report LOG --out DIR``: plots of a run log. Returns the exit code: 0 (also
    for a truncated log, reported as far as it goes, with one line on stderr), 2 for a log that
    cannot be read or a report that cannot be written (one line on stderr)."""
    path = Path(args.log)
    try:
        log, cols = read_for_report(path)
        files = write_report(log, path, args.out, cols)
    except LogFileError as exc:
        print(f"lapwrench log-report: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # the report folder, matplotlib: one line, never a traceback
        print(f"lapwrench log-report: cannot report {path}: {type(exc).__name__}: {str(exc)[:120]}", file=sys.stderr)
        return 2
    note = truncation_note(path, log, cols)
    if note is not None:
        print(note, file=sys.stderr)
    for f in files:
        print(display_path(f))
    if log.stats is not None:
        stats = _finite_json(log.stats)
        bad = f", {stats['bad_times']} with a bad time" if stats.get("bad_times") else ""
        print(f"logger: {stats.get('cycles')} cycles written, {stats.get('dropped')} dropped{bad}")
    return 0


def add_log_report_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``lapwrench log-report``."""
    parser.add_argument("log", help="an MCAP run log (lapwrench run --log)")
    parser.add_argument("--out", default="log-report", type=output_dir,
                        help="folder for the PNG plots (checked before the log is read)")
