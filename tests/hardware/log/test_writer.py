"""RunLogger on foxglove-sdk: round trip, standard-schema channels, the drop counter."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest
from hardware.log.support import Q0, record, write

from lapwrench.hardware import cli as hw
from lapwrench.hardware import log as runlog
from lapwrench.hardware.log import (
    CYCLE_TOPIC,
    EVENT_TOPIC,
    RunLogger,
    iter_messages,
    load_log,
    log_report_main,
    log_topics,
    read_log,
)
from lapwrench.robot.model import RobotModel


def test_round_trip_of_cycles_events_meta_and_stats(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    log = write(path, 300)
    cycles, events, meta = read_log(path)
    assert meta == {"robot": "test", "n": 300}
    assert [c["k"] for c in cycles] == list(range(300))
    c = cycles[7]
    assert c["t"] == pytest.approx(7e-3) and c["mode"] == "handle" and c["supervisor"] == "running"
    assert c["q"] == pytest.approx((Q0 + 7e-3).tolist()) and c["tactile"] == [0.0] * 64
    assert c["wrenches"]["rcm"] == list(range(6)) and c["instruments"] == [[10.0, 20.0]]
    assert c["external_force"] is None and c["p_G"] == [0.45, 0.0, 0.2]
    assert events == [{"time": 0.05, "kind": "rcm_error", "message": "RCM error 12 mm; holding"}]
    stats = load_log(path).stats
    assert stats is not None and stats["cycles"] == 300 and stats["dropped"] == 0 and stats["errors"] == 0
    assert log.cycles == 300 and log.dropped == 0 and log.events == 1
    # what comes back is the record's own dict, bit for bit; p_G defaults to None
    assert cycles[3] == record(3, p_G=np.array([0.45, 0.0, 0.2])).to_dict() and record(3).to_dict()["p_G"] is None
    assert {t for t, _ in iter_messages(path)} >= {CYCLE_TOPIC, EVENT_TOPIC, runlog.META_TOPIC, runlog.STATS_TOPIC}


def test_standard_schema_channels_in_the_mcap_summary(tmp_path: Path, panda: RobotModel) -> None:
    from mcap.reader import make_reader

    path = tmp_path / "run.mcap"
    with RunLogger(path, {"robot": "test"}, model=panda) as log:
        for k in range(50):
            log.cycle(record(k))
        log.event(0.01, "start", "go")
        log.image(0.02, b"\xff\xd8 not really a jpeg", "jpeg")
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    schema_of = {ch.topic: summary.schemas[ch.schema_id] for ch in summary.channels.values()}
    expected = {
        runlog.TF_TOPIC: "foxglove.FrameTransforms",
        runlog.POSE_TOPIC: "foxglove.PoseInFrame",
        runlog.JOINTS_TOPIC: "foxglove.JointStates",
        runlog.WRENCH_TOPIC: "foxglove.SceneUpdate",
        runlog.LOG_TOPIC: "foxglove.Log",
        runlog.IMAGE_TOPIC: "foxglove.CompressedImage",
        CYCLE_TOPIC: "lapwrench.Cycle",
        EVENT_TOPIC: "lapwrench.Event",
        runlog.META_TOPIC: "lapwrench.Meta",
        runlog.STATS_TOPIC: "lapwrench.LogStats",
    }
    assert {t: s.name for t, s in schema_of.items()} == expected
    json_topics = {EVENT_TOPIC, runlog.META_TOPIC, runlog.STATS_TOPIC}
    for ch in summary.channels.values():
        encoding = "json" if ch.topic in json_topics else "protobuf"
        assert ch.message_encoding == encoding, ch.topic
        assert schema_of[ch.topic].encoding == ("jsonschema" if encoding == "json" else "protobuf"), ch.topic
    assert log_topics(path)[CYCLE_TOPIC].messages == 50


def test_drop_counter_counts_when_the_ring_is_full(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    log = RunLogger(path, {"robot": "test"}, capacity=3, start=False)  # a writer that is not writing
    for k in range(10):
        log.cycle(record(k))  # never blocks, even with the writer stuck
    assert log.dropped == 7
    log.start()
    log.close()
    contents = load_log(path)
    assert [c["k"] for c in contents.cycles] == [0, 1, 2]
    assert contents.stats is not None and contents.stats["dropped"] == 7 and contents.stats["capacity"] == 3
    (ev,) = [e for e in contents.events if e["kind"] == "log_dropped"]
    assert "dropped 7 cycles" in ev["message"]
    out = tmp_path / "report"
    assert log_report_main(argparse.Namespace(log=str(path), out=str(out))) == 0
    assert '"log_dropped": 7' in (out / "summary.json").read_text()


def test_mcap_round_trip_and_report(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with RunLogger(path, {"robot": "test"}) as log:
        for k in range(200):
            log.cycle(record(k, ft_force=np.array([np.nan, 1.0, 2.0]) if k == 5 else np.array([1.0, 2.0, 3.0])))
        log.event(0.1, "rcm_error", "RCM error 12 mm; holding")
    cycles, events, meta = read_log(path)
    assert meta == {"robot": "test"}
    assert len(cycles) == 200 and [c["k"] for c in cycles] == list(range(200))
    assert cycles[3]["wrenches"]["rcm"] == list(range(6)) and cycles[3]["mode"] == "handle"
    assert cycles[5]["ft_force"] == [None, 1.0, 2.0]  # NaN survives as null, the file stays JSON
    assert cycles[0]["external_force"] is None
    assert events == [{"time": 0.1, "kind": "rcm_error", "message": "RCM error 12 mm; holding"}]
    topics = {t for t, _ in iter_messages(path)}
    assert {CYCLE_TOPIC, EVENT_TOPIC} <= topics
    # every channel has a schema Foxglove can show the fields with: JSON schemas for the JSON messages,
    # protobuf descriptors for the cycle and Foxglove's standard messages (see the test above)
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    schemas = {ch.topic: (summary.schemas[ch.schema_id], ch.message_encoding) for ch in summary.channels.values()}
    assert {(schema.encoding, encoding) for schema, encoding in schemas.values()} == {
        ("jsonschema", "json"),
        ("protobuf", "protobuf"),
    }
    assert schemas[CYCLE_TOPIC][0].name == "lapwrench.Cycle"
    out = tmp_path / "report"
    assert hw.log_report_main(argparse.Namespace(log=str(path), out=str(out))) == 0
    for name in ("rcm_error.png", "wrenches.png", "mode.png", "joint_commands.png"):
        assert (out / name).stat().st_size > 5000
    assert hw.log_report_main(argparse.Namespace(log=str(tmp_path / "none.mcap"), out=str(out))) == 2


BAD_TIMES = {10: 1e15, 11: float("nan"), 12: -5.0, 13: float("inf"), 14: 1e10}  # cycle -> its time


def test_records_whose_time_is_no_session_time_are_kept_counted_and_cost_no_other(
    tmp_path: Path, panda: RobotModel, capsys: pytest.CaptureFixture[str]
) -> None:
    """A time of 1e15 s overflowed foxglove-sdk's 64-bit ns (the record lost, an error counted); 1e10 s fit
    the ns but not a Timestamp's 32-bit seconds, and its frame set moved the next one 316 years ahead (no
    transform after it); NaN, inf and negative times went to 0 unsaid. Now each is logged at the latest
    good cycle's time, fields as they are, counted, and said in a log_bad_time event and by log-report."""
    from hardware.log.support import tf_messages

    path = tmp_path / "run.mcap"
    with RunLogger(path, {"robot": "test"}, model=panda) as log:
        for k in range(300):
            log.cycle(record(k, t=BAD_TIMES.get(k, k * 1e-3)))
        log.event(1e15, "odd", "an event 31 million years in")
        log.image(float("nan"), np.zeros((8, 8, 3), np.uint8))
    stats = log.stats()
    assert stats["errors"] == 0 and stats["bad_times"] == len(BAD_TIMES) + 2 and stats["images"] == 1
    cycles, events, _ = read_log(path)
    assert [c["k"] for c in cycles] == list(range(300))  # every cycle, in order (the bad ones at cycle 9's time)
    assert [c["t"] for c in cycles[10:15]] == [1e15, None, -5.0, None, 1e10]  # its own time, as it came
    assert len(tf_messages(path)) == 30  # a frame set every 10 ms of the good cycles' time, to the end
    assert {e["kind"] for e in events} == {"odd", "log_bad_time"}
    note = next(e["message"] for e in events if e["kind"] == "log_bad_time")
    assert note.startswith("7 records, events or images had a time that is no session time (0 to 4294967295 s")
    assert log_report_main(argparse.Namespace(log=str(path), out=str(tmp_path / "report"))) == 0
    assert "logger: 300 cycles written, 0 dropped, 7 with a bad time" in capsys.readouterr().out
