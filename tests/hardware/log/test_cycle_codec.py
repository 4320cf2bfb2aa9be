"""Cycle messages encoded as protobuf decode with the protobuf library."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hardware.log.support import record

from lapwrench.hardware import log as runlog


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


def test_the_cues_telemetry_decodes_by_name_with_the_protobuf_library() -> None:
    """Foxglove reads ``telemetry.<cue>.<field>`` from the schema alone; decode_cycle with the log's
    own message class gives the record's dict back, a cue without values this cycle left out."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    layout = (("zoom", ("spread", "in_band", "force")), ("keep_out", ("distance", "barrier")))
    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(runlog.cycle_descriptor(layout)).file:
        pool.Add(fd)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName("lapwrench.Cycle"))
    rec = record(3, telemetry={"zoom": (0.12, 1.0, -4.5)})
    msg = cls.FromString(runlog.encode_cycle(rec, layout))
    assert (msg.telemetry.zoom.spread, msg.telemetry.zoom.in_band, msg.telemetry.zoom.force) == (0.12, 1.0, -4.5)
    assert msg.telemetry.HasField("zoom") and not msg.telemetry.HasField("keep_out")
    assert runlog.decode_cycle(msg.SerializeToString(), cls) == rec.to_dict(layout)
    assert runlog.decode_cycle(runlog.encode_cycle(rec))["telemetry"] == {}  # no layout: no telemetry
