"""Reading a run log back: every message decoded (JSON parsed, the cycles by
:func:`~lapwrench.hardware.log.cycle_codec.decode_cycle`, Foxglove's protobuf messages as dicts
through the schemas in the file), and a plain :class:`LogFileError` for a missing, truncated or
corrupt file. Logs of the JSON-only logger (cycles in JSON) read the same way."""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lapwrench.hardware.log.cycle_codec import CYCLE_SCHEMA_NAME, decode_cycle, message_class
from lapwrench.hardware.log.topics import CYCLE_TOPIC, EVENT_TOPIC, META_TOPIC, STATS_TOPIC

_MCAP_MAGIC = b"\x89MCAP0\r\n"


class LogFileError(ValueError):
    """A run log that cannot be read (missing, truncated, not MCAP, corrupt)."""


def check_log_file(path: str | Path) -> Path:
    """``path`` if it is a complete MCAP file (magic at both ends), else :class:`LogFileError`."""
    p = Path(path)
    if not p.is_file():
        raise LogFileError(f"{p}: no such log file")
    size = p.stat().st_size
    with p.open("rb") as f:
        head = f.read(len(_MCAP_MAGIC))
        f.seek(max(0, size - len(_MCAP_MAGIC)))
        tail = f.read()
    if head != _MCAP_MAGIC:
        raise LogFileError(f"{p}: not an MCAP file")
    if size < 2 * len(_MCAP_MAGIC) or tail != _MCAP_MAGIC:
        raise LogFileError(f"{p}: truncated MCAP file ({size} bytes, no footer): the run did not close its log")
    return p


class _Decoder:
    """Message bytes → Python: JSON parsed, ``lapwrench.Cycle`` by :func:`decode_cycle`, other
    protobuf messages as dicts through the schema's ``FileDescriptorSet``; anything else as bytes."""

    def __init__(self) -> None:
        self._classes: dict[int, Any] = {}
        self._pool: Any = None
        self._files: set[str] = set()

    def decode(self, schema: Any, encoding: str, data: bytes) -> Any:
        """One message's data, by its channel's encoding and schema."""
        if encoding == "json":
            return json.loads(data)
        if encoding == "protobuf" and schema is not None and schema.name == CYCLE_SCHEMA_NAME:
            return decode_cycle(data)
        if encoding == "protobuf" and schema is not None:
            return _message_dict(self._message_class(schema).FromString(data))
        return data

    def _message_class(self, schema: Any) -> Any:
        if schema.id not in self._classes:
            self._classes[schema.id] = self._build(schema)
        return self._classes[schema.id]

    def _build(self, schema: Any) -> Any:
        """The message class of a protobuf schema, on the decoder's descriptor pool."""
        from google.protobuf import descriptor_pb2, descriptor_pool

        if self._pool is None:
            self._pool = descriptor_pool.DescriptorPool()
        for fd in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
            if fd.name not in self._files:
                self._pool.Add(fd)
                self._files.add(fd.name)
        return message_class(self._pool.FindMessageTypeByName(schema.name))


def _message_dict(msg: Any) -> dict[str, Any]:
    """A protobuf message as a dict with the proto field names, zeros included where possible."""
    from google.protobuf.json_format import MessageToDict

    try:
        return MessageToDict(msg, preserving_proto_field_name=True, always_print_fields_with_no_presence=True)
    except TypeError:  # protobuf < 5.26
        return MessageToDict(msg, preserving_proto_field_name=True)


def iter_messages(path: str | Path, topics: Iterable[str] | None = None) -> Iterator[tuple[str, Any]]:
    """(topic, decoded message) for every message (of ``topics``, if given), in log-time order.

    JSON messages come as parsed JSON, the cycles as :meth:`CycleRecord.to_dict` dicts,
    Foxglove's protobuf messages as dicts (bytes fields in base64).
    Raises :class:`LogFileError` for a missing, truncated or corrupt file.
    """
    from mcap.reader import make_reader

    p = check_log_file(path)
    decoder = _Decoder()
    try:
        with p.open("rb") as f:
            reader = make_reader(f)
            for schema, channel, message in reader.iter_messages(
                topics=None if topics is None else list(topics), log_time_order=True
            ):
                yield channel.topic, decoder.decode(schema, channel.message_encoding, message.data)
    except Exception as exc:  # mcap, zstd/lz4, protobuf, JSON: the file's content is bad
        raise LogFileError(f"{p}: corrupt MCAP file ({type(exc).__name__}: {exc})") from exc


@dataclass
class TopicInfo:
    """One channel of a log: its schema name, message encoding and message count."""

    schema: str
    encoding: str
    messages: int


@dataclass
class LogContents:
    """A run log read back: the custom messages as dicts, the stats and the topics."""

    cycles: list[dict[str, Any]] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    meta: dict[str, Any] | None = None
    stats: dict[str, Any] | None = None
    topics: dict[str, TopicInfo] = field(default_factory=dict)


def log_topics(path: str | Path) -> dict[str, TopicInfo]:
    """Topic → :class:`TopicInfo`, from the MCAP summary section."""
    from mcap.reader import make_reader

    p = check_log_file(path)
    try:
        with p.open("rb") as f:
            summary = make_reader(f).get_summary()
    except Exception as exc:  # mcap, struct: the summary section is bad
        raise LogFileError(f"{p}: corrupt MCAP summary ({type(exc).__name__}: {exc})") from exc
    if summary is None:
        raise LogFileError(f"{p}: MCAP file without a summary section")
    counts = summary.statistics.channel_message_counts if summary.statistics is not None else {}
    out = {}
    for cid, ch in summary.channels.items():
        schema = summary.schemas.get(ch.schema_id)
        out[ch.topic] = TopicInfo(schema.name if schema else "", ch.message_encoding, counts.get(cid, 0))
    return out


def load_log(path: str | Path) -> LogContents:
    """The cycles, events, meta and stats of a run log, and its topics."""
    out = LogContents(topics=log_topics(path))
    for topic, data in iter_messages(path, (CYCLE_TOPIC, EVENT_TOPIC, META_TOPIC, STATS_TOPIC)):
        if topic == CYCLE_TOPIC:
            out.cycles.append(data)
        elif topic == EVENT_TOPIC:
            out.events.append(data)
        elif topic == META_TOPIC:
            out.meta = data
        else:
            out.stats = data
    return out


def read_log(path: str | Path) -> tuple[list[dict[str, Any]], list[dict[str, Any]], dict[str, Any] | None]:
    """(cycles, events, meta) of an MCAP run log."""
    c = load_log(path)
    return c.cycles, c.events, c.meta
