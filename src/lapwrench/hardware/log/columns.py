"""What ``log-report`` draws of a run log's cycles, gathered one cycle at a time (:class:`CycleColumns`).

The report used to hold every cycle as the dict :func:`~lapwrench.hardware.log.reader.load_log` gives:
9.2 kB a cycle (``bench/log_report_memory.py``, 100 000 cycles like a run's: 7 joints, three wrenches, five
telemetry values), 1.8 GB for a 200 s run at 1 kHz. It needs a few numbers of each: these are kept here as
columns of 8-byte floats, 0.7 kB a cycle in the same run of the bench, and the cycles are not kept.
Every value is taken as :func:`number` reads it, so the figures are those of the cycles' dicts, value for
value (the same pixels, the same summary.json).

A value is never trusted: a field that is not a number (text, a list, an integer beyond any float)
counts as missing (NaN), a cycle without a session time (from 0 to 2^32 - 1 s, as the writer logs it:
the writer counts a record without one, and logs it at the time of the cycle before) is left out and
counted.
At most :data:`MAX_PANELS` joints, and of the cues' telemetry the first :data:`MAX_PANELS` cues and
fields, are kept (what the report plots); the names of all wrenches are kept, and of all telemetry
fields, for the report's summary.
"""

from __future__ import annotations

import math
from array import array
from typing import Any

import numpy as np

from lapwrench.hardware.log.sink import MAX_LOG_TIME_S

LARGEST = 1e100  # beyond any quantity of a run: such a value is a corrupt record, drawn as a gap
MAX_PANELS = 16  # joints, cues, wrenches and telemetry fields plotted at most
MODES = ("idle", "tracking", "handle", "handle+tracking", "handle-dominant")
SUPERVISOR = ("running", "stopping", "holding")


def number(x: object) -> float:
    """``x`` as a float if it is a real number (not a bool), else NaN (None, text, a list, an integer
    beyond any float)."""
    if isinstance(x, bool) or not isinstance(x, int | float):
        return math.nan
    try:
        return float(x)
    except OverflowError:
        return math.nan


def mapping(c: dict[str, Any], key: str) -> dict[str, Any]:
    """``c[key]`` if it is a mapping, else an empty one."""
    v = c.get(key)
    return v if isinstance(v, dict) else {}


def plottable(a: np.ndarray) -> np.ndarray:
    """``a`` with values that are not finite or beyond :data:`LARGEST` as NaN (gaps in a plot)."""
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(a) <= LARGEST, a, np.nan)


def cycle_time(c: dict[str, Any]) -> float:
    """A cycle's (or an event's) time if it is a session time, a number from 0 to
    :data:`~lapwrench.hardware.log.sink.MAX_LOG_TIME_S` (as the writer has it), else NaN."""
    t = number(c.get("t"))
    return t if 0.0 <= t <= MAX_LOG_TIME_S else math.nan


def level(value: object, names: tuple[str, ...]) -> int:
    """The index of ``value`` among ``names``; -1 for anything else (absent, unknown, not text)."""
    return names.index(value) if isinstance(value, str) and value in names else -1


class _Column:
    """One column: its values from cycle ``start`` on, one per cycle; the cycle numbers too once a cycle
    went without it (a wrench that appears late, or not in every cycle)."""

    __slots__ = ("idx", "start", "values")

    def __init__(self, start: int) -> None:
        self.start = start
        self.idx: array[int] | None = None
        self.values = array("d")

    def put(self, i: int, v: float) -> None:
        if self.idx is None:
            if i == self.start + len(self.values):
                self.values.append(v)
                return
            self.idx = array("q", range(self.start, self.start + len(self.values)))
        self.idx.append(i)
        self.values.append(v)

    def dense(self, n: int) -> np.ndarray:
        out = np.full(n, np.nan)
        values = np.frombuffer(self.values, dtype=np.float64) if self.values else np.empty(0)
        if self.idx is None:
            out[self.start : self.start + len(values)] = values
        else:
            out[np.frombuffer(self.idx, dtype=np.int64)] = values
        return out


class CycleColumns:
    """The report's numbers of every cycle with a time, gathered by :meth:`add` (see the module)."""

    def __init__(self) -> None:
        self.n = 0  # cycles kept: those with a time
        self.read = 0  # every cycle handed to add()
        self.joints = 0  # the longest joint vector (q or q_cmd) of any cycle
        self.wrenches: set[str] = set()
        self.telemetry: dict[str, list[str]] = {}  # cue -> its fields, first seen first
        self._cue_rank: dict[str, int] = {}  # cue -> its place in telemetry
        self._columns: dict[tuple[str, ...], _Column] = {}

    def _put(self, key: tuple[str, ...], value: float) -> None:
        column = self._columns.get(key)
        if column is None:
            column = self._columns[key] = _Column(self.n)
        column.put(self.n, value)

    def _vector(self, key: str, value: object, n: int) -> None:
        """The first ``n`` numbers of a list field as ``(key, j)`` columns (NaN past its end, or for all
        when it is no list)."""
        row = [number(x) for x in value[:n]] if isinstance(value, list) else []
        for j in range(n):
            self._put((key, str(j)), row[j] if j < len(row) else math.nan)

    def add(self, c: dict[str, Any]) -> None:
        """Take the numbers of one cycle (as :func:`~lapwrench.hardware.log.reader.load_log` gives it)."""
        self.read += 1
        t = cycle_time(c)
        if not math.isfinite(t):
            return
        for key in ("q", "q_cmd"):
            if isinstance(v := c.get(key), list):
                self.joints = max(self.joints, len(v))
        self._put(("t",), t)
        for key in ("rcm_error", "rcm_error_measured", "compute_us"):
            self._put((key,), number(c.get(key)))
        self._put(("mode",), level(c.get("mode"), MODES))
        self._put(("supervisor",), level(c.get("supervisor"), SUPERVISOR))
        self._put(("alarm",), float(c.get("alarm") is True))
        self._vector("ft_force", c.get("ft_force"), 3)
        self._vector("q", c.get("q"), MAX_PANELS)
        self._vector("q_cmd", c.get("q_cmd"), MAX_PANELS)
        for name, w in mapping(c, "wrenches").items():
            self.wrenches.add(name)
            self._vector(f"wrench {name}", w, 6)
        for cue, values in mapping(c, "telemetry").items():
            if cue not in self.telemetry:
                self._cue_rank[cue] = len(self.telemetry)
            known = self.telemetry.setdefault(cue, [])
            fields = values if isinstance(values, dict) else {}
            known.extend(f for f in fields if f not in known)
            if self._cue_rank[cue] < MAX_PANELS:
                for name in known[:MAX_PANELS]:
                    if name in fields:
                        self._put(("telemetry", cue, name), number(fields[name]))
        self.n += 1

    def column(self, *key: str) -> np.ndarray:
        """One column over the kept cycles, NaN where a cycle did not have it."""
        column = self._columns.get(key)
        return np.full(self.n, np.nan) if column is None else column.dense(self.n)

    def matrix(self, key: str, n: int) -> np.ndarray:
        """The first ``n`` values of a vector field (``q``, ``q_cmd``, ``ft_force``, ``wrench <name>``), one
        row per kept cycle."""
        return np.stack([self.column(key, str(j)) for j in range(n)], axis=1) if n else np.empty((self.n, 0))

    def telemetry_values(self, cue: str, name: str) -> np.ndarray:
        """One telemetry field of one cue (of the first :data:`MAX_PANELS` of each) over the kept cycles."""
        return self.column("telemetry", cue, name)
