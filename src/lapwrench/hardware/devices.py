"""The devices of ``lapwrench run``: parsing their specs, opening and checking them, and the simulated
ones of ``--dry-run`` / ``--frankysim`` (the scripted surgeon, a simulated F/T box in its own process,
a simulated tactile array on a pty)."""

from __future__ import annotations

import argparse
import contextlib
import functools
import math
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from lapwrench.drivers.ft import wire_counts
from lapwrench.spawn import quiet_process, start_quiet


class CliError(Exception):
    """An argument or device problem reported as ``lapwrench run: <message>`` with exit code 2."""


# -- device specs -------------------------------------------------------------------------------
def parse_ft_url(url: str) -> tuple[str, str, int]:
    """``hex://HOST[:PORT]`` / ``ati://HOST[:PORT]`` → (kind, host, port); port 1-65535, default 49152."""
    shown = url if len(url) <= 60 else url[:60] + "..."
    try:
        parts = urlsplit(url)
        host, port = parts.hostname, parts.port
    except ValueError as exc:  # a malformed address (``hex://[zz``) or a port out of range
        raise CliError(f"--ft {shown!r}: not a valid HOST[:PORT] (port 1 to 65535)") from exc
    if parts.scheme not in ("hex", "ati") or not host:
        raise CliError(f"--ft must be hex://HOST[:PORT] or ati://HOST[:PORT], got {shown!r}")
    if port == 0:
        raise CliError(f"--ft {shown!r}: port must be 1 to 65535")
    return parts.scheme, host, port or 49152


def parse_camera(spec: str) -> int | str:
    """A device index for digits, otherwise the file path or URL."""
    return int(spec) if spec.isdigit() else spec


TACTILE_CHECKSUMS = ("none", "sum8", "xor8", "crc16-modbus")


def tactile_format(args: argparse.Namespace, cfg: Any) -> Any:
    """The tactile array's :class:`~lapwrench.drivers.tactile.TactileFrameFormat`: the config's
    ``tactile`` section (header, checksum, length byte, checksum over the header), with
    ``--tactile-header`` / ``--tactile-checksum`` taking precedence when given.

    The same format goes to the reader and, in a dry run, to the simulated array's writer, so any
    format runs end to end. Raises :class:`CliError` for a format the driver refuses.
    """
    from lapwrench.drivers.tactile import TactileFrameFormat

    section = getattr(cfg, "tactile", None)  # absent in configurations older than the tactile section
    default = TactileFrameFormat()
    header = getattr(args, "tactile_header", None)
    if header is None:
        text = getattr(section, "header", None)
        try:
            header = default.header if text is None else bytes.fromhex(str(text))
        except ValueError as exc:
            raise CliError(f"tactile.header must be bytes in hex, e.g. AA55, got {str(text)[:60]!r}") from exc
    checksum = getattr(args, "tactile_checksum", None) or getattr(section, "checksum", None) or default.checksum
    try:
        return TactileFrameFormat(
            header=header,
            checksum=checksum,
            length_byte=bool(getattr(section, "length_byte", default.length_byte)),
            checksum_includes_header=bool(
                getattr(section, "checksum_includes_header", default.checksum_includes_header)
            ),
        )
    except ValueError as exc:
        raise CliError(f"tactile frame format: {exc}") from exc


# -- the dry-run script ---------------------------------------------------------------------------
@dataclass
class DryRunScript:
    """The scripted surgeon of ``--dry-run`` (times in s since the script's start, wall clock).

    The handle is untouched for ``tare_s`` (the F/T tare happens then), gripped from ``grip[0]`` to
    ``grip[1]``, and pushed with the force segments ``(t_start, t_end, force in {H})``.
    """

    tare_s: float = 1.0
    grip: tuple[float, float] = (1.2, 5.8)
    grip_value: int = 40
    pushes: list[tuple[float, float, tuple[float, float, float]]] = field(
        default_factory=lambda: [(1.5, 3.5, (6.0, 0.0, 0.0)), (4.0, 5.5, (0.0, -5.0, 0.0))]
    )
    t0: float = field(default_factory=time.monotonic)

    def now(self) -> float:
        return time.monotonic() - self.t0

    def force_H(self, t: float | None = None) -> np.ndarray:
        t = self.now() if t is None else t
        for a, b, f in self.pushes:
            if a <= t < b:
                return np.array(f, dtype=float)
        return np.zeros(3)

    def tactile(self, t: float | None = None) -> np.ndarray:
        t = self.now() if t is None else t
        on = self.grip[0] <= t < self.grip[1]
        return np.full(64, self.grip_value if on else 0, dtype=np.uint8)


class TactileWriter:
    """Writes tactile frames of a script to a pty master at ``rate_hz`` (the simulated grip array)."""

    def __init__(
        self, fd: int, values: Callable[[], np.ndarray], rate_hz: float = 200.0, fmt: Any = None
    ) -> None:
        from lapwrench.drivers.tactile import TactileFrameFormat

        self.fd = fd
        self.values = values
        self.period = 1.0 / rate_hz
        self.fmt = fmt if fmt is not None else TactileFrameFormat()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lapwrench-sim-tactile", daemon=True)

    def start(self) -> TactileWriter:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            with contextlib.suppress(OSError):
                os.write(self.fd, self.fmt.encode(self.values()))
            self._stop.wait(self.period)


# -- opened devices ---------------------------------------------------------------------------------
class Devices:
    """Opened devices, closed in reverse order."""

    def __init__(self) -> None:
        self._closers: list[Callable[[], None]] = []

    def add(self, closer: Callable[[], None]) -> None:
        self._closers.append(closer)

    def close(self) -> None:
        while self._closers:
            with contextlib.suppress(Exception):
                self._closers.pop()()


def open_sources(
    args: argparse.Namespace, cfg: Any, devices: Devices, script: DryRunScript | None
) -> tuple[Any, dict[str, str]]:
    """Open, check and start every sensor source; return (Sources, device descriptions).

    The camera's frames must have the size of the configured intrinsics (``camera.width`` x
    ``camera.height``), which the tracking wrench projects with: a mismatch fails at start.
    """
    from lapwrench.drivers import AtiNetFTSensor, DeviceError, OnRobotHexSensor, SerialTactileArray
    from lapwrench.hardware.runner import DetectorWorker, Sources

    sources = Sources()
    described: dict[str, str] = {}
    ft_url, tactile_port = args.ft, args.tactile
    fmt = getattr(args, "tactile_frame_format", None) or tactile_format(args, cfg)
    if script is not None:
        from lapwrench.drivers.simulated_hex import SimulatedHexBox

        def counts(_i: int) -> np.ndarray:
            return _hex_counts(script.force_H())

        fake = SimulatedHexBox(rate_hz=1000.0, counts_fn=counts).start()
        devices.add(fake.close)
        ft_url = f"hex://127.0.0.1:{fake.port}"
        master, slave = os.openpty()
        devices.add(lambda: os.close(slave))  # closed in reverse order: the master first
        devices.add(lambda: os.close(master))
        writer = TactileWriter(master, script.tactile, fmt=fmt).start()
        devices.add(writer.stop)
        tactile_port = os.ttyname(slave)
    try:
        if ft_url:
            kind, host, port = parse_ft_url(ft_url)
            cls = OnRobotHexSensor if kind == "hex" else AtiNetFTSensor
            ft = cls(host, port)
            ft.start()
            devices.add(ft.stop)
            if not args.no_tare:
                ft.tare(n_samples=100)
            sources.ft = ft.buffer
            described["ft"] = ft.device
        if tactile_port:
            tac = SerialTactileArray(tactile_port, args.tactile_baud, fmt)
            tac.start()
            devices.add(tac.stop)
            if tac.buffer.wait_newer(0, timeout=2.0) is None:
                raise DeviceError(tac.device, "no valid tactile frame within 2 s (format or baud rate?)")
            sources.tactile = tac.buffer
            described["tactile"] = tac.device
        if args.camera is not None:
            from lapwrench.drivers.camera import Camera
            from lapwrench.perception import DetectorConfig, PerceptionError, make_detector

            size = (cfg.camera.width, cfg.camera.height)
            cam = Camera(parse_camera(args.camera), loop=True, expected_size=size)
            cam.start()
            devices.add(cam.stop)
            try:
                detector = make_detector(args.detector or "classical", DetectorConfig(frame_size=size))
            except (PerceptionError, ImportError) as exc:
                raise CliError(f"instrument detector {args.detector!r}: {exc}") from exc
            worker = DetectorWorker(cam.buffer, detector).start()
            devices.add(worker.stop)
            sources.instruments = worker.buffer
            described["camera"] = cam.device
    except DeviceError as exc:
        raise CliError(f"device not ready: {exc}") from exc
    for name, (spec, buffer) in open_registered_inputs(cfg, devices, described).items():
        sources.extra[name] = (buffer, spec.max_age)
    return sources, described


def open_registered_inputs(cfg: Any, devices: Devices, described: dict[str, str]) -> dict[str, tuple[Any, Any]]:
    """Start the driver of every registered input the configured cues ask for (``InputSpec.open``, in
    this process); return name → (its spec, its latest-value buffer). A driver that fails to start, or
    an input without one, is a :class:`CliError` naming the input."""
    from lapwrench.config_ranges import ConfigError
    from lapwrench.wrenches.registry import build_cues, input_specs

    try:
        specs = input_specs(build_cues(cfg))
    except ConfigError as exc:
        raise CliError(str(exc)) from exc
    out: dict[str, tuple[Any, Any]] = {}
    for name, spec in specs.items():
        if spec.open is None:
            raise CliError(f"input {name!r} has no driver for the robot (its InputSpec.open is None)")
        try:
            driver = spec.open(cfg)
        except Exception as exc:  # a plugin's driver: its failure is the user's to see, in one line
            raise CliError(f"input {name!r}: its driver failed to start: {type(exc).__name__}: {exc}") from exc
        devices.add(driver.close)
        out[name] = (spec, driver.buffer)
        described[name] = str(getattr(driver, "device", f"{name} driver"))
    return out


# -- the simulated F/T box in its own process, and the dry run's simulated devices ------------------
def _hex_counts(force: Any) -> np.ndarray:
    """Raw counts (:data:`~lapwrench.drivers.ft.WIRE_ORDER`) of a HEX box for a hand force (N), no torque."""
    return wire_counts(force, counts_per_force=10000.0, counts_per_torque=100000.0)


def _force_counts(force_fn: Callable[[float], Any], t0: Any, _i: int) -> np.ndarray:
    return _hex_counts(force_fn(time.monotonic() - t0.value))


def _simulated_hex_main(
    force_fn: Callable[[float], Any], t0: Any, rate_hz: float, conn: Any, fifo_priority: int | None = None
) -> None:
    import multiprocessing as mp

    from lapwrench.drivers.simulated_hex import SimulatedHexBox

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops it: Ctrl-C and a closed terminal
    signal.signal(signal.SIGHUP, signal.SIG_IGN)  # reach the whole process group
    # it stands for a device with a CPU of its own: fifo_priority keeps it off our CPU contention
    dev = SimulatedHexBox(
        rate_hz=rate_hz, counts_fn=functools.partial(_force_counts, force_fn, t0), fifo_priority=fifo_priority
    ).start()
    try:
        conn.send(dev.port)
        parent = mp.parent_process()
        while not conn.poll(0.1):
            if parent is not None and not parent.is_alive():
                break
    finally:
        dev.close()


class SimulatedHexProcess:
    """A simulated OnRobot HEX box (:class:`~lapwrench.drivers.simulated_hex.SimulatedHexBox`, 10000 counts/N) in
    its own process, streaming ``force_fn(t)`` (N, in {H}) at ``rate_hz`` on 127.0.0.1; ``t`` counts
    from :meth:`set_t0` (before it, ``-inf``). A real box does not share this process's interpreter,
    so neither does this one (its sends are not delayed by this process's threads). ``fifo_priority``
    (when permitted) keeps the simulated box off our own CPU contention, as a real box has its own CPU."""

    def __init__(
        self, force_fn: Callable[[float], Any], rate_hz: float = 1000.0, fifo_priority: int | None = None
    ) -> None:
        import multiprocessing as mp

        self.ctx = mp.get_context("spawn")
        self.t0 = self.ctx.RawValue("d", math.inf)
        self.force_fn = force_fn
        self.rate_hz = rate_hz
        self.fifo_priority = fifo_priority
        self.proc: Any = None
        self.port = 0
        self._conn: Any = None

    def start(self, timeout: float = 30.0) -> SimulatedHexProcess:
        self._conn, child = self.ctx.Pipe()
        self.proc = quiet_process(
            self.ctx,
            _simulated_hex_main,
            (self.force_fn, self.t0, self.rate_hz, child, self.fifo_priority),
            name="lapwrench-simulated-hex",
            daemon=True,
        )
        start_quiet(self.proc)  # Ctrl-C is this process's to handle: it stops the box
        child.close()
        if not self._conn.poll(timeout):
            self.close()
            raise CliError("the simulated F/T box did not start")
        self.port = int(self._conn.recv())
        return self

    def set_t0(self, t0: float) -> None:
        self.t0.value = t0

    def close(self) -> None:
        if self.proc is None:
            return
        with contextlib.suppress(Exception):
            self._conn.send("stop")
        self.proc.join(3.0)
        if self.proc.exitcode is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.join(2.0)
        with contextlib.suppress(Exception):
            self._conn.close()
        self.proc = None


def _simulated_devices(
    devices: Devices, script: DryRunScript, fmt: Any = None
) -> tuple[str, str, SimulatedHexProcess]:
    """The dry run's F/T box (loopback UDP, own process) and tactile array (a pty) writing frames of
    ``fmt`` (default: the driver's default format; pass the reader's format)."""
    fake = SimulatedHexProcess(script.force_H).start()
    devices.add(fake.close)
    master, slave = os.openpty()
    devices.add(lambda: os.close(slave))  # closed in reverse order: the master first
    devices.add(lambda: os.close(master))
    writer = TactileWriter(master, script.tactile, fmt=fmt).start()
    devices.add(writer.stop)
    return f"hex://127.0.0.1:{fake.port}", os.ttyname(slave), fake
