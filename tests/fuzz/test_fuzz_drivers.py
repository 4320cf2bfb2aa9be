"""Property-based fuzzing of the driver parsers (issue 11): F/T records and sequence logic, tactile
frames, camera frames and video files.

The properties: a parser returns a well-formed value or raises its documented error
(:class:`~lapwrench.drivers.base.PacketError`); only plausible values are published; the counters
are honest (never negative, and they add up to what was fed); corruption never becomes a frame when
the format can detect it; a clean stream is recovered whole however it is chunked.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import wait_until
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from lapwrench.buffer import RateMonitor
from lapwrench.drivers.base import DeviceOpenError, PacketError
from lapwrench.drivers.camera import Camera, to_rgb
from lapwrench.drivers.ft import (
    RECORD_SIZE,
    AtiNetFTSensor,
    FTRecord,
    OnRobotHexSensor,
    UdpForceTorqueSensor,
    pack_record,
    unpack_record,
)
from lapwrench.drivers.ft import Wrench as FtWrench
from lapwrench.drivers.tactile import ChecksumType, TactileFrameFormat, TactileFrameParser

U32 = 1 << 32
RESYNC_GAP = 100  # RateMonitor's default

# -- F/T records -----------------------------------------------------------------------------------

int32 = st.integers(-(2**31), 2**31 - 1)
plausible_counts = st.tuples(*[st.integers(-200_000, 200_000)] * 6)  # within 20 N / 2 N m on a HEX
records = st.builds(
    pack_record,
    st.integers(0, U32 - 1),
    st.integers(0, U32 - 1),
    st.one_of(st.just(0), st.integers(0, U32 - 1)),
    st.one_of(plausible_counts, st.tuples(*[int32] * 6)),
)
datagrams = st.one_of(
    records, st.binary(max_size=2 * RECORD_SIZE), st.binary(min_size=RECORD_SIZE, max_size=RECORD_SIZE)
)


@given(st.binary(max_size=80))
def test_unpack_record_returns_a_record_or_a_packet_error(data: bytes) -> None:
    try:
        rec = unpack_record(data)
    except PacketError:
        assert len(data) != RECORD_SIZE
        return
    assert isinstance(rec, FTRecord) and len(data) == RECORD_SIZE
    assert pack_record(rec.sequence, rec.ft_sequence, rec.status, rec.counts) == data


def _feed(sensor: UdpForceTorqueSensor, packets: list[bytes]) -> list[FtWrench]:
    """What the reader thread does with each datagram (no socket); the wrenches published."""
    return [sensor.latest().value for k, data in enumerate(packets) if sensor.feed(data, float(k))]


def _check_published(sensor: UdpForceTorqueSensor, n_fed: int) -> None:
    st_ = sensor.status()
    assert min(st_.samples, st_.malformed, st_.drops, st_.out_of_order, st_.io_errors) >= 0
    # every datagram is exactly one of: published, malformed, discarded by the sequence logic
    assert st_.samples + st_.malformed + st_.out_of_order == n_fed
    assert st_.drops <= (RESYNC_GAP - 1) * st_.samples
    latest = sensor.latest()
    if latest is not None:
        w = latest.value
        assert np.isfinite(w.force).all() and np.isfinite(w.torque).all()
        assert np.linalg.norm(w.force) <= sensor.max_force and np.linalg.norm(w.torque) <= sensor.max_torque
        assert w.status & sensor.status_error_mask == 0


@given(st.sampled_from([OnRobotHexSensor, AtiNetFTSensor]), st.lists(datagrams, max_size=30))
def test_ft_sensor_publishes_only_plausible_wrenches_and_counts_honestly(cls: type, packets: list[bytes]) -> None:
    sensor = cls("127.0.0.1", 9)  # never started: datagrams are handed over directly
    published = _feed(sensor, packets)  # never tared: the published wrench is the raw one
    _check_published(sensor, len(packets))
    assert sensor.status().samples == len(published)
    for w in published:
        assert np.isfinite(w.force).all() and np.isfinite(w.torque).all()
        assert np.linalg.norm(w.force) <= sensor.max_force and np.linalg.norm(w.torque) <= sensor.max_torque


@given(
    seq0=st.one_of(st.integers(0, U32 - 1), st.integers(U32 - 20, U32 - 1)),  # wrap-around included
    n=st.integers(2, 40),
    at=st.integers(0, 40),
    bad=records,
)
@example(seq0=10, n=20, at=5, bad=pack_record(10 + 5 + 90, 0, 0, [0] * 6))  # a near jump: cost 15 good records
@example(seq0=0, n=20, at=0, bad=pack_record(500, 0, 0, [0] * 6))  # a bad first number: cost 20 good records
@example(seq0=U32 - 3, n=10, at=2, bad=pack_record(900, 0, 0, [0] * 6))  # a far jump across the wrap
def test_one_bad_record_costs_at_most_one_good_record(seq0: int, n: int, at: int, bad: bytes) -> None:
    """A clean stream (any start, across the 32-bit wrap) with one arbitrary record slipped in."""
    sensor = OnRobotHexSensor("127.0.0.1", 9)
    clean = [pack_record((seq0 + i) % U32, i, 0, [i, 0, 0, 0, 0, 0]) for i in range(n)]
    at = min(at, n)
    packets = [*clean[:at], bad, *clean[at:]]
    seen = [w.ft_sequence for w in _feed(sensor, packets)]
    good = [s for s in seen if s in range(n)]
    assert len(set(good)) >= n - 1, f"the bad record cost {n - len(set(good))} good records"
    rm = sensor.rate.stats()
    # first or last, the bad record cannot be told from a good one next to a loss; in between it can
    assert rm.drops <= (RESYNC_GAP - 1 if at in (0, n) else 0)


@given(st.integers(0, U32 - 1), st.lists(st.integers(1, 150), max_size=30))
def test_rate_monitor_counts_gaps_across_the_wrap(seq0: int, steps: list[int]) -> None:
    """A stream going forward only: every step up to the resync gap is accepted and counted exactly."""
    rm = RateMonitor()
    assert rm.check_seq(seq0)
    seq, drops = seq0, 0
    for step in steps:
        seq = (seq + step) % U32
        if rm.check_seq(seq):
            drops += step - 1
    st_ = rm.stats()
    if all(s <= RESYNC_GAP for s in steps):
        assert st_.drops == drops and st_.out_of_order == 0
    assert 0 <= st_.drops <= (RESYNC_GAP - 1) * len(steps)


@given(st.lists(st.integers(0, U32 - 1) | st.integers(0, 300), max_size=60))
def test_rate_monitor_counters_stay_honest(seqs: list[int]) -> None:
    rm = RateMonitor()
    accepted = sum(rm.check_seq(s) for s in seqs)
    st_ = rm.stats()
    assert accepted + st_.out_of_order == len(seqs)
    assert 0 <= st_.drops <= (RESYNC_GAP - 1) * accepted
    assert 0 <= st_.resyncs <= accepted


@given(st.lists(st.floats(0.0, 1e6), max_size=50), st.floats(0.1, 1000.0))
def test_rate_monitor_rate_is_finite_and_non_negative(times: list[float], rate_hz: float) -> None:
    rm = RateMonitor(expected_rate_hz=rate_hz)
    for t in times:
        rm.tick(t)
    st_ = rm.stats(now=max(times, default=0.0))
    assert np.isfinite(st_.rate_hz) and st_.rate_hz >= 0.0
    assert st_.count == len(times) and 0 <= st_.late <= max(len(times) - 1, 0)


# -- tactile frames --------------------------------------------------------------------------------

formats = st.builds(
    TactileFrameFormat,
    header=st.sampled_from([b"\xaa\x55", b"\xa5\x5a\x01", b"\x7e"]),
    n_elements=st.sampled_from([1, 4, 64]),
    element_width=st.sampled_from([1, 2]),
    byteorder=st.sampled_from(["little", "big"]),
    length_byte=st.booleans(),
    checksum=st.sampled_from(list(ChecksumType)),
    checksum_includes_header=st.booleans(),
    max_value=st.sampled_from([255]),
)


@st.composite
def streams(draw: st.DrawFn, fmt_strategy: st.SearchStrategy[TactileFrameFormat] = formats) -> tuple:
    """A format, the frames' values and their encoding (with the confirming header without a checksum)."""
    fmt = draw(fmt_strategy)
    values = draw(st.lists(hnp.arrays(np.int64, fmt.n_elements, elements=st.integers(0, fmt.max_value)),
                           min_size=1, max_size=6))
    data = b"".join(fmt.encode(v) for v in values)
    if fmt.checksum is ChecksumType.NONE:
        data += fmt.header  # a frame without a checksum counts once the next header follows it
    return fmt, values, data


def _chunks(draw: st.DrawFn, data: bytes) -> list[bytes]:
    cuts = sorted(draw(st.lists(st.integers(0, len(data)), max_size=8)))
    return [data[a:b] for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True)]


def _feed_all(parser: TactileFrameParser, chunks: list[bytes]) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    for c in chunks:
        frames, errors = parser.feed(c)
        assert all(isinstance(e, PacketError) for e in errors)
        out += frames
    return out


def _check_counters(parser: TactileFrameParser, fed: int) -> None:
    """Every byte fed is in exactly one place: a frame, garbage, a rejected candidate's first byte, the buffer."""
    assert min(parser.frames, parser.malformed, parser.garbage_bytes) >= 0
    assert parser.frames * parser.fmt.frame_size + parser.garbage_bytes + parser.malformed + parser.pending == fed


@given(streams(), st.data())
def test_a_clean_tactile_stream_is_recovered_whole_however_it_is_chunked(stream: tuple, data: st.DataObject) -> None:
    fmt, values, raw = stream
    parser = TactileFrameParser(fmt)
    out = _feed_all(parser, _chunks(data.draw, raw))
    assert [v.tolist() for v in out] == [v.tolist() for v in values]
    assert parser.malformed == 0 and parser.garbage_bytes == 0
    _check_counters(parser, len(raw))


def _is_subsequence(sub: list[list[int]], seq: list[list[int]]) -> bool:
    it = iter(seq)
    return all(any(s == x for x in it) for s in sub)


@given(streams(formats.filter(lambda f: f.checksum is not ChecksumType.NONE and len(f.header) > 1)), st.data())
def test_a_corrupted_byte_never_becomes_a_frame_with_a_checksum(stream: tuple, data: st.DataObject) -> None:
    """One byte changed anywhere: that frame is rejected (sum8, xor8 and CRC all catch one byte), the others kept."""
    fmt, values, raw = stream
    pos = data.draw(st.integers(0, len(raw) - 1))
    new = data.draw(st.integers(0, 255).filter(lambda b: b != raw[pos]))
    bad = raw[:pos] + bytes([new]) + raw[pos + 1 :]
    parser = TactileFrameParser(fmt)
    out = [v.tolist() for v in _feed_all(parser, _chunks(data.draw, bad))]
    hit = pos // fmt.frame_size
    expected = [v.tolist() for i, v in enumerate(values) if i != hit]
    assert out == expected
    assert parser.malformed + parser.garbage_bytes > 0
    _check_counters(parser, len(bad))


@given(
    streams(st.one_of(formats.filter(lambda f: f.checksum is ChecksumType.CRC16_MODBUS and len(f.header) > 1),
                      formats.filter(lambda f: f.checksum is ChecksumType.NONE and len(f.header) > 1))),
    st.data(),
)
def test_cut_or_noise_never_becomes_a_frame(stream: tuple, data: st.DataObject) -> None:
    """Bytes cut out of the stream, or line noise inserted (no header in it): every frame out was sent."""
    fmt, values, raw = stream
    a = data.draw(st.integers(0, len(raw) - 1))
    b = data.draw(st.integers(a + 1, min(len(raw), a + fmt.frame_size)))
    noise = data.draw(st.binary(min_size=1, max_size=40).filter(lambda n: fmt.header not in n))
    bad = raw[:a] + raw[b:] if data.draw(st.booleans()) else raw[:a] + noise + raw[a:]
    parser = TactileFrameParser(fmt)
    out = [v.tolist() for v in _feed_all(parser, _chunks(data.draw, bad))]
    assert _is_subsequence(out, [v.tolist() for v in values]), "a frame that was never sent"
    _check_counters(parser, len(bad))


@given(formats, st.lists(st.binary(max_size=300), max_size=6))
@example(TactileFrameFormat(), [b"\xaa\x55" + bytes(64) + b"\xaa"])  # no checksum, header cut: unconfirmed
def test_random_bytes_give_only_frames_that_are_in_them(fmt: TactileFrameFormat, chunks: list[bytes]) -> None:
    """Line noise: a frame out is one whose exact bytes (and, without a checksum, the next header) were fed."""
    parser = TactileFrameParser(fmt)
    fed = b"".join(chunks)
    out = _feed_all(parser, chunks)
    confirm = fmt.header if fmt.checksum is ChecksumType.NONE else b""
    for v in out:
        assert v.shape == (fmt.n_elements,) and v.min() >= 0 and v.max() <= fmt.max_value
        assert fmt.encode(v) + confirm in fed
    _check_counters(parser, len(fed))


# -- camera ----------------------------------------------------------------------------------------

image_dtypes = st.sampled_from([np.uint8, np.uint16, np.float32, np.int8, np.bool_])


@given(st.one_of(
    hnp.arrays(image_dtypes, hnp.array_shapes(min_dims=1, max_dims=4, min_side=0, max_side=6)),
    hnp.arrays(np.uint8, st.tuples(st.integers(0, 5), st.integers(0, 5), st.integers(0, 5))),
    hnp.arrays(np.uint8, st.tuples(st.integers(1, 5), st.integers(1, 8), st.sampled_from([1, 3, 4])))
    .map(lambda a: a[:, ::2]),  # a strided view
    st.sampled_from([None, [[1, 2, 3]], "frame", 3]),
), st.sampled_from([None, (4, 3), (3, 4)]))
def test_to_rgb_returns_an_rgb_image_or_a_packet_error(frame: object, size: tuple[int, int] | None) -> None:
    try:
        rgb = to_rgb(frame, size)
    except PacketError:
        return
    assert isinstance(frame, np.ndarray)
    assert rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[2] == 3 and rgb.flags.c_contiguous
    assert rgb.shape[:2] == frame.shape[:2] and rgb.size > 0
    assert size is None or (rgb.shape[1], rgb.shape[0]) == size


VW, VH, VN = 32, 24, 8


@pytest.fixture(scope="module")
def clean_video(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """The bytes of an 8-frame 32x24 MJPG .avi."""
    path = tmp_path_factory.mktemp("video") / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (VW, VH))
    assert writer.isOpened(), "OpenCV cannot write MJPG AVI"
    for k in range(VN):
        img = np.zeros((VH, VW, 3), np.uint8)
        img[:, :, 2], img[:, :, 1] = 220, k * 25
        writer.write(img)
    writer.release()
    return path.read_bytes()


def _play(path: Path) -> Camera | None:
    """Run the grabber on the file (unpaced) until its reader thread reaches the end, or stops."""
    try:
        cam = Camera(path, pace=False, expected_size=(VW, VH)).start()
    except DeviceOpenError:
        return None
    try:
        wait_until(lambda: cam.status().finished or not cam.running, timeout=10.0)
    finally:
        cam.stop()
    return cam


@settings(max_examples=20)
@given(data=st.data())
def test_a_truncated_or_corrupted_video_is_counted(clean_video: bytes, data: st.DataObject,
                                                   tmp_path_factory: pytest.TempPathFactory) -> None:
    movi = clean_video.find(b"movi")
    assume(movi > 0)
    if data.draw(st.booleans(), label="truncate"):
        cut = data.draw(st.integers(movi + 4, len(clean_video) - 1), label="cut at")
        bad = clean_video[:cut]
    else:
        at = data.draw(st.integers(movi + 4, len(clean_video) - 1), label="corrupt at")
        junk = data.draw(st.binary(min_size=1, max_size=64), label="junk")
        bad = clean_video[:at] + junk + clean_video[at + len(junk) :]
    path = tmp_path_factory.mktemp("bad") / "bad.avi"
    path.write_bytes(bad)
    cam = _play(path)
    if cam is None:
        return  # refused at open, with DeviceOpenError naming the file
    st_ = cam.status()
    assert cam.status().finished, "the read loop did not reach the end of the file"
    assert 1 <= st_.samples <= VN and min(st_.malformed, st_.drops, st_.io_errors) >= 0
    assert st_.drops <= VN
    frame = cam.latest().value
    assert frame.image.shape == (VH, VW, 3) and frame.image.dtype == np.uint8
    if st_.samples < VN:
        assert st_.malformed >= 1 and st_.last_error, "the video ended early and nothing was reported"
