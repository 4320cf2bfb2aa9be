"""Registered inputs: sensor readings beyond the built-in three that a cue can ask for by name.

A plugin registers an :class:`InputSpec` in the ``lapwrench.inputs`` entry-point group
(:mod:`lapwrench.plugins`) and lists its name in its cue's ``inputs``. A source of that ``kind``
(:mod:`lapwrench.sources`) then fills ``SensorFrame.extra[name]`` with a :class:`Reading`; the
validator checks it against the spec (shape, finite, range, age) like any built-in reading, and a
valid one reaches the cue as ``ctx.inputs.extra[name]``. In simulation, ``InputSpec.simulate``
builds the source's read function from the world; on a robot (``lapwrench run``), ``InputSpec.open``
starts the plugin's driver in the parent process, whose latest value reaches the 1 kHz loop through
a shared-memory slot of its own (as the tactile array's does).

Also here: the two checks every reading goes through (real numbers, a fresh stamp), shared with
:mod:`lapwrench.sensors`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeGuard

import numpy as np

from lapwrench.spatial import Vec

BUILT_IN_INPUTS = ("ft", "tactile", "instruments")
"""The inputs the core reads itself (the handle F/T, the tactile grip, the instrument detections)."""

_F64 = np.dtype(np.float64)  # compared with ==: arrays from numba's cached kernels carry an equal one of their own
MAX_INPUT_VALUES = 4096  # a registered input's reading: a shared-memory slot of at most this many doubles


def is_f64_c(x: object) -> TypeGuard[np.ndarray]:
    """``x`` is a C-contiguous float64 array: what the bound kernels take as it is (the cheap check of the fast
    paths). The dtype compared with ``==``, not ``is``: arrays from numba's cached kernels carry an equal
    float64 dtype of their own."""
    return type(x) is np.ndarray and x.dtype == _F64 and x.flags.c_contiguous


def as_f64_c(x: object) -> np.ndarray:
    """``x`` as a C-contiguous float64 array: itself when it is one (:func:`is_f64_c`), the usual case."""
    return x if is_f64_c(x) else np.ascontiguousarray(x, dtype=np.float64)


def real_array(x: object) -> np.ndarray | None:
    """``x`` as a C-contiguous float64 array if it holds real numbers (ints or floats; not strings,
    booleans, complex values or objects), else None."""
    if type(x) is np.ndarray and x.dtype == _F64 and x.flags.carray:  # C-contiguous, aligned, writeable
        return x  # the common case, checked cheaply
    try:
        a = np.asarray(x)
    except (TypeError, ValueError):  # ragged nesting, unconvertible objects
        return None
    if a.dtype.kind not in "fiu":
        return None
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.aligned else a.copy()  # the compiled checks read aligned memory


def fresh_stamp(stamp: object, now: float, max_age: float) -> bool:
    """A real, finite stamp at most ``max_age`` before ``now`` (and not after it by more than that)."""
    if type(stamp) not in (float, int) and not isinstance(stamp, np.floating | np.integer):
        return False
    try:
        stamp = float(stamp)  # type: ignore[arg-type]
    except OverflowError:  # an int beyond any float, e.g. 10**400
        return False
    return math.isfinite(stamp) and abs(now - stamp) <= max_age if math.isfinite(now) else False


@dataclass(frozen=True)
class Reading:
    """A registered input's reading: an array of numbers and its stamp (session seconds)."""

    value: Vec
    stamp: float = 0.0


@dataclass(frozen=True)
class InputSpec:
    """A named input (module docstring): what its readings must look like, and how to simulate it.

    ``shape`` is the reading's array shape; every element must be finite and inside
    [``lower``, ``upper``]; a reading older than ``max_age`` seconds is stale (the cue then sees
    None). ``simulate(world)`` returns ``read(t) -> array | None`` for the simulation, sampled every
    ``update_interval`` s and arriving ``delay`` s later; None: the input has no simulated source.
    """

    name: str
    shape: tuple[int, ...]
    lower: float = -math.inf
    upper: float = math.inf
    max_age: float = 0.1
    update_interval: float = 0.01
    delay: float = 0.0
    simulate: Callable[[Any], Callable[[float], Any]] | None = None
    open: Callable[[Any], Any] | None = None
    doc: str = ""

    def __post_init__(self) -> None:
        if not (isinstance(self.shape, tuple) and all(isinstance(n, int) and n > 0 for n in self.shape)):
            raise ValueError(f"input {self.name!r}: shape must be a tuple of positive ints, got {self.shape!r}")
        if not self.lower <= self.upper:
            raise ValueError(f"input {self.name!r}: lower must not exceed upper")
        for key in ("max_age", "update_interval"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"input {self.name!r}: {key} must be a positive number of seconds, got {value!r}")
        if not (math.isfinite(self.delay) and self.delay >= 0.0):
            raise ValueError(f"input {self.name!r}: delay must be >= 0, got {self.delay!r}")
        if math.prod(self.shape) > MAX_INPUT_VALUES:
            raise ValueError(f"input {self.name!r}: at most {MAX_INPUT_VALUES} values, got shape {self.shape}")

    def check(self, reading: object, now: float) -> tuple[Reading | None, str]:
        """The reading as a valid :class:`Reading`, or None and why it was rejected."""
        value = real_array(getattr(reading, "value", None))
        if value is None or value.shape != self.shape:
            return None, f"{self.name} reading must be real numbers of shape {self.shape}"
        if not np.isfinite(value).all():
            return None, f"{self.name} reading is not finite"
        if np.any(value < self.lower) or np.any(value > self.upper):
            return None, f"{self.name} reading outside [{self.lower:g}, {self.upper:g}]"
        stamp = getattr(reading, "stamp", None)
        if not fresh_stamp(stamp, now, self.max_age):
            return None, f"{self.name} reading older than {self.max_age:g} s"
        return (reading if value is getattr(reading, "value", None) and isinstance(reading, Reading)
                else Reading(value, float(stamp))), ""  # type: ignore[arg-type]
