"""Tactile array: frame codec, resynchronising parser, and the serial reader on a pty / loop://."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import serial

from lapwrench.drivers.base import DeviceOpenError, PacketError
from lapwrench.drivers.tactile import (
    ChecksumType,
    SerialTactileArray,
    TactileFrame,
    TactileFrameFormat,
    TactileFrameParser,
    crc16_modbus,
)

ALL_CHECKSUMS = list(ChecksumType)


def wait_until(cond: Callable[[], bool], timeout: float = 3.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


def pattern(k: int, n: int = 64, hi: int = 255) -> np.ndarray:
    return ((np.arange(n) * 7 + k * 13) % (hi + 1)).astype(np.int64)


# --------------------------------------------------------------------------- codec
def test_crc16_modbus_check_value() -> None:
    assert crc16_modbus(b"123456789") == 0x4B37
    # classic Modbus request 01 03 00 00 00 0A -> CRC bytes C5 CD (low byte first)
    assert crc16_modbus(bytes.fromhex("01030000000A")).to_bytes(2, "little") == bytes.fromhex("C5CD")


@pytest.mark.parametrize("checksum", ALL_CHECKSUMS)
@pytest.mark.parametrize("length_byte", [False, True])
@pytest.mark.parametrize("width", [1, 2])
def test_encode_decode_roundtrip(checksum: ChecksumType, length_byte: bool, width: int) -> None:
    fmt = TactileFrameFormat(
        checksum=checksum, length_byte=length_byte, element_width=width, max_value=255 if width == 1 else 4095
    )
    v = pattern(3, hi=fmt.max_value)
    frame = fmt.encode(v)
    assert len(frame) == fmt.frame_size
    np.testing.assert_array_equal(fmt.decode(frame), v)


def test_sum8_and_xor8_values() -> None:
    fmt = TactileFrameFormat(header=b"\xff", n_elements=3, checksum="sum8")
    assert fmt.encode([1, 2, 250]) == bytes([0xFF, 1, 2, 250, (1 + 2 + 250) & 0xFF])
    fmt = TactileFrameFormat(header=b"\xff", n_elements=3, checksum="xor8")
    assert fmt.encode([1, 2, 4]) == bytes([0xFF, 1, 2, 4, 7])
    fmt = TactileFrameFormat(header=b"\xff", n_elements=3, checksum="xor8", checksum_includes_header=True)
    assert fmt.encode([1, 2, 4]) == bytes([0xFF, 1, 2, 4, 0xFF ^ 7])


def test_decode_rejects_bad_frames() -> None:
    fmt = TactileFrameFormat(checksum="crc16-modbus", length_byte=True)
    good = bytearray(fmt.encode(pattern(1)))
    bad_crc = bytearray(good)
    bad_crc[10] ^= 0x01
    with pytest.raises(PacketError, match="checksum"):
        fmt.decode(bad_crc)
    bad_len = bytearray(good)
    bad_len[2] = 63
    with pytest.raises(PacketError):
        fmt.decode(bad_len)
    with pytest.raises(PacketError, match="bytes"):
        fmt.decode(good[:-1])
    fmt16 = TactileFrameFormat(element_width=2, max_value=1000)
    raw = bytearray(fmt16.encode(np.zeros(64, dtype=int)))
    raw[2:4] = (2000).to_bytes(2, "little")
    with pytest.raises(PacketError, match="max_value"):
        fmt16.decode(raw)
    fmt8 = TactileFrameFormat(checksum="sum8", max_value=100)  # a cap below what one byte holds
    with pytest.raises(ValueError):
        fmt8.encode(np.full(64, 200))
    raw8 = bytearray(fmt8.encode(np.full(64, 100)))
    raw8[2] = 200  # one element over the cap, the checksum made to match
    raw8[-1] = (raw8[-1] + 100) % 256
    with pytest.raises(PacketError, match="element value 200 > max_value 100"):
        fmt8.decode(raw8)


def test_format_validation() -> None:
    with pytest.raises(ValueError):
        TactileFrameFormat(header=b"")
    with pytest.raises(ValueError):
        TactileFrameFormat(element_width=2, length_byte=True, n_elements=200, max_value=300)
    with pytest.raises(ValueError):
        TactileFrameFormat(checksum="md5")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        TactileFrameFormat().encode(np.full(64, 256))


# --------------------------------------------------------------------------- parser
@pytest.mark.parametrize("checksum", ALL_CHECKSUMS)
def test_parser_handles_split_reads_and_garbage(checksum: ChecksumType) -> None:
    fmt = TactileFrameFormat(checksum=checksum)
    frames = [fmt.encode(pattern(k)) for k in range(5)]
    stream = b"\x00\x13garbage\xaa" + frames[0] + frames[1] + b"\x55\xaa\x01" + frames[2] + frames[3] + frames[4]
    p = TactileFrameParser(fmt)
    out = []
    for i in range(0, len(stream), 7):  # arbitrary read boundaries
        got, _errs = p.feed(stream[i : i + 7])
        out += got
    if checksum is ChecksumType.NONE:
        # without a checksum a frame counts once the next header follows it: frame 1 is followed by
        # garbage (unconfirmed, rejected) and frame 4 waits for a successor
        assert len(out) == 3
        for k, v in zip((0, 2, 3), out, strict=True):
            np.testing.assert_array_equal(v, pattern(k))
        assert p.malformed == 1
    else:
        assert len(out) == 5
        for k, v in enumerate(out):
            np.testing.assert_array_equal(v, pattern(k))
        assert p.malformed == 0
    assert p.garbage_bytes > 0


@pytest.mark.parametrize("checksum", [ChecksumType.SUM8, ChecksumType.XOR8, ChecksumType.CRC16_MODBUS])
def test_parser_rejects_bad_checksum_and_short_frames_then_resyncs(checksum: ChecksumType) -> None:
    fmt = TactileFrameFormat(checksum=checksum)
    good = [fmt.encode(pattern(k)) for k in range(4)]
    corrupted = bytearray(fmt.encode(pattern(9)))
    corrupted[20] ^= 0x5A
    short = fmt.encode(pattern(8))[:30]  # truncated on the wire
    stream = good[0] + bytes(corrupted) + good[1] + short + good[2] + good[3]
    p = TactileFrameParser(fmt)
    out, errs = p.feed(stream)
    assert [int(v[0]) for v in out] == [int(pattern(k)[0]) for k in range(4)]
    assert p.malformed >= 2 and len(errs) == p.malformed
    assert all(isinstance(e, PacketError) for e in errs)


def test_parser_without_checksum_detects_length_mismatch() -> None:
    fmt = TactileFrameFormat(length_byte=True)
    bad = bytearray(fmt.encode(pattern(0)))
    bad[2] = 10
    p = TactileFrameParser(fmt)
    out, errs = p.feed(bytes(bad) + fmt.encode(pattern(1)) + fmt.header)  # the next frame's header confirms
    assert len(out) == 1 and len(errs) == 1
    np.testing.assert_array_equal(out[0], pattern(1))


def test_parser_keeps_header_prefix_across_reads() -> None:
    fmt = TactileFrameFormat(checksum="sum8")
    frame = fmt.encode(pattern(2))
    p = TactileFrameParser(fmt)
    assert p.feed(b"junk" + frame[:1]) == ([], [])
    out, _ = p.feed(frame[1:])
    assert len(out) == 1


def test_tactile_frame_helpers() -> None:
    v = np.zeros(64, dtype=np.uint8)
    v[:5] = [10, 0, 200, 255, 1]
    f = TactileFrame(v)
    assert f.contact_count() == 4
    assert f.contact_count(threshold=100) == 2
    assert f.total() == 466


# --------------------------------------------------------------------------- serial reader
@pytest.fixture
def pty_pair() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    name = os.ttyname(slave)
    try:
        yield master, name
    finally:
        os.close(master)
        os.close(slave)


def test_serial_reader_on_pty(pty_pair: tuple[int, str]) -> None:
    master, name = pty_pair
    fmt = TactileFrameFormat(checksum="crc16-modbus", length_byte=True)
    baseline = threading.active_count()
    src = SerialTactileArray(name, 115200, fmt, read_timeout=0.02)
    with src:
        assert threading.active_count() == baseline + 1
        corrupted = bytearray(fmt.encode(pattern(50)))
        corrupted[-1] ^= 0xFF
        chunks = [
            b"\x00\x01\x02noise",
            fmt.encode(pattern(0)),
            bytes(corrupted),  # bad checksum
            fmt.encode(pattern(1))[:40],  # short frame
            b"\xaa",  # lone header byte
            fmt.encode(pattern(2)),
            fmt.encode(pattern(3)),
        ]
        for c in chunks:
            os.write(master, c)
        assert wait_until(lambda: src.latest() is not None and src.latest().seq >= 3)
        latest = src.latest()
        np.testing.assert_array_equal(latest.value.values, pattern(3))
        assert latest.value.values.dtype == np.uint8
        assert not latest.value.values.flags.writeable
        st = src.status()
        assert st.samples == 3
        assert st.malformed >= 2
        assert st.running
        assert src.parser.garbage_bytes > 0
        # staleness: the peer stops sending
        assert src.fresh(1.0)
        time.sleep(0.12)
        assert not src.fresh(0.1)
        os.write(master, fmt.encode(pattern(4)))
        assert wait_until(lambda: src.fresh(0.1))
    assert not src.running
    assert threading.active_count() == baseline


def test_serial_reader_stream_rate_on_pty(pty_pair: tuple[int, str]) -> None:
    master, name = pty_pair
    fmt = TactileFrameFormat(checksum="sum8")
    with SerialTactileArray(name, frame_format=fmt) as src:
        for k in range(40):
            os.write(master, fmt.encode(pattern(k)))
            time.sleep(0.005)
        assert wait_until(lambda: src.status().samples == 40)
        assert src.status().malformed == 0
        assert src.status().rate_hz > 20


def test_serial_reader_with_loop_url() -> None:
    port = serial.serial_for_url("loop://", timeout=0.02)
    fmt = TactileFrameFormat(checksum="xor8")
    with SerialTactileArray(port, frame_format=fmt) as src:
        port.write(b"zz" + fmt.encode(pattern(5)) + b"\xaa\x55\x00" + fmt.encode(pattern(6)))
        assert wait_until(lambda: src.latest() is not None and src.latest().seq >= 2)
        np.testing.assert_array_equal(src.latest().value.values, pattern(6))
    assert not port.is_open


def test_missing_serial_port_names_device(tmp_path: Path) -> None:
    missing = str(tmp_path / "ttyNOPE")
    src = SerialTactileArray(missing)
    with pytest.raises(DeviceOpenError, match="ttyNOPE"):
        src.start()
    assert not src.running


@pytest.mark.parametrize("seed", range(5))
def test_random_bytes_never_make_a_grip_without_a_checksum(seed: int) -> None:
    """Issue 11: line noise and random bytes became grip frames with the default (no checksum) format."""
    fmt = TactileFrameFormat()
    rng = np.random.default_rng(seed)
    noise = rng.integers(0, 256, 2_000_000, dtype=np.uint8).tobytes()  # ~30 chance headers in 2 MB
    p = TactileFrameParser(fmt)
    out: list = []
    for i in range(0, len(noise), 4096):
        out += p.feed(noise[i : i + 4096])[0]
    assert out == [] and p.malformed > 0  # every chance header was a candidate, none confirmed


def test_a_frame_cut_short_without_a_checksum_is_rejected() -> None:
    fmt = TactileFrameFormat()
    frames = [fmt.encode(pattern(k)) for k in range(3)]
    p = TactileFrameParser(fmt)
    out, _ = p.feed(frames[0] + frames[1][:30] + frames[2] + fmt.header)
    assert [int(v[0]) for v in out] == [int(pattern(0)[0]), int(pattern(2)[0])]
