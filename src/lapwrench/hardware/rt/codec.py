"""Cycle records as fixed float64 rows (:class:`CycleCodec`) and the child's logger writing them,
with its events, into the bus's bounded rings (:class:`ShmLogSink`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np

from lapwrench.config_cues import MAX_TELEMETRY
from lapwrench.hardware.log import CycleRecord
from lapwrench.hardware.rt.sizes import MAX_POINTS, TACTILE_N
from lapwrench.hardware.shm import Ring, pack_event
from lapwrench.robot.description import MAX_JOINTS

_WRENCH_SLOT = 1 + 6
"""Places per wrench in a row: the interned name, then the 6-vector [moment; force]."""
_N_WRENCH = 8
_TELEMETRY_PLACES = 2 * _N_WRENCH + MAX_TELEMETRY + 1
"""Places for the cues' telemetry in a row: per cue its interned name, its value count and the values,
then -2 (the end); room for every cue's header and all the telemetry values the configuration allows."""


class CycleCodec:
    """Packs a :class:`~lapwrench.hardware.log.CycleRecord` into one float64 row and back.

    Optional vectors carry a presence flag (``None`` stays ``None``; NaN stays NaN). Strings (mode,
    supervisor state, wrench names) are interned: a new string is announced once on the event ring
    (kind ``__intern__``) before the first row that uses it.

    The row has a fixed width (a ring slot), so each joint vector (q, dq, tau_J, q_ref, q_cmd) has
    :data:`~lapwrench.robot.description.MAX_JOINTS` places; the row records the arm's actual joint
    count (``n_joints``, from the record's q) and only that many values are written and read back.

    The cues' telemetry (``record.telemetry``, cue name → values) follows, cue by cue (its name
    interned like the wrenches'); what passes the row's room (the configuration's bounds,
    :data:`~lapwrench.config_cues.MAX_TELEMETRY`) is cut.
    """

    N_WRENCH = _N_WRENCH
    _spec: tuple[tuple[str, str, int], ...] = (
        ("t", "f", 1), ("robot_time", "f", 1), ("k", "f", 1), ("n_joints", "f", 1), ("q", "v", MAX_JOINTS),
        ("dq", "v", MAX_JOINTS), ("tau_J", "o", MAX_JOINTS), ("external_force", "o", 3), ("ft_force", "o", 3),
        ("ft_torque", "o", 3), ("tactile", "o", TACTILE_N), ("instruments", "p", MAX_POINTS),
        ("wrenches", "w", N_WRENCH), ("mode", "s", 1), ("delta", "f", 1), ("contacts", "f", 1), ("p_R", "v", 3),
        ("e_R", "v", 3), ("rcm_error", "f", 1), ("rcm_error_measured", "n", 1), ("q_ref", "v", MAX_JOINTS),
        ("q_cmd", "v", MAX_JOINTS), ("supervisor", "s", 1), ("alarm", "f", 1), ("compute_us", "f", 1),
        ("cycle_us", "f", 1), ("telemetry", "t", _TELEMETRY_PLACES),
    )
    OFF: ClassVar[dict[str, int]] = {}
    WIDTH = 0

    @classmethod
    def _build(cls) -> None:
        o = 0
        for name, kind, n in cls._spec:
            cls.OFF[name] = o
            o += {"f": 1, "v": n, "o": 1 + n, "p": 1 + 2 * n, "w": _WRENCH_SLOT * n, "s": 1, "n": 2, "t": n}[kind]
        cls.WIDTH = o

    def __init__(self, announce: Callable[[str, str], bool] | None = None) -> None:
        self.announce = announce
        self.tables: dict[str, list[str]] = {"mode": [], "supervisor": [], "wrench": []}
        self._index: dict[str, dict[str, int]] = {"mode": {}, "supervisor": {}, "wrench": {}}

    def intern(self, table: str, s: str) -> int:
        idx = self._index[table]
        i = idx.get(s)
        if i is None:
            if self.announce is not None and not self.announce(table, s):
                return -1  # not announced (event ring full): "?" in this row, announced again next time
            i = idx[s] = len(self.tables[table])
            self.tables[table].append(s)
        return i

    def learn(self, message: str) -> None:
        """Apply an ``__intern__`` announcement (``table:name``) on the decoding side."""
        table, _, name = message.partition(":")
        if table in self.tables and name not in self._index[table]:
            self._index[table][name] = len(self.tables[table])
            self.tables[table].append(name)

    def encode(self, row: np.ndarray, r: CycleRecord) -> None:
        off = self.OFF
        nj = len(r.q)
        if nj > MAX_JOINTS:
            raise ValueError(f"a cycle row holds at most {MAX_JOINTS} joints, the record has {nj}")
        row[0] = r.t
        row[1] = r.robot_time
        row[2] = r.k
        row[off["n_joints"]] = nj
        row[off["q"] : off["q"] + nj] = r.q
        row[off["dq"] : off["dq"] + nj] = r.dq
        optional = (("tau_J", nj), ("external_force", 3), ("ft_force", 3), ("ft_torque", 3), ("tactile", TACTILE_N))
        for name, n in optional:
            o = off[name]
            v = getattr(r, name)
            if v is None:
                row[o] = 0.0
            else:
                row[o] = 1.0
                row[o + 1 : o + 1 + n] = v
        o = off["instruments"]
        if r.instruments is None:
            row[o] = -1.0
        else:
            pts = np.asarray(r.instruments, dtype=float).reshape(-1, 2)[:MAX_POINTS]
            row[o] = len(pts)
            row[o + 1 : o + 1 + 2 * len(pts)] = pts.ravel()
        o = off["wrenches"]
        row[o : o + _WRENCH_SLOT * self.N_WRENCH : _WRENCH_SLOT] = -2.0
        for i, (name, w) in enumerate(list(r.wrenches.items())[: self.N_WRENCH]):
            s = o + _WRENCH_SLOT * i
            row[s] = self.intern("wrench", name)
            row[s + 1 : s + _WRENCH_SLOT] = w
        row[off["mode"]] = self.intern("mode", r.mode)
        row[off["delta"]] = r.delta
        row[off["contacts"]] = r.contacts
        row[off["p_R"] : off["p_R"] + 3] = r.p_R
        row[off["e_R"] : off["e_R"] + 3] = r.e_R
        row[off["rcm_error"]] = r.rcm_error
        o = off["rcm_error_measured"]
        row[o] = 0.0 if r.rcm_error_measured is None else 1.0
        row[o + 1] = math.nan if r.rcm_error_measured is None else r.rcm_error_measured
        row[off["q_ref"] : off["q_ref"] + nj] = r.q_ref
        row[off["q_cmd"] : off["q_cmd"] + nj] = r.q_cmd
        row[off["supervisor"]] = self.intern("supervisor", r.supervisor)
        row[off["alarm"]] = 1.0 if r.alarm else 0.0
        row[off["compute_us"]] = r.compute_us
        row[off["cycle_us"]] = r.cycle_us
        self._encode_telemetry(row, r.telemetry)

    def _encode_telemetry(self, row: np.ndarray, telemetry: dict[str, Any] | None) -> None:
        """Each cue's name, value count and values, then the end mark (-2); cut at the row's room."""
        o = self.OFF["telemetry"]
        end = o + _TELEMETRY_PLACES - 1  # the last place is kept for the end mark
        for name, values in (telemetry or {}).items():
            n = len(values)
            if o + 2 + n > end:
                break
            row[o] = self.intern("wrench", name)
            row[o + 1] = n
            row[o + 2 : o + 2 + n] = values
            o += 2 + n
        row[o] = -2.0

    def _decode_telemetry(self, row: np.ndarray) -> dict[str, tuple[float, ...]]:
        o = self.OFF["telemetry"]
        end = o + _TELEMETRY_PLACES - 1
        out = {}
        while o < end and row[o] >= -1:
            n = min(int(row[o + 1]), end - o - 2)
            out[self._name("wrench", row[o])] = tuple(row[o + 2 : o + 2 + n].tolist())
            o += 2 + n
        return out

    def _name(self, table: str, x: float) -> str:
        t = self.tables[table]
        i = int(x)
        return t[i] if 0 <= i < len(t) else "?"

    def decode(self, row: np.ndarray) -> CycleRecord:
        off = self.OFF
        nj = int(row[off["n_joints"]])

        def opt(name: str, n: int) -> np.ndarray | None:
            o = off[name]
            return row[o + 1 : o + 1 + n].copy() if row[o] == 1.0 else None

        o = off["instruments"]
        n = int(row[o])
        inst = None if n < 0 else row[o + 1 : o + 1 + 2 * n].reshape(n, 2).copy()
        o = off["wrenches"]
        slots = (o + _WRENCH_SLOT * i for i in range(self.N_WRENCH))
        wr = {self._name("wrench", row[s]): row[s + 1 : s + _WRENCH_SLOT].copy() for s in slots if row[s] >= -1}
        om = off["rcm_error_measured"]
        return CycleRecord(
            t=float(row[0]),
            robot_time=float(row[1]),
            k=int(row[2]),
            q=row[off["q"] : off["q"] + nj].copy(),
            dq=row[off["dq"] : off["dq"] + nj].copy(),
            tau_J=opt("tau_J", nj),
            external_force=opt("external_force", 3),
            ft_force=opt("ft_force", 3),
            ft_torque=opt("ft_torque", 3),
            tactile=opt("tactile", TACTILE_N),
            instruments=inst,
            wrenches=wr,
            mode=self._name("mode", row[off["mode"]]),
            delta=float(row[off["delta"]]),
            contacts=int(row[off["contacts"]]),
            p_R=row[off["p_R"] : off["p_R"] + 3].copy(),
            e_R=row[off["e_R"] : off["e_R"] + 3].copy(),
            rcm_error=float(row[off["rcm_error"]]),
            rcm_error_measured=float(row[om + 1]) if row[om] == 1.0 else None,
            q_ref=row[off["q_ref"] : off["q_ref"] + nj].copy(),
            q_cmd=row[off["q_cmd"] : off["q_cmd"] + nj].copy(),
            supervisor=self._name("supervisor", row[off["supervisor"]]),
            alarm=bool(row[off["alarm"]]),
            compute_us=float(row[off["compute_us"]]),
            cycle_us=float(row[off["cycle_us"]]),
            telemetry=self._decode_telemetry(row),
        )


CycleCodec._build()
INTERN = "__intern__"


class ShmLogSink:
    """The child's logger (duck-typed :class:`~lapwrench.hardware.log.RunLogger`): rows into the
    bounded rings, never blocking; a full ring or a record that does not encode is counted."""

    def __init__(self, log: Ring, events: Ring, *, cycles: bool = True) -> None:
        self.log, self.events = log, events
        self.cycles = cycles
        self.codec = CycleCodec(self._announce)
        self.encode_errors = 0

    @property
    def logs_cycles(self) -> bool:
        """False when it takes events only (a run without ``--log``): the loop then builds no cycle records."""
        return self.cycles

    def _announce(self, table: str, name: str) -> bool:
        return self.event(0.0, INTERN, f"{table}:{name}")

    def cycle(self, record: CycleRecord) -> None:
        if not self.cycles:
            return
        row = self.log.reserve()
        if row is None:
            return
        try:
            self.codec.encode(row, record)
        except Exception:  # a record of an unexpected shape: dropped, counted, never raised
            self.encode_errors += 1
            return
        self.log.commit()

    def event(self, time: float, kind: str, message: str) -> bool:
        row = self.events.reserve()
        if row is None:
            return False
        pack_event(row, time, kind, message)
        self.events.commit()
        return True
