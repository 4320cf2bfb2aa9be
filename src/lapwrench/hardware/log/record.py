"""What the loop hands to the logger each cycle, and that record as plain values (lists, floats,
``None`` for NaN/inf and absent values): what :func:`~lapwrench.hardware.log.read_log` gives back."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from lapwrench.hardware.log.telemetry import TelemetryLayout
    from lapwrench.loop_stats import Cycle


def plain_list(x: Any) -> Any:
    """An array (any shape) as nested lists, NaN/inf as ``None``; ``None`` stays ``None``."""
    if x is None:
        return None
    a = np.asarray(x, dtype=float)
    finite = np.isfinite(a)
    if finite.all():
        return a.tolist()
    out = a.astype(object)  # Python floats, and None in place of the others
    out[~finite] = None
    return out.tolist()


def plain_float(x: Any) -> float | None:
    """A float, or ``None`` for NaN/inf/None."""
    if x is None:
        return None
    v = float(x)
    return v if math.isfinite(v) else None


@dataclass(slots=True)
class CycleRecord:
    """What the loop hands to the logger each cycle (references; serialised in the writer thread).

    ``p_G`` (the closest point, m in {B}) is optional: with it the log has the G frame and the
    null-space wrench arrows at G. ``telemetry`` is the cues' telemetry by cue name, one number per
    field (:attr:`TickResult.telemetry <lapwrench.controller.TickResult.telemetry>`).
    """

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
    p_G: Any = None
    telemetry: dict[str, Any] | None = None

    def to_dict(self, telemetry: TelemetryLayout = ()) -> dict[str, Any]:
        """The record as :func:`~lapwrench.hardware.log.read_log` gives it back (lists; NaN/inf → ``None``)
        from a log whose cycle schema names the cues' telemetry fields ``telemetry``."""
        return {
            "t": plain_float(self.t),
            "robot_time": plain_float(self.robot_time),
            "k": int(self.k),
            "q": plain_list(self.q),
            "dq": plain_list(self.dq),
            "tau_J": plain_list(self.tau_J),
            "external_force": plain_list(self.external_force),
            "ft_force": plain_list(self.ft_force),
            "ft_torque": plain_list(self.ft_torque),
            "tactile": plain_list(self.tactile),
            "instruments": plain_list(self.instruments),
            "wrenches": {str(k): plain_list(v) for k, v in self.wrenches.items()},
            "mode": str(self.mode),
            "delta": plain_float(self.delta),
            "contacts": int(self.contacts),
            "p_R": plain_list(self.p_R),
            "p_G": plain_list(self.p_G),
            "e_R": plain_list(self.e_R),
            "rcm_error": plain_float(self.rcm_error),
            "rcm_error_measured": plain_float(self.rcm_error_measured),
            "q_ref": plain_list(self.q_ref),
            "q_cmd": plain_list(self.q_cmd),
            "supervisor": str(self.supervisor),
            "alarm": bool(self.alarm),
            "compute_us": plain_float(self.compute_us),
            "cycle_us": plain_float(self.cycle_us),
            "telemetry": self.telemetry_dict(telemetry),
        }

    def telemetry_dict(self, telemetry: TelemetryLayout) -> dict[str, dict[str, float | None]]:
        """cue → field → value of the cues in ``telemetry`` the record has values for (a missing value
        reads 0, as protobuf gives back an unset field)."""
        values = self.telemetry or {}
        out = {}
        for cue, fields in telemetry:
            v = values.get(cue)
            if v is not None:
                v = list(v) + [0.0] * (len(fields) - len(v))
                out[cue] = {name: plain_float(x) for name, x in zip(fields, v, strict=False)}
        return out


def cycle_record(c: Cycle, supervisor: str, alarm: bool, tau_J: Any = None) -> CycleRecord | None:
    """The record of one loop cycle (None after a failed tick: nothing to log but its events), with the
    supervisor's state and alarm flag after it and the robot's measured joint torques if it has them.

    The loop builds one every cycle, so the fields are passed by position, in :class:`CycleRecord`'s
    order (a call with 27 keywords costs twice as much)."""
    r, frame, reading = c.result, c.frame, c.reading
    if r is None:
        return None
    ft, ta, ins = frame.ft, frame.tactile, frame.instruments
    return CycleRecord(
        frame.time, reading.stamp, c.k, reading.q, reading.dq, tau_J,  # t, robot_time, k, q, dq, tau_J
        reading.external_force, None if ft is None else ft.force, None if ft is None else ft.torque,
        None if ta is None else ta.values, None if ins is None else ins.points,  # ... tactile, instruments
        r.wrenches, r.mode, r.delta, r.contacts, r.p_R, r.e_R, r.rcm_error,  # wrenches ... rcm_error
        c.scope.rcm_error, r.q_ref, c.q_cmd, supervisor, alarm,  # rcm_error_measured ... alarm
        c.compute * 1e6, c.period * 1e6, r.p_G, r.telemetry,  # compute_us, cycle_us, p_G, telemetry
    )
