"""``/lapwrench/cycle``: the ``lapwrench.Cycle`` protobuf message, encoded and decoded by the
``google.protobuf`` library.

The schema is built here in Python as a ``FileDescriptorProto`` (no ``.proto`` file, no generated
code): :func:`cycle_descriptor` is the ``FileDescriptorSet`` written as the channel's schema, which
Foxglove (and any protobuf library) decodes the messages with, and :func:`cycle_message_classes`
the message classes the library builds from it. Proto3: a zero, an empty string, ``False`` or an
empty repeated field is not written and reads back as such.

The schema depends on the cues a run logs telemetry for (a :data:`~.telemetry.TelemetryLayout`):
field ``telemetry`` holds one message per cue with one ``double`` per field (:mod:`.telemetry`).
Every function takes the layout (default: none) and caches what it builds for it.
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from lapwrench.hardware.log.record import CycleRecord, plain_float
from lapwrench.hardware.log.telemetry import TELEMETRY_FIELD, TelemetryLayout, add_telemetry_message

if TYPE_CHECKING:
    from google.protobuf.descriptor import Descriptor
    from google.protobuf.descriptor_pb2 import FileDescriptorProto
    from google.protobuf.message import Message

CYCLE_SCHEMA_NAME = "lapwrench.Cycle"
WRENCH_SCHEMA_NAME = "lapwrench.Wrench"
CYCLE_PROTO_FILE = "lapwrench/cycle.proto"

# (field name, field number, kind): "f" double (NaN ⇄ None), "i" int64, "b" bool, "s" string,
# "v" packed repeated double (absent or empty ⇄ None), "pts" the instrument points (packed x, y pairs
# plus ``instrument_count``, -1 = absent), "w" the wrenches (repeated lapwrench.Wrench {name, w}).
CYCLE_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("t", 1, "f"), ("robot_time", 2, "f"), ("k", 3, "i"), ("q", 4, "v"), ("dq", 5, "v"), ("tau_J", 6, "v"),
    ("external_force", 7, "v"), ("ft_force", 8, "v"), ("ft_torque", 9, "v"), ("tactile", 10, "v"),
    ("instruments", 11, "pts"), ("wrenches", 12, "w"), ("mode", 13, "s"), ("delta", 14, "f"), ("contacts", 15, "i"),
    ("p_R", 16, "v"), ("p_G", 17, "v"), ("e_R", 18, "v"), ("rcm_error", 19, "f"), ("rcm_error_measured", 20, "f"),
    ("q_ref", 21, "v"), ("q_cmd", 22, "v"), ("supervisor", 23, "s"), ("alarm", 24, "b"), ("compute_us", 25, "f"),
    ("cycle_us", 26, "f"),
)  # fmt: skip
INSTRUMENT_COUNT_FIELD = 27
TELEMETRY_FIELD_NUMBER = 28  # lapwrench.Telemetry: the cues' telemetry (.telemetry)
WRENCH_FIELDS: tuple[tuple[str, int, str], ...] = (("name", 1, "s"), ("w", 2, "v"))

_NAMES = {kind: tuple(n for n, _, k in CYCLE_FIELDS if k == kind) for kind in ("f", "i", "b", "s", "v")}


# -- the schema ------------------------------------------------------------------------------------
def cycle_file_descriptor(telemetry: TelemetryLayout = ()) -> FileDescriptorProto:
    """``lapwrench/cycle.proto`` (proto3): ``lapwrench.Cycle``, ``lapwrench.Wrench`` and the
    ``lapwrench.Telemetry`` of the cues in ``telemetry``."""
    from google.protobuf.descriptor_pb2 import FieldDescriptorProto as F
    from google.protobuf.descriptor_pb2 import FileDescriptorProto

    types = {
        "f": (F.TYPE_DOUBLE, F.LABEL_OPTIONAL), "i": (F.TYPE_INT64, F.LABEL_OPTIONAL),
        "b": (F.TYPE_BOOL, F.LABEL_OPTIONAL), "s": (F.TYPE_STRING, F.LABEL_OPTIONAL),
        "v": (F.TYPE_DOUBLE, F.LABEL_REPEATED), "pts": (F.TYPE_DOUBLE, F.LABEL_REPEATED),
        "w": (F.TYPE_MESSAGE, F.LABEL_REPEATED),
    }  # fmt: skip
    file = FileDescriptorProto(name=CYCLE_PROTO_FILE, package="lapwrench", syntax="proto3")
    cycle_fields = (*CYCLE_FIELDS, ("instrument_count", INSTRUMENT_COUNT_FIELD, "i"))
    for message, fields in (("Cycle", cycle_fields), ("Wrench", WRENCH_FIELDS)):
        proto = file.message_type.add(name=message)
        for name, number, kind in fields:
            type_, label = types[kind]
            field = proto.field.add(name=name, number=number, label=label, type=type_)
            if kind == "w":
                field.type_name = "." + WRENCH_SCHEMA_NAME
    cycle = file.message_type[0]
    cycle.field.add(name=TELEMETRY_FIELD, number=TELEMETRY_FIELD_NUMBER, label=F.LABEL_OPTIONAL, type=F.TYPE_MESSAGE,
                    type_name=add_telemetry_message(file, telemetry))
    return file


@functools.cache
def cycle_descriptor(telemetry: TelemetryLayout = ()) -> bytes:
    """The ``FileDescriptorSet`` of ``lapwrench.Cycle`` (the MCAP schema data)."""
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    return FileDescriptorSet(file=[cycle_file_descriptor(telemetry)]).SerializeToString()


def message_class(descriptor: Descriptor) -> type[Message]:
    """The library's message class of a descriptor (``GetMessageClass``, or the older factory)."""
    from google.protobuf import message_factory

    get = getattr(message_factory, "GetMessageClass", None)
    if get is not None:
        return get(descriptor)
    return message_factory.MessageFactory(descriptor.file.pool).GetPrototype(descriptor)  # protobuf < 4.22


@functools.cache
def cycle_message_classes(telemetry: TelemetryLayout = ()) -> tuple[type[Message], type[Message]]:
    """The ``lapwrench.Cycle`` and ``lapwrench.Wrench`` classes, on a descriptor pool of their own."""
    from google.protobuf import descriptor_pool

    pool = descriptor_pool.DescriptorPool()
    pool.Add(cycle_file_descriptor(telemetry))
    return (
        message_class(pool.FindMessageTypeByName(CYCLE_SCHEMA_NAME)),
        message_class(pool.FindMessageTypeByName(WRENCH_SCHEMA_NAME)),
    )


# -- encoding (the writer thread) -------------------------------------------------------------------
def _floats(x: Any) -> list[float]:
    """Any array (flattened) as a list of floats."""
    return np.asarray(x, dtype=float).ravel().tolist()


def encode_cycle(rec: CycleRecord, telemetry: TelemetryLayout = ()) -> bytes:
    """The ``lapwrench.Cycle`` protobuf bytes of a record (about 1.3 kB for the runner's record),
    with the telemetry of the cues in ``telemetry`` (a cue the record has no values for is left out)."""
    msg = cycle_message_classes(telemetry)[0]()
    for name in _NAMES["f"]:
        x = getattr(rec, name)
        setattr(msg, name, math.nan if x is None else float(x))
    for name in _NAMES["i"]:
        setattr(msg, name, int(getattr(rec, name)))
    for name in _NAMES["b"]:
        setattr(msg, name, bool(getattr(rec, name)))
    for name in _NAMES["s"]:
        setattr(msg, name, str(getattr(rec, name)))
    for name in _NAMES["v"]:
        x = getattr(rec, name)
        if x is not None:
            getattr(msg, name).extend(_floats(x))
    if rec.instruments is None:
        msg.instrument_count = -1
    else:
        points = np.asarray(rec.instruments, dtype=float)
        msg.instruments.extend(points.ravel().tolist())
        msg.instrument_count = points.shape[0] if points.ndim else 1
    for name, w in rec.wrenches.items():
        wrench = msg.wrenches.add(name=str(name))
        if w is not None:
            wrench.w.extend(_floats(w))
    if telemetry and rec.telemetry:
        _encode_telemetry(msg.telemetry, telemetry, rec.telemetry)
    return msg.SerializeToString()


def _encode_telemetry(msg: Any, layout: TelemetryLayout, values: dict[str, Any]) -> None:
    """Each cue's values into its message of ``lapwrench.Telemetry`` (set, even when all zero)."""
    for cue, fields in layout:
        v = values.get(cue)
        if v is None:
            continue
        sub = getattr(msg, cue)
        sub.SetInParent()
        for name, x in zip(fields, v, strict=False):
            setattr(sub, name, float(x))


# -- decoding (the reader) --------------------------------------------------------------------------
def _values(field: Any) -> list[float | None] | None:
    """A repeated double as a list (NaN/inf → ``None``); ``None`` when empty (absent)."""
    if not field:
        return None
    values = list(field)
    if all(map(math.isfinite, values)):
        return values
    return [v if math.isfinite(v) else None for v in values]


def _points(msg: Any) -> list[Any] | None:
    """The instrument points: ``None`` when absent (count -1), else ``instrument_count`` rows."""
    count = msg.instrument_count
    if count < 0:
        return None
    if count == 0:
        return []
    values = _values(msg.instruments) or []
    if len(values) % count:
        raise ValueError(f"{len(values)} instrument values for {count} points")
    n = len(values) // count
    return [values[i * n : (i + 1) * n] for i in range(count)]


def _telemetry(msg: Any) -> dict[str, dict[str, float | None]]:
    """The cues' telemetry of a cycle message: cue → field → value (NaN/inf → ``None``); only the
    cues the message has values for; none when its schema has no telemetry (an older log)."""
    tel = getattr(msg, TELEMETRY_FIELD, None)
    if tel is None:
        return {}
    return {
        fd.name: {f.name: plain_float(getattr(sub, f.name)) for f in fd.message_type.fields}
        for fd, sub in tel.ListFields()
    }


def decode_cycle(data: bytes, cycle_class: type[Message] | None = None) -> dict[str, Any]:
    """``lapwrench.Cycle`` bytes → the dict of :meth:`CycleRecord.to_dict`. ``cycle_class`` is the
    message class of the log's own schema (which names its cues' telemetry fields); by default
    the schema without telemetry."""
    msg = (cycle_message_classes()[0] if cycle_class is None else cycle_class).FromString(data)
    out: dict[str, Any] = {}
    for name, _, kind in CYCLE_FIELDS:
        value = getattr(msg, name)
        if kind == "f":
            out[name] = plain_float(value)
        elif kind == "i":
            out[name] = int(value)
        elif kind == "b":
            out[name] = bool(value)
        elif kind == "s":
            out[name] = str(value)
        elif kind == "v":
            out[name] = _values(value)
        elif kind == "pts":
            out[name] = _points(msg)
        else:
            out[name] = {w.name: _values(w.w) for w in value}
    out[TELEMETRY_FIELD] = _telemetry(msg)
    return out
