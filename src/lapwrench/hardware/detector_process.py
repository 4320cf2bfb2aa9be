"""The instrument detector in its own process: frames in through shared memory, points out.

The parent copies each new camera frame into a frame slot (a :class:`~lapwrench.hardware.shm.SeqlockSlot`
of ``height x width x 3`` uint8 in a block of its own, stamped with the frame's capture time); the
detector process copies the newest frame out, runs the detector and writes the image points (at
most :data:`~lapwrench.hardware.rt.MAX_POINTS`, in the detector's order, finite only) into
the real-time bus's ``instruments`` slot, stamped with the *frame's* time so the control loop's
age check covers capture + detection latency. It beats its heartbeat on the bus each iteration;
the real-time process watches that heartbeat and the detector's pid (see
:mod:`lapwrench.hardware.rt`).

The detector is built in the child from a picklable ``factory()`` (a module-level function or a
``functools.partial``), e.g. :func:`shipped_factory` or :func:`spec_factory`.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np

from lapwrench.buffer import LatestValue
from lapwrench.hardware.rt import (
    BEAT_DETECTOR,
    CTL_DET_ERRORS,
    CTL_DET_FRAMES,
    CTL_DET_STOP,
    MAX_POINTS,
    RtOptions,
    RtProcessError,
    apply_realtime,
    bus_layout,
)
from lapwrench.hardware.shm import Bus, Layout
from lapwrench.spawn import quiet_process, start_quiet

__all__ = ["DetectorProcess", "frame_layout", "shipped_factory", "spec_factory"]


def frame_layout(size: tuple[int, int]) -> Layout:
    """One RGB frame slot of ``size = (width, height)``."""
    w, h = size
    return Layout().slot("frame", np.uint8, (h, w, 3))


def shipped_factory(size: tuple[int, int] = (640, 480), num_threads: int = 1, test_time_flip: bool = True) -> Any:
    """The shipped ONNX model (:func:`lapwrench.perception.shipped_detector`), ``num_threads`` intra-op threads."""
    from lapwrench.perception import SHIPPED_MODEL, DetectorConfig, OnnxYoloDetector

    return OnnxYoloDetector(
        SHIPPED_MODEL, DetectorConfig(frame_size=size), num_threads=num_threads, test_time_flip=test_time_flip
    )


def spec_factory(spec: str, size: tuple[int, int] = (640, 480)) -> Any:
    """``make_detector(spec)`` ("classical", a ``.onnx`` or ``.pt`` path) for frames of ``size``."""
    from lapwrench.perception import DetectorConfig, make_detector

    return make_detector(spec, DetectorConfig(frame_size=size))


def _points(dets: Any) -> np.ndarray:
    pts = np.array([[d.u, d.v] for d in dets], dtype=float).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    return pts[:MAX_POINTS]


def _detector_main(
    factory: Callable[[], Any],
    frame_name: str,
    size: tuple[int, int],
    bus_name: str,
    bus_rows: tuple[int, int],
    conn: Any,
    poll_s: float,
    nice: int,
    cpus: tuple[int, ...] | None,
) -> None:
    # the parent stops it: Ctrl-C and a closed terminal reach the whole process group
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    frames = bus = None
    try:
        if nice:
            with contextlib.suppress(OSError):
                os.nice(nice)
        problems = apply_realtime(RtOptions(fifo_priority=None, cpus=cpus, gc_freeze=False, warn=False))
        frames = Bus.attach(frame_name, frame_layout(size))
        bus = Bus.attach(bus_name, bus_layout(*bus_rows))
        ctl, beat = bus["ctl"], bus["beat"]
        slot, out = frames.slot("frame"), bus.slot("instruments")
        detector = factory()
        w, h = size
        detector.detect(np.zeros((h, w, 3), np.uint8))  # warm-up (session, allocations) before "ready"
        beat[BEAT_DETECTOR] = time.monotonic()
        conn.send(("ready", {"pid": os.getpid(), "problems": problems, "detector": type(detector).__name__}))
        buf = np.empty_like(slot.data)
        last = 0
        parent = mp.parent_process()
        while not ctl[CTL_DET_STOP]:
            beat[BEAT_DETECTOR] = time.monotonic()
            r = slot.read_into(buf)
            if r is None or r[0] == last:
                if parent is not None and not parent.is_alive():
                    break
                time.sleep(poll_s)
                continue
            last, stamp, _ = r
            try:
                pts = _points(detector.detect(buf))
            except Exception:  # a failing detection leaves the points stale, never kills the process
                ctl[CTL_DET_ERRORS] += 1
                continue
            out.write(pts, stamp, count=len(pts))
            ctl[CTL_DET_FRAMES] += 1
    except BaseException as exc:
        with contextlib.suppress(Exception):
            conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"))
    finally:
        for b in (frames, bus):
            if b is not None:
                b.close()


class DetectorProcess:
    """Runs ``factory()``'s detector in a spawned process on frames published by this one.

    Args:
        factory: Builds the detector in the child (picklable).
        bus_name: The real-time bus (:attr:`RtProcess.bus_name` or a :class:`Bus` of
            :func:`~lapwrench.hardware.rt.bus_layout`), where the points go.
        size: Frame size ``(width, height)``.
        bus_rows: The bus layout's ``(log_rows, event_rows)``.
        poll_s: The child's sleep when no new frame is there.
        nice: Niceness added in the child (perception below the control loop); 0 leaves it.
        cpus: CPUs to pin the detector to (``None``: don't pin).
    """

    def __init__(
        self,
        factory: Callable[[], Any],
        bus_name: str,
        size: tuple[int, int] = (640, 480),
        *,
        bus_rows: tuple[int, int] = (4096, 1024),
        poll_s: float = 0.002,
        nice: int = 0,
        cpus: tuple[int, ...] | None = None,
    ) -> None:
        self.factory = factory
        self.bus_name = bus_name
        self.size = size
        self.bus_rows = bus_rows
        self.poll_s = poll_s
        self.nice = nice
        self.cpus = cpus
        self.frames = Bus.create(frame_layout(size))
        self._slot = self.frames.slot("frame")
        self._bus = Bus.attach(bus_name, bus_layout(*bus_rows))
        self.proc: Any = None
        self._conn: Any = None
        self._fwd_stop = threading.Event()
        self._fwd: threading.Thread | None = None
        self.info: dict[str, Any] = {}

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.exitcode is None

    @property
    def frames_done(self) -> int:
        return int(self._bus["ctl"][CTL_DET_FRAMES])

    @property
    def errors(self) -> int:
        return int(self._bus["ctl"][CTL_DET_ERRORS])

    def start(self, timeout: float = 120.0) -> DetectorProcess:
        """Spawn the process and wait until its detector is loaded and warmed up.

        Raises:
            RtProcessError: it failed (the detector could not be built) or died.
        """
        ctx = mp.get_context("spawn")
        parent_conn, child_conn = ctx.Pipe()
        self._conn = parent_conn
        self._bus["ctl"][CTL_DET_STOP] = 0
        self.proc = quiet_process(
            ctx,
            _detector_main,
            (
                self.factory, self.frames.name, self.size, self.bus_name, self.bus_rows, child_conn, self.poll_s,
                self.nice, self.cpus,
            ),
            name="lapwrench-detector",
            daemon=True,
        )
        start_quiet(self.proc)  # Ctrl-C is this process's to handle: it stops the detector
        child_conn.close()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if parent_conn.poll(0.05):
                try:
                    msg = parent_conn.recv()
                except (EOFError, OSError):
                    msg = ("error", "the detector process closed its pipe")
                if msg[0] == "ready":
                    self.info = msg[1]
                    return self
                self.stop()
                raise RtProcessError(f"the detector process failed to start: {msg[1]}")
            if self.proc.exitcode is not None:
                code = self.proc.exitcode
                self.stop()
                raise RtProcessError(f"the detector process exited during start-up (exit code {code})")
        self.stop()
        raise RtProcessError(f"the detector process did not get ready within {timeout:.0f} s")

    def publish(self, image: np.ndarray, stamp: float | None = None) -> None:
        """Copy one RGB frame (of :attr:`size`) into the frame slot, stamped ``stamp`` (monotonic s)."""
        self._slot.write(image, time.monotonic() if stamp is None else stamp)

    def forward(self, frames: LatestValue[Any], poll_s: float = 0.005) -> DetectorProcess:
        """Copy every new camera sample (values with an ``image``) into the frame slot, from a thread."""

        def run() -> None:
            last = 0
            while not self._fwd_stop.wait(poll_s):
                s = frames.get()
                if s is None or s.seq == last:
                    continue
                last = s.seq
                with contextlib.suppress(Exception):  # a frame of the wrong size is not forwarded
                    self.publish(s.value.image, s.timestamp)

        self._fwd = threading.Thread(target=run, name="lapwrench-frame-forward", daemon=True)
        self._fwd.start()
        return self

    def stop(self, timeout: float = 3.0) -> None:
        """Stop the forwarder and the process (stop flag, then SIGKILL), free the frame block. Idempotent."""
        self._fwd_stop.set()
        if self._fwd is not None:
            self._fwd.join(1.0)
            self._fwd = None
        if self.proc is not None:
            with contextlib.suppress(Exception):
                self._bus["ctl"][CTL_DET_STOP] = 1
            self.proc.join(timeout)
            if self.proc.exitcode is None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(self.proc.pid, signal.SIGKILL)
                self.proc.join(2.0)
        if self._conn is not None:
            with contextlib.suppress(Exception):
                self._conn.close()
            self._conn = None
        self.frames.close()
        self._bus.close()

    def __enter__(self) -> DetectorProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

