"""One sensor abstraction for the virtual model, the simulation and the robot.

Every input of the controller (the handle F/T, the tactile grip array, the instrument detections)
comes from a :class:`Source` of the same shape, whatever produces it:

* :meth:`Source.poll` ``(now)`` is called once per control cycle, first. A simulated source samples
  its world there when an update is due; a hardware source has nothing to do (its driver thread or
  process publishes on its own) or drains its socket.
* :meth:`Source.latest` gives the newest reading that has *arrived*, with its stamp (session
  seconds), or None. The loop uses it only if it is at most :attr:`Source.max_age` old; an older
  one switches that cue's wrench off (and the loop reports the input as stale).

Besides the three built-in kinds (``ft``, ``tactile``, ``instruments``) a source may have the kind
of a registered input (:mod:`lapwrench.inputs`): its readings fill ``SensorFrame.extra`` under
that name. :func:`simulated_input` builds the simulated source of such an input.

Simulated sources are :class:`Observable` s, after dm_control's observables: a ``read(t)`` of the
world every ``update_interval`` seconds, which arrives ``delay`` seconds later, through an optional
``corruptor`` (noise, bias, dropout). Hardware sources are :class:`BufferSource` s over a driver's
:class:`~lapwrench.buffer.LatestValue`.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Any, Generic, Protocol, TypeVar, runtime_checkable

import numpy as np

from lapwrench.buffer import SampleBuffer
from lapwrench.inputs import BUILT_IN_INPUTS, InputSpec, Reading
from lapwrench.plugins import NAME
from lapwrench.sensors import ForceTorqueReading, InstrumentObservation, TactileReading

R = TypeVar("R", ForceTorqueReading, TactileReading, InstrumentObservation, Reading)
KINDS = BUILT_IN_INPUTS


def _check_kind(kind: object) -> str:
    if not (isinstance(kind, str) and (kind in KINDS or NAME.match(kind))):
        raise ValueError(f"source kind must be one of {KINDS} or a registered input's name, got {kind!r}")
    return kind


@runtime_checkable
class Source(Protocol):
    """A controller input: latest value, its age (from its ``stamp``) and staleness (:attr:`max_age`)."""

    kind: str  # one of KINDS: which field of the SensorFrame it fills
    max_age: float

    def poll(self, now: float) -> None: ...

    def latest(self) -> Any | None: ...


def _check_age(max_age: float, name: str) -> float:
    if not (isinstance(max_age, int | float) and math.isfinite(max_age) and max_age > 0):
        raise ValueError(f"max age of {name} must be a positive number of seconds, got {max_age!r}")
    return float(max_age)


class Observable(Generic[R]):
    """A simulated source (dm_control's observable): samples ``read(t)`` every ``update_interval`` s;
    each sample arrives ``delay`` s after it was taken, passed through ``corruptor`` if given.

    ``read`` returns a reading stamped with its own time (the time it was taken), or None when the
    sensor has nothing (a detector that found no instrument still returns an empty observation).
    """

    def __init__(
        self,
        kind: str,
        read: Callable[[float], R | None],
        *,
        update_interval: float,
        delay: float = 0.0,
        max_age: float,
        corruptor: Callable[[R, np.random.Generator], R | None] | None = None,
        seed: int = 0,
    ) -> None:
        _check_kind(kind)
        if not (math.isfinite(update_interval) and update_interval > 0):
            raise ValueError(f"update_interval must be positive, got {update_interval!r}")
        if not (math.isfinite(delay) and delay >= 0):
            raise ValueError(f"delay must be >= 0, got {delay!r}")
        self.kind = kind
        self.read: Callable[[float], R | None] = read
        self.update_interval = float(update_interval)
        self.delay = float(delay)
        self.max_age = _check_age(max_age, kind)
        self.corruptor: Callable[[R, np.random.Generator], R | None] | None = corruptor
        self.rng = np.random.default_rng(seed)
        self._next = -math.inf
        self._in_flight: deque[tuple[float, R]] = deque()
        self._latest: R | None = None

    def poll(self, now: float) -> None:
        """Take a sample if one is due (at most one per call), then deliver those that have arrived.

        Without a delay a sample arrives at once: it becomes the latest directly (nothing is ever in
        flight then), the same outcome without the queue's work at every control period."""
        if now >= self._next - 1e-12:
            self._next = (now if self._next == -math.inf else self._next) + self.update_interval
            value = self.read(now)
            if value is not None and self.corruptor is not None:
                value = self.corruptor(value, self.rng)
            if value is not None:
                if self.delay == 0.0 and not self._in_flight:
                    self._latest = value
                    return
                self._in_flight.append((now + self.delay, value))
        in_flight = self._in_flight
        while in_flight and in_flight[0][0] <= now + 1e-12:
            self._latest = in_flight.popleft()[1]

    def latest(self) -> R | None:
        return self._latest


class BufferSource(Generic[R]):
    """A hardware source: the newest sample of a driver's :class:`~lapwrench.buffer.LatestValue` (or of another
    process's slot), converted to a reading.

    ``convert(value, stamp)`` builds the reading from the driver's value and the sample's time in
    session seconds (its monotonic arrival time minus ``t0``, set by the loop when it starts).
    """

    def __init__(
        self, kind: str, buffer: SampleBuffer[Any], convert: Callable[[Any, float], R], *, max_age: float
    ) -> None:
        self.kind = _check_kind(kind)
        self.buffer = buffer
        self.convert: Callable[[Any, float], R] = convert
        self.max_age = _check_age(max_age, kind)
        self.t0 = 0.0

    def poll(self, now: float) -> None:
        """Nothing: the driver publishes on its own."""

    def latest(self) -> R | None:
        s = self.buffer.get()
        return None if s is None else self.convert(s.value, s.timestamp - self.t0)


def ft_reading(value: Any, stamp: float) -> ForceTorqueReading:
    """A driver wrench (``force``, ``torque`` in the handle frame {H}) as a reading."""
    return ForceTorqueReading(value.force, value.torque, stamp)


def tactile_reading(value: Any, stamp: float) -> TactileReading:
    """A tactile frame (``values``, 64 elements) as a reading."""
    return TactileReading(np.asarray(value.values, dtype=float), stamp)


def registered_reading(value: Any, stamp: float) -> Reading:
    """A registered input's driver value (an array) as a reading (:mod:`lapwrench.inputs`)."""
    return Reading(np.asarray(value, dtype=float), stamp)


def instruments_reading(value: Any, stamp: float) -> InstrumentObservation:
    """A detector's observation (image ``points``) stamped with its sample's time."""
    return InstrumentObservation(value.points, stamp)


def simulated_input(spec: InputSpec, world: Any, seed: int = 0) -> Observable[Reading]:
    """The simulated source of a registered input: ``spec.simulate(world)`` sampled every
    ``spec.update_interval`` s, arriving ``spec.delay`` s later (ValueError if it has none)."""
    if spec.simulate is None:
        raise ValueError(f"input {spec.name!r} has no simulated source (its InputSpec.simulate is None)")
    read = spec.simulate(world)

    def sample(t: float) -> Reading | None:
        value = read(t)
        return None if value is None else Reading(np.asarray(value, dtype=float), t)

    return Observable(spec.name, sample, update_interval=spec.update_interval, delay=spec.delay,
                      max_age=spec.max_age, seed=seed)


def fresh(source: Source, now: float) -> Any | None:
    """The source's latest reading if it is at most ``max_age`` old at ``now``.

    A stamp slightly after ``now`` (a driver thread published between the loop's clock read and this
    call) counts as fresh; one further in the future than ``max_age`` does not.
    """
    r = source.latest()
    if r is None:
        return None
    stamp = getattr(r, "stamp", math.nan)
    return r if math.isfinite(stamp) and abs(now - stamp) <= source.max_age else None
