"""Reading run logs: the older JSON logs, truncated logs, damaged chunks."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import pytest
from hardware.log.support import N_LONG, record, report

from lapwrench.hardware import log as runlog
from lapwrench.hardware.log import (
    CYCLE_TOPIC,
    EVENT_TOPIC,
    LogFileError,
    load_log,
    log_report_main,
    log_topics,
    read_log,
)


def chunk_offsets(path: Path) -> list[int]:
    """Where each chunk record starts (from the summary's chunk indexes)."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return sorted(ci.chunk_start_offset for ci in summary.chunk_indexes)


def test_logs_of_the_json_logger_still_read_and_report(tmp_path: Path) -> None:
    """A log of the earlier logger (every channel JSON with a JSON schema, cycles without p_G)
    reads back as it was written and log-report plots it."""
    import json

    from mcap.writer import CompressionType, Writer

    path = tmp_path / "old.mcap"
    cycles = []
    for k in range(50):
        c = record(k).to_dict()
        del c["p_G"]
        cycles.append(c)
    with path.open("wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD)
        writer.start(profile="", library="lapwrench")
        channels = {}
        names = {CYCLE_TOPIC: "lapwrench.Cycle", EVENT_TOPIC: "lapwrench.Event", runlog.META_TOPIC: "lapwrench.Meta"}
        for topic, name in names.items():
            sid = writer.register_schema(name=name, encoding="jsonschema", data=json.dumps({"title": name}).encode())
            channels[topic] = writer.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        messages = [(runlog.META_TOPIC, 0.0, {"robot": "old"})] + [(CYCLE_TOPIC, c["t"], c) for c in cycles]
        messages.append((EVENT_TOPIC, 0.02, {"time": 0.02, "kind": "rcm_error", "message": "RCM error 12 mm"}))
        for seq, (topic, t, data) in enumerate(messages):
            ns = round(t * 1e9)
            writer.add_message(channels[topic], ns, json.dumps(data).encode(), ns, sequence=seq)
        writer.finish()
    read_cycles, events, meta = read_log(path)
    assert read_cycles == cycles and meta == {"robot": "old"} and events[0]["kind"] == "rcm_error"
    assert log_topics(path)[CYCLE_TOPIC] == runlog.TopicInfo("lapwrench.Cycle", "json", 50)
    out = tmp_path / "report"
    assert log_report_main(argparse.Namespace(log=str(path), out=str(out))) == 0
    assert (out / "rcm_error.png").is_file() and '"cycles": 50' in (out / "summary.json").read_text()


@pytest.mark.parametrize("cut", ["last byte", "half", "inside the chunk being written"])
def test_a_truncated_log_is_read_as_far_as_it_goes(
    cut: str,
    long_log: tuple[Path, list[dict[str, Any]]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    full, cycles = long_log
    data = full.read_bytes()
    path = tmp_path / "cut.mcap"
    if cut == "last byte":
        path.write_bytes(data[:-1])
    elif cut == "half":
        path.write_bytes(data[: len(data) // 2])
    else:  # killed while a chunk streams to the file: foxglove-sdk's header holds a 2**64 - 1 placeholder length
        at = chunk_offsets(full)[2]
        path.write_bytes(data[:at] + bytes([0x06]) + (2**64 - 1).to_bytes(8, "little") + data[at + 9 : at + 2000])
    log = load_log(path, allow_truncated=True)
    assert log.truncated is not None and log.truncated.size == path.stat().st_size
    n = len(log.cycles)
    # a clean prefix of the run, every cycle bit for bit: nothing from a cut or half-written chunk
    assert 0 < n <= N_LONG and log.cycles == cycles[:n]
    assert log.meta == {"robot": "test", "n": N_LONG} and len(log.events) == 1
    assert log.topics[CYCLE_TOPIC].messages == n
    if cut == "last byte":  # only the closing magic is incomplete: everything is there
        assert n == N_LONG and log.stats is not None and log.truncated.missing == "closing magic incomplete"
    else:
        assert n < N_LONG and log.stats is None and log.truncated.missing == "no summary/footer"
    with pytest.raises(LogFileError, match="truncated"):
        read_log(path)  # the strict reader still refuses it
    code, out, err = report(path, tmp_path / "report", capsys)
    assert code == 0 and "summary.json" in out
    t_last = cycles[n - 1]["t"]
    assert err.strip() == (
        f"lapwrench log-report: {path} is truncated ({log.truncated.missing}); read {n} cycles up to t={t_last:.3f} s"
    )
    for name in ("rcm_error.png", "wrenches.png", "mode.png", "joint_commands.png"):
        assert (tmp_path / "report" / name).stat().st_size > 5000
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    assert summary["cycles"] == n and summary["truncated"]["missing"] == log.truncated.missing


def test_a_damaged_chunk_in_a_complete_log_is_corruption_not_data(
    long_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same for a complete file (read through its summary): the chunk CRCs are checked, so one flipped
    bit is refused rather than read as a joint angle of 1e-226."""
    full, _ = long_log
    data = bytearray(full.read_bytes())
    data[chunk_offsets(full)[1] + 500] ^= 0x01
    path = tmp_path / "flipped.mcap"
    path.write_bytes(bytes(data))
    with pytest.raises(LogFileError, match="corrupt"):
        load_log(path)
    code, out, err = report(path, tmp_path / "report", capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "corrupt" in err and not out


def test_a_damaged_chunk_in_a_truncated_log_is_corruption_not_data(
    long_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The stream reader checks each chunk's CRC: a flipped byte is an error, never garbled cycles."""
    full, _ = long_log
    data = bytearray(full.read_bytes()[: 3 * full.stat().st_size // 4])
    data[chunk_offsets(full)[1] + 500] ^= 0xFF  # inside the second chunk's compressed records
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(data))
    with pytest.raises(LogFileError, match="corrupt"):
        load_log(path, allow_truncated=True)
    code, out, err = report(path, tmp_path / "report", capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "corrupt" in err and not out


def foreign_log(path: Path, messages: dict[str, list[bytes]]) -> Path:
    """An MCAP file of another program: JSON channels named like a lapwrench log's, holding ``messages``."""
    from mcap.writer import Writer

    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="another program")
        for topic, payloads in messages.items():
            channel = writer.register_channel(topic=topic, message_encoding="json", schema_id=0)
            for i, data in enumerate(payloads):
                writer.add_message(channel, log_time=i, publish_time=i, data=data)
        writer.finish()
    return path


@pytest.mark.parametrize(
    ("topic", "data", "kind"),
    [
        (CYCLE_TOPIC, b"[1, 2, 3]", "a JSON array"),
        (CYCLE_TOPIC, b'"a cycle"', "JSON text"),
        (EVENT_TOPIC, b"5", "a JSON number"),
        (runlog.META_TOPIC, b"null", "JSON null"),
        (runlog.STATS_TOPIC, b"[]", "a JSON array"),
    ],
)
def test_a_message_that_is_not_a_record_on_a_log_topic_is_refused(
    tmp_path: Path, topic: str, data: bytes, kind: str
) -> None:
    """Another program's messages on the log's topic names reached log-report and identify-grip as lists
    or text (an AttributeError there, a traceback in identify-grip): now the reader refuses the file."""
    path = foreign_log(tmp_path / "foreign.mcap", {CYCLE_TOPIC: [b'{"t": 0.0}'], topic: [data]})
    with pytest.raises(LogFileError, match=f"a {topic} message holds {kind}, not a record"):
        load_log(path)
    with pytest.raises(LogFileError, match=f"a {topic} message holds {kind}"):
        list(runlog.iter_messages(path))
    cut = tmp_path / "cut.mcap"  # the same read from the front, as a truncated file is
    cut.write_bytes(path.read_bytes()[:-8])
    with pytest.raises(LogFileError, match=f"a {topic} message holds {kind}"):
        load_log(cut, allow_truncated=True)


def test_a_path_the_system_cannot_stat_is_a_log_file_error(tmp_path: Path) -> None:
    """A name longer than the file system allows raised OSError from Path.is_dir (a traceback in
    identify-grip); an empty path was read as the current folder."""
    with pytest.raises(LogFileError, match="cannot read"):
        runlog.check_log_file(tmp_path / ("x" * 300 + ".mcap"))
    with pytest.raises(LogFileError, match="no log file given"):
        runlog.check_log_file("")


def test_a_pipe_or_device_is_refused_without_reading_it(tmp_path: Path) -> None:
    """A FIFO made the reader wait forever for a writer (log-report hung); /dev/zero was called empty."""
    import os
    import subprocess
    import sys

    fifo = tmp_path / "run.mcap"
    os.mkfifo(fifo)
    script = "import sys; from lapwrench.cli import main; sys.exit(main(sys.argv[1:]))"
    for path in (fifo, Path("/dev/zero")):
        proc = subprocess.run(
            [sys.executable, "-c", script, "log-report", str(path), "--out", str(tmp_path / "report")],
            capture_output=True, text=True, timeout=120,  # a hang fails here
        )  # fmt: skip
        assert proc.returncode == 2, proc.stderr
        words = "not a regular file (a pipe, socket or device), not a log file"
        assert proc.stderr == f"lapwrench log-report: {path}: {words}\n"
