"""Run logs on foxglove-sdk: round trip, standard-schema channels, frame transforms from the
measured joints, the drop counter, NaN records, images, and log-report on broken files."""

from __future__ import annotations

import argparse
import base64
import json
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lapwrench.hardware import log as runlog
from lapwrench.hardware.log import (
    CYCLE_TOPIC,
    EVENT_TOPIC,
    CycleRecord,
    LogFileError,
    RunLogger,
    iter_messages,
    load_log,
    log_report_main,
    log_topics,
    read_log,
)
from lapwrench.robot.model import RobotModel
from lapwrench.virtual import DEFAULT_Q0

Q0 = np.asarray(DEFAULT_Q0, dtype=float)


def record(i: int, **over: Any) -> CycleRecord:
    """Cycle ``i`` like the runner's (1 kHz session time), with ``over`` replacing fields."""
    base: dict[str, Any] = dict(
        t=i * 1e-3, robot_time=i * 1e-3, k=i, q=Q0 + 1e-3 * i, dq=np.zeros(7), tau_J=np.ones(7),
        external_force=None, ft_force=np.array([1.0, 2.0, 3.0]), ft_torque=np.zeros(3), tactile=np.zeros(64),
        instruments=np.array([[10.0, 20.0]]),
        wrenches={"rcm": np.arange(6.0), "interaction": np.array([0, 0, 0, 0, 0, -5.0]), "tracking": np.zeros(6)},
        mode="handle", delta=1.2, contacts=64, p_R=np.array([0.45, 0.0, 0.25]), e_R=np.array([1e-3, 0, 0]),
        rcm_error=1e-3, rcm_error_measured=2e-3, q_ref=np.zeros(7), q_cmd=np.zeros(7), supervisor="running",
        alarm=False, compute_us=150.0, cycle_us=1000.0,
    )  # fmt: skip
    base.update(over)
    return CycleRecord(**base)


def write(path: Path, n: int, model: RobotModel | None = None, **kw: Any) -> RunLogger:
    with RunLogger(path, {"robot": "test", "n": n}, model=model, **kw) as log:
        for k in range(n):
            log.cycle(record(k, p_G=np.array([0.45, 0.0, 0.2])))
        log.event(0.05, "rcm_error", "RCM error 12 mm; holding")
    return log


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


def test_cycle_messages_decode_with_the_protobuf_library(tmp_path: Path) -> None:
    """The lapwrench.Cycle schema written in the file (its FileDescriptorSet), loaded in a descriptor
    pool of its own as Foxglove and other readers do, decodes what encode_cycle writes, and
    decode_cycle gives the record's dict back."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(runlog.cycle_descriptor()).file:
        pool.Add(fd)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName("lapwrench.Cycle"))
    rec = record(42, k=-3, p_G=np.array([0.1, 0.2, 0.3]), instruments=np.array([[1.0, 2.0], [3.0, 4.0]]))
    data = runlog.encode_cycle(rec)
    msg = cls.FromString(data)
    assert msg.k == -3 and msg.mode == "handle" and msg.alarm is False and msg.t == pytest.approx(0.042)
    assert list(msg.q) == pytest.approx(rec.q.tolist()) and len(msg.tactile) == 64
    assert list(msg.instruments) == [1.0, 2.0, 3.0, 4.0] and msg.instrument_count == 2
    assert [w.name for w in msg.wrenches] == ["rcm", "interaction", "tracking"] and list(msg.wrenches[0].w) == [
        0.0, 1.0, 2.0, 3.0, 4.0, 5.0,
    ]  # fmt: skip
    assert runlog.decode_cycle(data) == rec.to_dict()
    assert runlog.decode_cycle(msg.SerializeToString()) == rec.to_dict()  # the library's bytes read back too
    # no instruments (stale) and no instruments in view (fresh, empty) stay apart
    assert runlog.decode_cycle(runlog.encode_cycle(record(1, instruments=None)))["instruments"] is None
    assert runlog.decode_cycle(runlog.encode_cycle(record(1, instruments=np.zeros((0, 2)))))["instruments"] == []


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


def _tf_messages(path: Path) -> list[dict[str, Any]]:
    return [m for _, m in iter_messages(path, [runlog.TF_TOPIC])]


def test_transforms_from_the_measured_joints_when_a_model_is_given(tmp_path: Path, panda: RobotModel) -> None:
    path = tmp_path / "run.mcap"
    write(path, 200, model=panda)  # 0.2 s of cycles: transforms at 100 Hz of session time
    tfs = _tf_messages(path)
    assert len(tfs) == 20
    first = {t["child_frame_id"]: t for t in tfs[0]["transforms"]}
    last = {t["child_frame_id"]: t for t in tfs[-1]["transforms"]}
    # the fixed frames (flange, scope frames on it) in the first set, the moving ones in every set
    assert {"lap_E", "lap_H", "lap_C", "panda_link8", "lap_R", "lap_G", "panda_link1", "panda_link7"} <= set(first)
    assert set(last) == {f"panda_link{j}" for j in range(1, 8)} | {"lap_R", "lap_G"}
    assert first["lap_E"]["parent_frame_id"] == "panda_link8" and first["lap_C"]["parent_frame_id"] == "lap_E"
    assert last["panda_link1"]["parent_frame_id"] == "panda_link0" and last["lap_R"]["parent_frame_id"] == "panda_link0"
    t_R = last["lap_R"]["translation"]
    assert [t_R["x"], t_R["y"], t_R["z"]] == pytest.approx([0.45, 0.0, 0.25])
    # the scope pose is the forward kinematics of the measured q of the cycle it was written with
    kin = panda.kinematics(Q0 + 1e-3 * 190, np.zeros(7))
    pose = [m for _, m in iter_messages(path, [runlog.POSE_TOPIC])][-1]
    p = pose["pose"]["position"]
    assert pose["frame_id"] == "panda_link0" and [p["x"], p["y"], p["z"]] == pytest.approx(kin.p_E, abs=1e-9)
    o = pose["pose"]["orientation"]
    x, y, z, w = o["x"], o["y"], o["z"], o["w"]
    R = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip
    assert np.allclose(R, kin.R_E, atol=1e-9)
    # wrench arrows: the interaction force (-5 N along z) drawn at H, 1 cm per N
    scene = [m for _, m in iter_messages(path, [runlog.WRENCH_TOPIC])][-1]
    ent = {e["id"]: e for e in scene["entities"]}
    (arrow,) = ent["interaction"]["arrows"]
    assert arrow["shaft_length"] + arrow["head_length"] == pytest.approx(0.05)
    h = arrow["pose"]["position"]
    assert [h["x"], h["y"], h["z"]] == pytest.approx(kin.p_H, abs=1e-9)
    assert ent["tracking"]["arrows"] == []  # a zero force: no arrow
    # without a model: no transforms, no pose, no arrows (joint states only)
    bare = tmp_path / "bare.mcap"
    write(bare, 200)
    topics = log_topics(bare)
    assert (
        runlog.TF_TOPIC not in topics
        and runlog.WRENCH_TOPIC not in topics
        and topics[runlog.JOINTS_TOPIC].messages == 20
    )


def test_drop_counter_counts_when_the_ring_is_full(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    gate = threading.Event()
    real_round = RunLogger._write_round

    def blocked_round(self: RunLogger) -> None:
        gate.wait()  # the writer is stuck, before taking anything off the ring, until released
        real_round(self)

    monkeypatch.setattr(RunLogger, "_write_round", blocked_round)
    path = tmp_path / "run.mcap"
    log = RunLogger(path, {"robot": "test"}, capacity=3)
    for k in range(10):
        log.cycle(record(k))  # never blocks, even with the writer stuck
    assert log.dropped == 7
    gate.set()
    log.close()
    contents = load_log(path)
    assert [c["k"] for c in contents.cycles] == [0, 1, 2]
    assert contents.stats is not None and contents.stats["dropped"] == 7 and contents.stats["capacity"] == 3
    (ev,) = [e for e in contents.events if e["kind"] == "log_dropped"]
    assert "dropped 7 cycles" in ev["message"]
    out = tmp_path / "report"
    assert log_report_main(argparse.Namespace(log=str(path), out=str(out))) == 0
    assert '"log_dropped": 7' in (out / "summary.json").read_text()


def test_nan_and_bad_records_do_not_break_the_file(tmp_path: Path, panda: RobotModel) -> None:
    path = tmp_path / "run.mcap"
    nan3 = np.array([np.nan, 1.0, np.inf])
    with RunLogger(path, {"robot": "test", "x": float("nan")}, model=panda) as log:
        log.cycle(record(0, q=np.full(7, np.nan), ft_force=nan3, rcm_error=float("nan"), delta=float("inf"),
                         wrenches={"rcm": np.full(6, np.nan)}, instruments=np.array([[np.nan, 2.0]])))  # fmt: skip
        log.cycle(record(1, q="not a joint vector"))  # cannot be converted: counted, skipped
        log.cycle(record(2, k=np.int64(2), alarm=np.bool_(True), p_G=np.array([np.nan, 0, 0])))
        log.event(float("nan"), "odd", "an event without a time")
    assert log.errors == 1 and "ValueError" in str(log.stats()["first_error"])
    cycles, _, meta = read_log(path)
    assert meta == {"robot": "test", "x": None}
    assert [c["k"] for c in cycles] == [0, 2]
    c0 = cycles[0]
    assert c0["q"] == [None] * 7 and c0["ft_force"] == [None, 1.0, None] and c0["rcm_error"] is None
    assert c0["delta"] is None and c0["wrenches"]["rcm"] == [None] * 6 and c0["instruments"] == [[None, 2.0]]
    assert cycles[1]["alarm"] is True and cycles[1]["p_G"] == [None, 0.0, 0.0]
    tfs = _tf_messages(path)  # the NaN q gave no transforms; the last cycle did (without G)
    assert len(tfs) == 1 and "lap_G" not in {t["child_frame_id"] for t in tfs[0]["transforms"]}
    assert log_report_main(argparse.Namespace(log=str(path), out=str(tmp_path / "report"))) == 0


def test_images_as_jpeg_bytes_and_as_arrays(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    rgb = np.zeros((24, 32, 3), np.uint8)
    rgb[:, :, 0] = 200
    with RunLogger(path) as log:
        log.image(0.0, rgb)
        log.image(0.04, b"\xff\xd8\xff\xe0fake", "jpeg")
    images = [m for _, m in iter_messages(path, [runlog.IMAGE_TOPIC])]
    assert [m["frame_id"] for m in images] == ["lap_C", "lap_C"] and [m["format"] for m in images] == ["jpeg"] * 2
    import cv2

    decoded = cv2.imdecode(np.frombuffer(base64.b64decode(images[0]["data"]), np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == (24, 32, 3) and decoded[..., 2].mean() > 150  # red stays red (RGB in, BGR decoded)
    assert base64.b64decode(images[1]["data"]) == b"\xff\xd8\xff\xe0fake"


# -- truncated and broken files (issue 11, item 9) ---------------------------------------------------
N_LONG = 3000  # cycles: 4 chunks of foxglove-sdk's default size, so a cut can fall between and inside them


@pytest.fixture(scope="module")
def long_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict[str, Any]]]:
    """A complete log of ``N_LONG`` cycles, and its cycles read back."""
    path = tmp_path_factory.mktemp("long") / "run.mcap"
    write(path, N_LONG)
    return path, read_log(path)[0]


def report(path: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = log_report_main(argparse.Namespace(log=str(path), out=str(out)))
    printed = capsys.readouterr()
    assert "Traceback" not in printed.out + printed.err
    return code, printed.out, printed.err


def chunk_offsets(path: Path) -> list[int]:
    """Where each chunk record starts (from the summary's chunk indexes)."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return sorted(ci.chunk_start_offset for ci in summary.chunk_indexes)


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


def test_files_that_cannot_be_read_give_one_line_and_exit_2(
    long_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    full, _ = long_log
    data = full.read_bytes()
    files = {
        "header.mcap": data[:20],  # inside the header record: no cycle at all
        "magic.mcap": data[:5],
        "garbage.mcap": b"not a log\n" * 100,
        "empty.mcap": b"",
        "damaged.mcap": data[: len(data) // 3] + bytes(64) + data[len(data) // 3 + 64 :],  # complete, corrupt
    }
    for name, content in files.items():
        (tmp_path / name).write_bytes(content)
    (tmp_path / "folder.mcap").mkdir()
    cases = {
        "header.mcap": "truncated MCAP file (20 bytes, no summary/footer) with no complete /lapwrench/cycle message",
        "magic.mcap": "truncated MCAP file (5 bytes, cut inside the magic)",
        "garbage.mcap": "not an MCAP file",
        "empty.mcap": "empty file (0 bytes), not an MCAP log",
        "damaged.mcap": "corrupt MCAP file",
        "folder.mcap": "is a directory, not a log file",
        "none.mcap": "no such log file",
    }
    for name, words in cases.items():
        path = tmp_path / name
        code, out, err = report(path, tmp_path / "report", capsys)
        assert code == 2 and not out, (name, out)
        assert err.startswith(f"lapwrench log-report: {path}: {words}") and len(err.strip().splitlines()) == 1, err
        if name == "header.mcap":  # readable as far as it goes: nothing
            assert load_log(path, allow_truncated=True).cycles == []
        else:
            with pytest.raises(LogFileError):
                load_log(path, allow_truncated=True)
    assert not (tmp_path / "report").exists()


def test_the_command_line_reports_a_truncated_log_and_refuses_a_foreign_one(
    long_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path
) -> None:
    full, _ = long_log
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    foreign = tmp_path / "foreign.mcap"
    foreign.write_text("not a log\n")
    script = "import sys; from lapwrench.cli import main; sys.exit(main(sys.argv[1:]))"
    for path, code, words in ((cut, 0, "is truncated (no summary/footer); read "), (foreign, 2, "not an MCAP file")):
        proc = subprocess.run(
            [sys.executable, "-c", script, "log-report", str(path), "--out", str(tmp_path / "report")],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert proc.returncode == code and words in proc.stderr, proc.stderr
        assert "Traceback" not in proc.stdout + proc.stderr and len(proc.stderr.strip().splitlines()) == 1
