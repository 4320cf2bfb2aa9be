"""Run logs in MCAP (JSON messages with JSON schemas): Foxglove, ``mcap`` CLI and Python open them.

Topics
------
``/lapwrench/cycle`` (one message per control cycle, 1 kHz)
    time, robot time, measured q/dq/tau_J/external force, the inputs the loop used (F/T force
    and torque, the 64 tactile values, instrument image points; ``null`` = absent or stale), each
    wrench ``[moment; force]``, the mode, grip gain, the RCM point, the RCM error vector and norm
    (at the reference) and the RCM error of the *measured* joints, the controller's command, the
    command actually sent, supervisor state/alarm, compute and cycle times.
``/lapwrench/event``
    supervisor and input events: ``{time, kind, message}``.
``/lapwrench/meta``
    one message at the start: configuration, robot, devices, command line.

Writing never blocks the control loop: :meth:`RunLogger.cycle` puts the cycle's objects on a
queue and a writer thread serialises them. ``log_time`` is the session time in ns.

:func:`log_report_main` turns a log into PNG plots (RCM error, wrenches, mode, joint commands).
"""

from __future__ import annotations

import argparse
import json
import queue
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

CYCLE_TOPIC = "/lapwrench/cycle"
EVENT_TOPIC = "/lapwrench/event"
META_TOPIC = "/lapwrench/meta"

_VEC = {"type": "array", "items": {"type": "number"}}
_OPT_VEC = {"type": ["array", "null"], "items": {"type": "number"}}

CYCLE_SCHEMA: dict[str, Any] = {
    "title": "lapwrench.Cycle",
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "session time (s)"},
        "robot_time": {"type": "number", "description": "robot time (s)"},
        "k": {"type": "integer"},
        "q": _VEC,
        "dq": _VEC,
        "tau_J": _VEC,
        "external_force": _OPT_VEC,
        "ft_force": _OPT_VEC,
        "ft_torque": _OPT_VEC,
        "tactile": _OPT_VEC,
        "instruments": {"type": ["array", "null"], "items": _VEC},
        "wrenches": {"type": "object", "additionalProperties": _VEC},
        "mode": {"type": "string"},
        "delta": {"type": "number"},
        "contacts": {"type": "integer"},
        "p_R": _VEC,
        "e_R": _VEC,
        "rcm_error": {"type": "number", "description": "m, at the reference"},
        "rcm_error_measured": {"type": ["number", "null"], "description": "m, from the measured joints"},
        "q_ref": _VEC,
        "q_cmd": _VEC,
        "supervisor": {"type": "string"},
        "alarm": {"type": "boolean"},
        "compute_us": {"type": "number"},
        "cycle_us": {"type": "number"},
    },
}
EVENT_SCHEMA: dict[str, Any] = {
    "title": "lapwrench.Event",
    "type": "object",
    "properties": {"time": {"type": "number"}, "kind": {"type": "string"}, "message": {"type": "string"}},
}
META_SCHEMA: dict[str, Any] = {"title": "lapwrench.Meta", "type": "object"}


def _list(x: Any) -> Any:
    if x is None:
        return None
    return np.asarray(x, dtype=float).tolist()


def _finite_json(x: Any) -> Any:
    """JSON has no NaN/inf: send them as null (a logged NaN input stays visible as a gap)."""
    if isinstance(x, float):
        return x if np.isfinite(x) else None
    if isinstance(x, list):
        return [_finite_json(v) for v in x]
    if isinstance(x, dict):
        return {k: _finite_json(v) for k, v in x.items()}
    return x


@dataclass
class CycleRecord:
    """What the loop hands to the logger each cycle (references; serialised in the writer thread)."""

    t: float
    robot_time: float
    k: int
    q: Any
    dq: Any
    tau_J: Any
    external_force: Any
    ft_force: Any
    ft_torque: Any
    tactile: Any
    instruments: Any
    wrenches: dict[str, Any]
    mode: str
    delta: float
    contacts: int
    p_R: Any
    e_R: Any
    rcm_error: float
    rcm_error_measured: float | None
    q_ref: Any
    q_cmd: Any
    supervisor: str
    alarm: bool
    compute_us: float
    cycle_us: float

    def to_dict(self) -> dict[str, Any]:
        d = {
            "t": self.t,
            "robot_time": self.robot_time,
            "k": self.k,
            "q": _list(self.q),
            "dq": _list(self.dq),
            "tau_J": _list(self.tau_J),
            "external_force": _list(self.external_force),
            "ft_force": _list(self.ft_force),
            "ft_torque": _list(self.ft_torque),
            "tactile": _list(self.tactile),
            "instruments": _list(self.instruments),
            "wrenches": {k: _list(v) for k, v in self.wrenches.items()},
            "mode": self.mode,
            "delta": float(self.delta),
            "contacts": int(self.contacts),
            "p_R": _list(self.p_R),
            "e_R": _list(self.e_R),
            "rcm_error": float(self.rcm_error),
            "rcm_error_measured": None if self.rcm_error_measured is None else float(self.rcm_error_measured),
            "q_ref": _list(self.q_ref),
            "q_cmd": _list(self.q_cmd),
            "supervisor": self.supervisor,
            "alarm": bool(self.alarm),
            "compute_us": float(self.compute_us),
            "cycle_us": float(self.cycle_us),
        }
        return _finite_json(d)


class RunLogger:
    """Writes a run to an MCAP file from a background thread.

    Args:
        path: Output ``.mcap`` file (parent folders are created).
        meta: Written once on ``/lapwrench/meta``.
    """

    def __init__(self, path: str | Path, meta: dict[str, Any] | None = None) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library="lapwrench")
        self._channels: dict[str, int] = {}
        for topic, schema in ((CYCLE_TOPIC, CYCLE_SCHEMA), (EVENT_TOPIC, EVENT_SCHEMA), (META_TOPIC, META_SCHEMA)):
            sid = self._writer.register_schema(
                name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
            )
            self._channels[topic] = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        self._seq = 0
        self._queue: queue.SimpleQueue[tuple[str, float, Any] | None] = queue.SimpleQueue()
        self.cycles = 0
        self.events = 0
        self.errors = 0
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="lapwrench-mcap", daemon=True)
        self._thread.start()
        if meta is not None:
            self._queue.put((META_TOPIC, 0.0, meta))

    def cycle(self, record: CycleRecord) -> None:
        """Queue one cycle (never blocks)."""
        self._queue.put((CYCLE_TOPIC, record.t, record))

    def event(self, time: float, kind: str, message: str) -> None:
        """Queue one event (never blocks)."""
        self._queue.put((EVENT_TOPIC, time, {"time": time, "kind": kind, "message": message}))

    def _write(self, topic: str, t: float, payload: Any) -> None:
        data = payload.to_dict() if isinstance(payload, CycleRecord) else _finite_json(payload)
        ns = max(0, round(t * 1e9))
        self._writer.add_message(
            channel_id=self._channels[topic],
            log_time=ns,
            publish_time=ns,
            sequence=self._seq,
            data=json.dumps(data, separators=(",", ":")).encode(),
        )
        self._seq += 1
        if topic == CYCLE_TOPIC:
            self.cycles += 1
        elif topic == EVENT_TOPIC:
            self.events += 1

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                self._write(*item)
            except Exception:  # a bad record must not kill the logger
                self.errors += 1

    def close(self) -> None:
        """Flush the queue and finish the file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._thread.join()
        self._writer.finish()
        self._file.close()

    def __enter__(self) -> RunLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- reading ------------------------------------------------------------------------------------
def read_log(path: str | Path) -> tuple[list[dict[str, Any]], list[dict[str, Any]], dict[str, Any] | None]:
    """(cycles, events, meta) of an MCAP run log."""
    cycles, events = [], []
    meta: dict[str, Any] | None = None
    for topic, data in iter_messages(path):
        if topic == CYCLE_TOPIC:
            cycles.append(data)
        elif topic == EVENT_TOPIC:
            events.append(data)
        elif topic == META_TOPIC:
            meta = data
    return cycles, events, meta


def iter_messages(path: str | Path) -> Iterator[tuple[str, Any]]:
    """(topic, decoded JSON) for every message, in log-time order."""
    from mcap.reader import make_reader

    with Path(path).open("rb") as f:
        reader = make_reader(f)
        for _schema, channel, message in reader.iter_messages(log_time_order=True):
            yield channel.topic, json.loads(message.data)


def _arr(cycles: list[dict[str, Any]], key: str, n: int) -> np.ndarray:
    out = np.full((len(cycles), n), np.nan)
    for i, c in enumerate(cycles):
        v = c.get(key)
        if v is not None:
            out[i] = np.array([np.nan if x is None else x for x in v], dtype=float)
    return out


def make_report(path: str | Path, out: str | Path) -> list[Path]:
    """Write the report PNGs for a log into ``out``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cycles, events, _meta = read_log(path)
    if not cycles:
        raise ValueError(f"{path}: no {CYCLE_TOPIC} messages")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t = np.array([c["t"] for c in cycles])
    files: list[Path] = []

    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t, 1e3 * np.array([c["rcm_error"] for c in cycles]), label="at the reference (controller)")
    meas = np.array([np.nan if c.get("rcm_error_measured") is None else c["rcm_error_measured"] for c in cycles])
    if np.isfinite(meas).any():
        ax.plot(t, 1e3 * meas, label="from the measured joints")
    for e in events:
        if e["kind"] not in ("start", "deadline_miss"):
            ax.axvline(e["time"], color="r", lw=0.6, alpha=0.5)
    ax.set(xlabel="time (s)", ylabel="RCM error (mm)", title="RCM error (red lines: supervisor events)")
    ax.legend()
    ax.grid(alpha=0.3)
    files.append(_save(fig, out / "rcm_error.png"))

    names = sorted({k for c in cycles for k in c.get("wrenches", {})})
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name in names:
        w = np.array([c["wrenches"].get(name, [np.nan] * 6) for c in cycles], dtype=float)
        axes[0].plot(t, np.linalg.norm(w[:, 3:], axis=1), label=name)
        axes[1].plot(t, np.linalg.norm(w[:, :3], axis=1), label=name)
    ft = _arr(cycles, "ft_force", 3)
    axes[0].plot(t, np.linalg.norm(ft, axis=1), "k:", lw=0.8, label="F/T |F| (input)")
    axes[0].set(ylabel="|force| (N)", title="Wrenches")
    axes[1].set(xlabel="time (s)", ylabel="|moment| (N m)")
    for a in axes:
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    files.append(_save(fig, out / "wrenches.png"))

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
    files.append(_save(fig, out / "mode.png"))

    q_cmd = _arr(cycles, "q_cmd", 7)
    q = _arr(cycles, "q", 7)
    fig, axes = plt.subplots(7, 1, figsize=(9, 11), sharex=True)
    for j in range(7):
        axes[j].plot(t, q_cmd[:, j], label="command")
        axes[j].plot(t, q[:, j], "--", label="measured")
        axes[j].set_ylabel(f"q{j + 1} (rad)")
        axes[j].grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[0].set_title("Joint commands")
    axes[-1].set_xlabel("time (s)")
    files.append(_save(fig, out / "joint_commands.png"))

    summary = {
        "cycles": len(cycles),
        "duration_s": float(t[-1] - t[0]),
        "rcm_error_max_mm": float(1e3 * np.max([c["rcm_error"] for c in cycles])),
        "rcm_error_measured_max_mm": float(1e3 * np.nanmax(meas)) if np.isfinite(meas).any() else None,
        "compute_p50_us": float(np.percentile([c["compute_us"] for c in cycles], 50)),
        "compute_p99_us": float(np.percentile([c["compute_us"] for c in cycles], 99)),
        "events": len(events),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "events.json").write_text(json.dumps(events, indent=2))
    files += [out / "summary.json", out / "events.json"]
    return files


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def log_report_main(args: argparse.Namespace) -> int:
    """``lapwrench log-report LOG --out DIR``: plots of a run log. Returns the exit code."""
    log = Path(args.log)
    if not log.is_file():
        print(f"lapwrench log-report: no such log file: {log}")
        return 2
    try:
        files = make_report(log, args.out)
    except Exception as exc:
        print(f"lapwrench log-report: cannot read {log}: {type(exc).__name__}: {exc}")
        return 2
    for f in files:
        print(f)
    return 0


def add_log_report_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``lapwrench log-report``."""
    parser.add_argument("log", help="an MCAP run log (lapwrench run --log)")
    parser.add_argument("--out", default="log-report", help="folder for the PNG plots")
