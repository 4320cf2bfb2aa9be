"""Reading a run log back: every message decoded (JSON parsed, the cycles by
:func:`~lapwrench.hardware.log.cycle_codec.decode_cycle`, Foxglove's protobuf messages as dicts
through the schemas in the file), and a plain :class:`LogFileError` for a missing, corrupt or
foreign file. Logs of the JSON-only logger (cycles in JSON) read the same way.

A complete file is read through its summary (mcap's seeking reader). A truncated one (no closing
magic: the run was killed, the machine lost power, the disk filled) is refused by default; with
``allow_truncated`` it is read from the front by mcap's non-seeking stream reader, record by
record, up to the last complete one: a chunk counts only when read whole with a matching CRC, so
the writer's last, unfinished chunk (up to ~1 MB, under a second of cycles) is lost and nothing
half-written is returned. :class:`Truncation` says where it stopped."""

from __future__ import annotations

import json
import stat
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lapwrench.hardware.log.cycle_codec import CYCLE_SCHEMA_NAME, decode_cycle, message_class
from lapwrench.hardware.log.topics import CYCLE_TOPIC, EVENT_TOPIC, META_TOPIC, STATS_TOPIC

_MCAP_MAGIC = b"\x89MCAP0\r\n"


class LogFileError(ValueError):
    """A run log that cannot be read (missing, not a file, empty, not MCAP, corrupt, or truncated
    where a complete file is required)."""


@dataclass(frozen=True)
class Truncation:
    """Where a truncated log (no closing magic: the run did not close it) stops.

    ``size``: bytes in the file; ``complete``: bytes up to the end of the last complete record
    (what was read); ``missing``: what the file lacks, e.g. ``"no summary/footer"``.
    """

    size: int
    complete: int
    missing: str


def _log_file_size(p: Path) -> int:
    """The size of an MCAP file that starts with the magic, else :class:`LogFileError`. Only a regular
    file is opened: a FIFO would block the read until a writer came, a device (``/dev/zero``) has no end."""
    try:
        st = p.stat()
    except FileNotFoundError:
        raise LogFileError(f"{p}: no such log file") from None
    except OSError as exc:  # a name too long, a symbolic link loop, a folder without permission
        raise LogFileError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    if stat.S_ISDIR(st.st_mode):
        raise LogFileError(f"{p}: is a directory, not a log file")
    if not stat.S_ISREG(st.st_mode):
        raise LogFileError(f"{p}: not a regular file (a pipe, socket or device), not a log file")
    try:
        with p.open("rb") as f:
            head = f.read(len(_MCAP_MAGIC))
    except OSError as exc:
        raise LogFileError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    size = st.st_size
    if size == 0:
        raise LogFileError(f"{p}: empty file (0 bytes), not an MCAP log")
    if not _MCAP_MAGIC.startswith(head):
        raise LogFileError(f"{p}: not an MCAP file")
    if len(head) < len(_MCAP_MAGIC):
        raise LogFileError(f"{p}: truncated MCAP file ({size} bytes, cut inside the magic)")
    return size


def _is_complete(p: Path, size: int) -> bool:
    """Closing magic at the end (the writer finished the file)."""
    if size < 2 * len(_MCAP_MAGIC):
        return False
    with p.open("rb") as f:
        f.seek(size - len(_MCAP_MAGIC))
        return f.read() == _MCAP_MAGIC


def check_log_file(path: str | Path, *, allow_truncated: bool = False) -> Path:
    """``path`` if it is an MCAP file, else :class:`LogFileError`. A truncated one (no closing
    magic) is refused unless ``allow_truncated`` (then :func:`load_log` reads it as far as it goes)."""
    if str(path) == "":  # Path("") is the current folder
        raise LogFileError("no log file given (an empty path)")
    p = Path(path)
    size = _log_file_size(p)
    if not allow_truncated and not _is_complete(p, size):
        raise LogFileError(
            f"{p}: truncated MCAP file ({size} bytes, no footer): the run did not close its log"
            " (lapwrench log-report reads it as far as it goes)"
        )
    return p


class _TruncatedError(Exception):
    """The file ended inside a record."""


class _ExactReader:
    """A forward-only view of a file whose ``read(n)`` returns exactly ``n`` bytes or raises
    :class:`_TruncatedError`: mcap's stream reader would otherwise take a short read at the end for a
    whole record (a cut chunk would be decompressed from half its bytes). Not seekable, so the
    stream reader never looks for the summary."""

    def __init__(self, f: Any, size: int) -> None:
        self._f = f
        self.size = size
        self.offset = 0

    def read(self, n: int = -1) -> bytes:
        if n is not None and n > self.size - self.offset:  # never allocate a record the file cannot hold
            raise _TruncatedError(f"a read of {n} bytes at byte {self.offset} passes the end ({self.size})")
        data = self._f.read(n)
        if n is not None and n >= 0 and len(data) < n:
            raise _TruncatedError(f"ends {len(data)} bytes into a read of {n} at byte {self.offset}")
        self.offset += len(data)
        return data


@dataclass
class _StreamRead:
    """What :func:`_read_stream` recovered from a file without its closing magic."""

    schemas: dict[int, Any] = field(default_factory=dict)
    channels: dict[int, Any] = field(default_factory=dict)
    messages: list[Any] = field(default_factory=list)  # of the topics asked for
    counts: dict[int, int] = field(default_factory=dict)  # channel id -> messages read, of every topic
    truncation: Truncation | None = None


def _read_stream(p: Path, size: int, topics: set[str] | None) -> _StreamRead:
    """Every complete record of a truncated file, in file order, with mcap's non-seeking stream
    reader. Chunks are decoded only when read whole and their CRC (and the data section's) checks
    out, so nothing after the cut, and nothing half-written, is returned. A record that fails in
    any other way than by the file's end is corruption: :class:`LogFileError`."""
    from mcap.records import Channel as ChannelRecord
    from mcap.records import DataEnd, Footer, Schema
    from mcap.records import Message as MessageRecord
    from mcap.stream_reader import StreamReader

    out = _StreamRead()
    seen_data_end = seen_footer = False
    with p.open("rb") as f:
        exact = _ExactReader(f, size)
        complete = 0
        try:
            # no size limit: a length past the end of the file (the writer's placeholder for the chunk
            # it was still writing when killed is 2**64 - 1) is the cut, caught by the exact reader
            reader = StreamReader(exact, validate_crcs=True, record_size_limit=None)  # type: ignore[arg-type]
            for record in reader.records:
                complete = exact.offset
                if isinstance(record, Schema):
                    out.schemas[record.id] = record
                elif isinstance(record, ChannelRecord):
                    out.channels[record.id] = record
                elif isinstance(record, MessageRecord):
                    ch = out.channels.get(record.channel_id)
                    if ch is not None:
                        out.counts[ch.id] = out.counts.get(ch.id, 0) + 1
                    if ch is not None and (topics is None or ch.topic in topics):
                        out.messages.append(record)  # only these: a camera's images are not held
                elif isinstance(record, DataEnd):
                    seen_data_end = True
                elif isinstance(record, Footer):
                    seen_footer = True
        except _TruncatedError:
            pass
        except Exception as exc:  # mcap, zstd/lz4, struct, a CRC mismatch: bad content, not a cut
            raise LogFileError(
                f"{p}: corrupt MCAP file near byte {exact.offset} ({type(exc).__name__}: {str(exc)[:80]})"
            ) from exc
    if seen_footer:
        missing = "closing magic incomplete"
    elif seen_data_end:
        missing = "summary section incomplete, no footer"
    else:
        missing = "no summary/footer"
    out.truncation = Truncation(size, complete, missing)
    out.messages.sort(key=lambda m: m.log_time)  # stable: file order among equal times
    return out


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
            return decode_cycle(data, self._message_class(schema))  # the file's own: its cues' telemetry
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


def iter_messages(
    path: str | Path, topics: Iterable[str] | None = None, *, allow_truncated: bool = False
) -> Iterator[tuple[str, Any]]:
    """(topic, decoded message) for every message (of ``topics``, if given), in log-time order.

    JSON messages come as parsed JSON, the cycles as :meth:`CycleRecord.to_dict` dicts,
    Foxglove's protobuf messages as dicts (bytes fields in base64).
    Raises :class:`LogFileError` for a missing, corrupt or (unless ``allow_truncated``: then the
    messages up to the cut) truncated file.
    """
    p = check_log_file(path, allow_truncated=allow_truncated)
    if not _is_complete(p, p.stat().st_size):
        yield from _decoded(p, _read_stream(p, p.stat().st_size, None if topics is None else set(topics)))
        return
    from mcap.reader import make_reader

    decoder = _Decoder()
    try:
        with p.open("rb") as f:
            reader = make_reader(f, validate_crcs=True)  # a flipped bit in a chunk is corruption, not data
            for schema, channel, message in reader.iter_messages(
                topics=None if topics is None else list(topics), log_time_order=True
            ):
                topic = channel.topic
                yield topic, _record(p, topic, decoder.decode(schema, channel.message_encoding, message.data))
    except LogFileError:
        raise
    except Exception as exc:  # mcap, zstd/lz4, protobuf, JSON: the file's content is bad
        raise LogFileError(f"{p}: corrupt MCAP file ({type(exc).__name__}: {exc})") from exc


def _decoded(p: Path, read: _StreamRead) -> Iterator[tuple[str, Any]]:
    """The messages of a stream read, decoded (a message that does not decode is corruption)."""
    decoder = _Decoder()
    try:
        for m in read.messages:
            ch = read.channels[m.channel_id]
            yield ch.topic, _record(p, ch.topic, decoder.decode(read.schemas.get(ch.schema_id), ch.message_encoding,
                                                                m.data))
    except LogFileError:
        raise
    except Exception as exc:  # protobuf, JSON
        raise LogFileError(f"{p}: corrupt MCAP file ({type(exc).__name__}: {str(exc)[:80]})") from exc


def _record(p: Path, topic: str, value: Any) -> Any:
    """``value``, checked where the log's own topics are concerned: a cycle, event, meta or stats message
    is a record (a JSON object, or a cycle decoded to a dict). Anything else there (a list, text, a
    number, undecoded bytes: another program's messages on the same topic names) is
    :class:`LogFileError`, so no reader of the records meets a value of the wrong kind."""
    if topic in _CONTENT_TOPICS and not isinstance(value, dict):
        kinds = {bytes: "undecoded bytes", list: "a JSON array", str: "JSON text", type(None): "JSON null"}
        kind = kinds.get(type(value), "a JSON number")
        raise LogFileError(f"{p}: a {topic} message holds {kind}, not a record: not a lapwrench run log")
    return value


@dataclass
class TopicInfo:
    """One channel of a log: its schema name, message encoding and message count."""

    schema: str
    encoding: str
    messages: int


@dataclass
class LogContents:
    """A run log read back: the custom messages as dicts, the stats and the topics."""

    cycles: list[dict[str, Any]] = field(default_factory=list)  # empty when load_log handed them on
    events: list[dict[str, Any]] = field(default_factory=list)
    meta: dict[str, Any] | None = None
    stats: dict[str, Any] | None = None
    topics: dict[str, TopicInfo] = field(default_factory=dict)
    truncated: Truncation | None = None  # set when the file had no closing magic


def log_topics(path: str | Path) -> dict[str, TopicInfo]:
    """Topic → :class:`TopicInfo`, from the MCAP summary section."""
    from mcap.reader import make_reader

    p = check_log_file(path)
    try:
        with p.open("rb") as f:
            summary = make_reader(f, validate_crcs=True).get_summary()
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


def load_log(
    path: str | Path, *, allow_truncated: bool = False, on_cycle: Callable[[dict[str, Any]], None] | None = None
) -> LogContents:
    """The cycles, events, meta and stats of a run log, and its topics.

    A truncated log (the run was killed, the disk filled) is refused unless ``allow_truncated``;
    then every complete record up to the cut is read, the topics are counted from what was read,
    and :attr:`LogContents.truncated` says where it stopped. With ``on_cycle``, each cycle is handed
    to it as it is decoded, in log-time order, and not kept (``cycles`` stays empty): a long log's
    cycles as dicts take about 8 kB each.
    """
    p = check_log_file(path, allow_truncated=allow_truncated)
    size = p.stat().st_size
    if _is_complete(p, size):
        out = LogContents(topics=log_topics(p))
        messages = iter_messages(p, _CONTENT_TOPICS)
    else:
        read = _read_stream(p, size, set(_CONTENT_TOPICS))
        out = LogContents(topics=_stream_topics(read), truncated=read.truncation)
        messages = _decoded(p, read)
    keep = out.cycles.append if on_cycle is None else on_cycle
    for topic, data in messages:
        if topic == CYCLE_TOPIC:
            keep(data)
        elif topic == EVENT_TOPIC:
            out.events.append(data)
        elif topic == META_TOPIC:
            out.meta = data
        else:
            out.stats = data
    return out


_CONTENT_TOPICS = (CYCLE_TOPIC, EVENT_TOPIC, META_TOPIC, STATS_TOPIC)


def _stream_topics(read: _StreamRead) -> dict[str, TopicInfo]:
    """Topic → :class:`TopicInfo` counted from the messages a stream read recovered."""
    out = {}
    for cid, ch in read.channels.items():
        schema = read.schemas.get(ch.schema_id)
        out[ch.topic] = TopicInfo(schema.name if schema else "", ch.message_encoding, read.counts.get(cid, 0))
    return out


def read_log(path: str | Path) -> tuple[list[dict[str, Any]], list[dict[str, Any]], dict[str, Any] | None]:
    """(cycles, events, meta) of a complete MCAP run log (a truncated one: :func:`load_log`)."""
    c = load_log(path)
    return c.cycles, c.events, c.meta
