"""The F/T wire protocol: request and 36-byte record codecs."""

from __future__ import annotations

import pytest

from lapwrench.drivers.base import PacketError
from lapwrench.drivers.ft import (
    CMD_START_REALTIME,
    CMD_STOP,
    RECORD_SIZE,
    pack_record,
    pack_request,
    record_fields,
    unpack_record,
    unpack_request,
)


# --------------------------------------------------------------------------- codec
def test_request_and_record_codec_roundtrip() -> None:
    req = pack_request(CMD_START_REALTIME, 0x01020304)
    assert req == bytes.fromhex("1234 0002 01020304")
    assert unpack_request(req) == (0x1234, CMD_START_REALTIME, 0x01020304)
    rec = pack_record(7, 99, 0, [1, -2, 3, -4, 5, -6])
    assert len(rec) == RECORD_SIZE == 36
    r = unpack_record(rec)
    assert (r.sequence, r.ft_sequence, r.status, r.counts) == (7, 99, 0, (1, -2, 3, -4, 5, -6))


@pytest.mark.parametrize(
    "data",
    [b"", b"\x00" * 35, b"\x00" * 37, pack_request(CMD_START_REALTIME)],
    ids=["empty", "short", "long", "request-header"],
)
def test_unpack_record_rejects_malformed(data: bytes) -> None:
    with pytest.raises(PacketError):
        unpack_record(data)
    with pytest.raises(PacketError):  # the same refusal from the fields' decoder the 1 kHz drain uses
        record_fields(data)


def test_record_fields_are_the_nine_numbers_on_the_wire_in_order() -> None:
    rec = pack_record(2**32 - 1, 5, 0x10, [1, -2, 3, -4, 5, -2**31])
    assert record_fields(rec) == (2**32 - 1, 5, 0x10, 1, -2, 3, -4, 5, -2**31)
    r = unpack_record(rec)
    assert (r.sequence, r.ft_sequence, r.status, *r.counts) == record_fields(rec)


def test_unpack_request_rejects_wrong_header() -> None:
    with pytest.raises(PacketError, match="header"):
        unpack_request(pack_request(CMD_STOP, header=0x4321))
