"""Cycle records as fixed float64 rows (:class:`CycleCodec`) and the child's logger writing them,
with its events, into the bus's bounded rings (:class:`ShmLogSink`)."""

from __future__ import annotations

import math
import struct
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


def _row_offsets(spec: tuple[tuple[str, str, int], ...]) -> tuple[dict[str, int], int]:
    """Where each field of ``spec`` (name, kind, count) starts in a row, and the row's width: a plain
    value ("f") takes one place, a vector ("v") its count, an optional vector ("o") a presence flag and its
    count, the points ("p") their number (-1 = absent) and two places each, the wrenches ("w") a
    :data:`_WRENCH_SLOT` each, an interned string ("s") one, an optional value ("n") a flag and the value,
    the telemetry ("t") its places."""
    off, o = {}, 0
    for name, kind, n in spec:
        off[name] = o
        o += {"f": 1, "v": n, "o": 1 + n, "p": 1 + 2 * n, "w": _WRENCH_SLOT * n, "s": 1, "n": 2, "t": n}[kind]
    return off, o


_SPEC: tuple[tuple[str, str, int], ...] = (
    ("t", "f", 1), ("robot_time", "f", 1), ("k", "f", 1), ("n_joints", "f", 1), ("mode", "s", 1), ("delta", "f", 1),
    ("contacts", "f", 1), ("rcm_error", "f", 1), ("rcm_error_measured", "n", 1), ("supervisor", "s", 1),
    ("alarm", "f", 1), ("compute_us", "f", 1), ("cycle_us", "f", 1),
    ("q", "v", MAX_JOINTS), ("dq", "v", MAX_JOINTS), ("tau_J", "o", MAX_JOINTS), ("external_force", "o", 3),
    ("ft_force", "o", 3), ("ft_torque", "o", 3), ("tactile", "o", TACTILE_N), ("instruments", "p", MAX_POINTS),
    ("wrenches", "w", _N_WRENCH), ("p_R", "v", 3), ("e_R", "v", 3), ("q_ref", "v", MAX_JOINTS),
    ("q_cmd", "v", MAX_JOINTS), ("telemetry", "t", _TELEMETRY_PLACES),
)  # fmt: skip
"""The fields of a cycle row, in order (name, kind, places: :func:`_row_offsets`). The plain values come
first, in one block that :meth:`CycleCodec.encode` writes in one call (:func:`_put_values`); the layout
is the bus's only (parent and child are the same version), never on disk."""
_OFF, _WIDTH = _row_offsets(_SPEC)
_HEAD = _OFF["q"]
"""Places of the plain values' block at the start of a row (t ... cycle_us)."""
# the offsets the encoder uses every cycle, as module constants (a dict lookup each costs more)
_Q, _DQ, _TAU_J, _EXTERNAL_FORCE, _FT_FORCE, _FT_TORQUE, _TACTILE, _INSTRUMENTS, _WRENCHES = (
    _OFF[n] for n in ("q", "dq", "tau_J", "external_force", "ft_force", "ft_torque", "tactile", "instruments",
                      "wrenches")
)
_P_R, _E_R, _Q_REF, _Q_CMD, _TELEMETRY = (_OFF[n] for n in ("p_R", "e_R", "q_ref", "q_cmd", "telemetry"))
_DOUBLES = tuple(struct.Struct(f"{n}d") for n in range(max(_HEAD, _TELEMETRY_PLACES) + 1))
"""``_DOUBLES[n]`` packs n native float64 values (:func:`_put_values`)."""


def _put_values(view: memoryview[float], row: np.ndarray, o: int, values: tuple[Any, ...]) -> None:
    """Plain values (floats, ints, bools) into ``row[o : o + len(values)]`` (``view`` is ``memoryview(row)``).

    One ``struct`` call packs them all as float64, a fraction of what a numpy item assignment costs
    each. What it does not take as a number (``None``, a string) goes through numpy, which converts it
    as it always did (``None`` is NaN); what numpy refuses raises. The same values either way."""
    try:
        _DOUBLES[len(values)].pack_into(view, 8 * o, *values)
    except (struct.error, TypeError, ValueError, OverflowError):
        row[o : o + len(values)] = values


def _put_vector(view: memoryview[float], row: np.ndarray, o: int, n: int, v: Any) -> None:
    """``v``'s ``n`` values into ``row[o : o + n]`` (``view`` is ``memoryview(row)``).

    What the loop hands over is a float64 array: the memoryview copies it as it is, in a third to a half
    of the time numpy's item assignment takes. Anything else (a list, another dtype, a shape numpy broadcasts)
    is refused by the memoryview before it writes anything and goes through numpy, which converts it as
    it always did; what numpy refuses raises. The same values in the row either way."""
    try:
        view[o : o + n] = v
    except (TypeError, ValueError, NotImplementedError):
        row[o : o + n] = v


def _put_optional(view: memoryview[float], row: np.ndarray, o: int, n: int, v: Any) -> None:
    """An optional vector at ``o``: its presence flag (0 for ``None``, which writes nothing else, 1), then its
    ``n`` values (:func:`_put_vector`)."""
    if v is None:
        view[o] = 0.0
    else:
        view[o] = 1.0
        _put_vector(view, row, o + 1, n, v)


def _put_points(view: memoryview[float], row: np.ndarray, o: int, points: Any) -> None:
    """The instrument points at ``o``: their number (-1 for ``None``), then x, y of each (the values in
    order, whatever the shape); at most :data:`~lapwrench.hardware.rt.sizes.MAX_POINTS`, the first ones."""
    if points is None:
        view[o] = -1.0
        return
    flat = (points if isinstance(points, np.ndarray) else np.asarray(points, dtype=float)).reshape(-1)
    n = len(flat)
    if n % 2:
        raise ValueError(f"instrument points need an x and a y each, got {n} values")
    if n > 2 * MAX_POINTS:
        flat, n = flat[: 2 * MAX_POINTS], 2 * MAX_POINTS
    view[o] = n // 2
    _put_vector(view, row, o + 1, n, flat)


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
    OFF: ClassVar[dict[str, int]] = _OFF
    WIDTH = _WIDTH

    def __init__(self, announce: Callable[[str, str], bool] | None = None) -> None:
        self.announce = announce
        self.tables: dict[str, list[str]] = {"mode": [], "supervisor": [], "wrench": []}
        self._index: dict[str, dict[str, int]] = {"mode": {}, "supervisor": {}, "wrench": {}}
        self._modes, self._states, self._names = (self._index[t] for t in ("mode", "supervisor", "wrench"))

    def intern(self, table: str, s: str) -> int:
        """The number of ``s`` in ``table``; a new string is announced first (-1 when it cannot be: the
        row then reads "?" and the next row tries again)."""
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
        """``r`` into ``row`` (float64, :attr:`WIDTH` places, C-contiguous: a ring slot); raises on a
        record of an unexpected shape.

        The real-time child runs this every cycle, so it costs the loop as little as it can: the plain
        values go in one call (:func:`_put_values`), the vectors through the row's memoryview
        (:func:`_put_vector`), the offsets are module constants, and a name already interned is found
        in the index without a call to :meth:`intern`."""
        nj = len(r.q)
        if nj > MAX_JOINTS:
            raise ValueError(f"a cycle row holds at most {MAX_JOINTS} joints, the record has {nj}")
        # a view of float64 places; numpy's stubs give arrays the buffer protocol only from Python 3.12 on
        view: memoryview[float] = memoryview(row)  # type: ignore[arg-type]
        self._encode_wrenches(view, row, r.wrenches)  # before the telemetry: their names share a table
        mode, state, measured = self._modes.get(r.mode), self._states.get(r.supervisor), r.rcm_error_measured
        _put_values(view, row, 0, (
            r.t, r.robot_time, r.k, nj, self.intern("mode", r.mode) if mode is None else mode, r.delta, r.contacts,
            r.rcm_error, 0.0 if measured is None else 1.0, math.nan if measured is None else measured,
            self.intern("supervisor", r.supervisor) if state is None else state, 1.0 if r.alarm else 0.0,
            r.compute_us, r.cycle_us,
        ))  # fmt: skip
        _put_vector(view, row, _Q, nj, r.q)
        _put_vector(view, row, _DQ, nj, r.dq)
        _put_optional(view, row, _TAU_J, nj, r.tau_J)
        _put_optional(view, row, _EXTERNAL_FORCE, 3, r.external_force)
        _put_optional(view, row, _FT_FORCE, 3, r.ft_force)
        _put_optional(view, row, _FT_TORQUE, 3, r.ft_torque)
        _put_optional(view, row, _TACTILE, TACTILE_N, r.tactile)
        _put_points(view, row, _INSTRUMENTS, r.instruments)
        _put_vector(view, row, _P_R, 3, r.p_R)
        _put_vector(view, row, _E_R, 3, r.e_R)
        _put_vector(view, row, _Q_REF, nj, r.q_ref)
        _put_vector(view, row, _Q_CMD, nj, r.q_cmd)
        self._encode_telemetry(view, row, r.telemetry)

    def _encode_wrenches(self, view: memoryview[float], row: np.ndarray, wrenches: dict[str, Any]) -> None:
        """The first :attr:`N_WRENCH` wrenches, each its interned name and 6 values; -2 (none) in the
        name of every slot left."""
        names = self._names
        s, end = _WRENCHES, _WRENCHES + _WRENCH_SLOT * _N_WRENCH
        for name, w in wrenches.items():
            if s == end:
                break
            i = names.get(name)
            view[s] = self.intern("wrench", name) if i is None else i
            _put_vector(view, row, s + 1, _WRENCH_SLOT - 1, w)
            s += _WRENCH_SLOT
        for free in range(s, end, _WRENCH_SLOT):
            view[free] = -2.0

    def _encode_telemetry(self, view: memoryview[float], row: np.ndarray, telemetry: dict[str, Any] | None) -> None:
        """Each cue's interned name, value count and values (:func:`_put_values`), then the end mark (-2);
        cut at the row's room."""
        names = self._names
        o = _TELEMETRY
        end = o + _TELEMETRY_PLACES - 1  # the last place is kept for the end mark
        for name, values in (telemetry or {}).items():
            n = len(values)
            if o + 2 + n > end:
                break
            i = names.get(name)
            _put_values(view, row, o, (self.intern("wrench", name) if i is None else i, n, *values))
            o += 2 + n
        view[o] = -2.0

    def _decode_telemetry(self, row: np.ndarray) -> dict[str, tuple[float, ...]]:
        o = _TELEMETRY
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
