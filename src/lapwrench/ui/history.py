"""The scrolling window of the page's plots: a fixed number of the latest samples per signal.

The sim thread appends a sample every few ticks; the page thread reads copies. Signals appear by
name as they come (one per cue: ``|W| <cue>``), so a configuration with other cues plots them too.
"""

from __future__ import annotations

import threading

import numpy as np

MODES = ("idle", "tracking", "handle", "handle+tracking", "handle-dominant")
"""The controller's modes in the order of the mode timeline's y axis (0-4)."""


def mode_index(mode: str) -> float:
    """A mode's row in the timeline: 0-4 in :data:`MODES` order, -1 while the supervisor holds the arm
    (``"held"``), NaN for an unknown mode."""
    if mode == "held":
        return -1.0
    return float(MODES.index(mode)) if mode in MODES else float("nan")


class History:
    """Ring buffers of ``capacity`` samples: a time column and named signals."""

    def __init__(self, capacity: int = 500) -> None:
        if capacity < 2:
            raise ValueError(f"capacity must be at least 2 samples, got {capacity}")
        self.capacity = capacity
        self._lock = threading.Lock()
        self._t = np.full(capacity, np.nan)
        self._cols: dict[str, np.ndarray] = {}
        self._n = 0  # samples written in total
        self.version = 0  # bumped on every append, so readers can tell new data

    def append(self, t: float, values: dict[str, float]) -> None:
        """One sample at time ``t`` (s); a signal missing from ``values`` is NaN there."""
        with self._lock:
            i = self._n % self.capacity
            self._t[i] = t
            for name, v in values.items():
                col = self._cols.get(name)
                if col is None:
                    col = self._cols[name] = np.full(self.capacity, np.nan)
                col[i] = v
            for name, col in self._cols.items():
                if name not in values:
                    col[i] = np.nan
            self._n += 1
            self.version += 1

    def clear(self) -> None:
        with self._lock:
            self._t[:] = np.nan
            self._cols.clear()
            self._n = 0
            self.version += 1

    def __len__(self) -> int:
        return min(self._n, self.capacity)

    def names(self) -> list[str]:
        with self._lock:
            return list(self._cols)

    def window(self, names: list[str] | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(times, {name: values}) oldest first: copies, safe to hand to another thread."""
        with self._lock:
            n = min(self._n, self.capacity)
            start = self._n % self.capacity if self._n > self.capacity else 0
            order = (np.arange(n) + start) % self.capacity
            empty = np.full(self.capacity, np.nan)
            cols = self._cols if names is None else {k: self._cols.get(k, empty) for k in names}
            return self._t[order].copy(), {k: v[order].copy() for k, v in cols.items()}
