"""franky-sim on loopback: a real libfranka-protocol server in a separate process, for tests and benchmarks.

franky-sim (PyPI) simulates an FR3 in MuJoCo behind the libfranka network protocol (TCP command
port 1337 + UDP state/command stream), so pylibfranka talks to it exactly as it talks to a robot.

Facts that matter (probed with franky-sim 1.0.4 / pylibfranka 0.21.3):

* The server must run in **another process**: in the same process the pylibfranka client and the
  Python server thread deadlock on the GIL. :class:`FrankySimServer` starts
  ``python -m lapwrench.hardware.frankysim`` with :mod:`subprocess` and stops it by its pid.
* libfranka's command port is fixed (1337), so one server per address. Tests on the same machine
  are serialised with a lock file; the server binds 127.0.0.1 only.
* Its robot is franky-sim's FR3 with a Franka Hand (no laparoscope, no trocar). The external
  wrench fields (``O_F_ext_hat_K`` ...) are zero and ``tau_J`` is the applied torque. It enforces
  **no** velocity/acceleration/jerk limits (a real Franka would abort on a violation), so the
  caller has to check them itself. The arm pose persists between client connections.
* It paces itself to 1 kHz with ``time.sleep`` and can run below real time on a loaded machine;
  every step's compute time is recorded and written to a JSON stats file when the server stops.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import fcntl
import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import numpy as np

from lapwrench.robot.description import ARM_SPECS

COMMAND_PORT = 1337
LOOPBACK = "127.0.0.1"
READY = "FRANKYSIM-READY"


class FrankySimError(RuntimeError):
    """franky-sim could not be started or reached."""


def frankysim_available() -> str | None:
    """None if pylibfranka and franky_sim both import, else the reason they don't."""
    try:
        import franky_sim  # noqa: F401
        import pylibfranka  # noqa: F401
    except Exception as exc:  # ImportError, or a missing shared library (OSError)
        return f"{type(exc).__name__}: {exc}"
    return None


@dataclass(frozen=True)
class StepStats:
    """franky-sim's own per-step compute time (commands + physics + state send), in microseconds."""

    steps: int
    p50_us: float
    p99_us: float
    max_us: float
    wall_s: float

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall second (1.0 = real time)."""
        return self.steps * 1e-3 / self.wall_s if self.wall_s > 0 else 0.0


def _port_free(host: str, port: int) -> bool:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        s.bind((host, port))
    except OSError as exc:
        if exc.errno in (errno.EADDRINUSE, errno.EACCES):
            return False
        raise
    finally:
        s.close()
    return True


class FrankySimServer:
    """Context manager running franky-sim on 127.0.0.1 in a child process.

    Args:
        initial_q: Initial FR3 joint configuration (rad).
        realtime: Pace the simulation at 1 kHz wall clock (False: as fast as possible).
        start_timeout: Seconds to wait for the server to accept connections.
        lock_timeout: Seconds to wait for another franky-sim user on this machine to finish.

    Attributes:
        pid: Process id of the server (``None`` before ``start``).
        stats: :class:`StepStats` read after ``stop`` (``None`` if the server wrote none).
    """

    def __init__(
        self,
        initial_q: np.ndarray | None = None,
        *,
        realtime: bool = True,
        start_timeout: float = 60.0,
        lock_timeout: float = 300.0,
    ) -> None:
        self.host = LOOPBACK
        self.initial_q = None if initial_q is None else np.asarray(initial_q, dtype=float)
        self.realtime = realtime
        self.start_timeout = start_timeout
        self.lock_timeout = lock_timeout
        self.pid: int | None = None
        self.stats: StepStats | None = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._lock_file: IO[str] | None = None
        self._stats_path: Path | None = None

    # -- life cycle ----------------------------------------------------------------------------
    def _acquire_lock(self) -> None:
        path = Path(tempfile.gettempdir()) / f"lapwrench-frankysim-{COMMAND_PORT}.lock"
        f = path.open("a+")
        deadline = time.monotonic() + self.lock_timeout
        while True:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError:
                if time.monotonic() > deadline:
                    f.close()
                    raise FrankySimError(
                        f"another franky-sim user holds {path} for more than {self.lock_timeout:.0f} s"
                    ) from None
                time.sleep(0.1)
        self._lock_file = f

    def start(self) -> FrankySimServer:
        """Start the server and wait until it accepts connections on 127.0.0.1:1337."""
        self._acquire_lock()
        try:
            deadline = time.monotonic() + 10.0
            while not _port_free(self.host, COMMAND_PORT):
                if time.monotonic() > deadline:
                    raise FrankySimError(f"{self.host}:{COMMAND_PORT} is in use by another process")
                time.sleep(0.2)
            fd, stats = tempfile.mkstemp(prefix="frankysim-stats-", suffix=".json")
            os.close(fd)
            self._stats_path = Path(stats)
            cmd = [sys.executable, "-m", "lapwrench.hardware.frankysim", "--stats", stats]
            if self.initial_q is not None:
                cmd += ["--q0", ",".join(f"{v:.9f}" for v in self.initial_q)]
            if not self.realtime:
                cmd.append("--no-realtime")
            env = dict(os.environ)
            env.setdefault("MUJOCO_GL", "egl")
            self._proc = subprocess.Popen(
                cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, start_new_session=True
            )
            self.pid = self._proc.pid
            self._wait_ready()
        except BaseException:
            self.stop()
            raise
        return self

    def _wait_ready(self) -> None:
        assert self._proc is not None and self._proc.stdout is not None
        fd = self._proc.stdout.fileno()
        os.set_blocking(fd, False)
        lines: list[str] = []
        buf = ""
        deadline = time.monotonic() + self.start_timeout
        while time.monotonic() < deadline:
            try:
                chunk = os.read(fd, 65536).decode(errors="replace")
            except BlockingIOError:
                chunk = ""
            if chunk:
                buf += chunk
                *done, buf = buf.split("\n")
                lines.extend(done)
                if any(READY in line for line in lines):
                    threading.Thread(target=self._drain, args=(fd,), daemon=True).start()
                    return
            if self._proc.poll() is not None:
                tail = "\n".join([*lines, buf][-20:])
                raise FrankySimError(f"franky-sim exited with code {self._proc.returncode}:\n{tail}")
            time.sleep(0.05)
        raise FrankySimError(f"franky-sim did not become ready within {self.start_timeout:.0f} s")

    @staticmethod
    def _drain(fd: int) -> None:
        """Keep reading the server's output so a chatty server never blocks on a full pipe."""
        os.set_blocking(fd, True)
        with contextlib.suppress(OSError, ValueError):
            while os.read(fd, 65536):
                pass

    def stop(self, timeout: float = 10.0) -> None:
        """Stop the server by its pid (SIGTERM, then SIGKILL), read its stats and release the lock."""
        proc, self._proc = self._proc, None
        try:
            if proc is not None:
                if proc.poll() is None:
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(proc.pid, signal.SIGTERM)
                    try:
                        proc.wait(timeout)
                    except subprocess.TimeoutExpired:
                        with contextlib.suppress(ProcessLookupError):
                            os.kill(proc.pid, signal.SIGKILL)
                        proc.wait(5.0)
                if proc.stdout is not None:
                    proc.stdout.close()
            if self._stats_path is not None:
                with contextlib.suppress(OSError, ValueError, KeyError, TypeError):
                    self.stats = StepStats(**json.loads(self._stats_path.read_text()))
                with contextlib.suppress(OSError):
                    self._stats_path.unlink()
                self._stats_path = None
        finally:
            if self._lock_file is not None:
                with contextlib.suppress(OSError):
                    fcntl.flock(self._lock_file, fcntl.LOCK_UN)
                self._lock_file.close()
                self._lock_file = None

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def __enter__(self) -> FrankySimServer:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


# -- the server process ------------------------------------------------------------------------
def _serve(q0: tuple[float, ...] | None, stats_path: str | None, realtime: bool) -> None:
    import logging

    from franky_sim import SimulationServer
    from franky_sim.mujoco_simulator import MujocoSimulator

    logging.basicConfig(level=logging.ERROR)
    stop = False

    def on_signal(signum: int, frame: Any) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    times = np.zeros(600_000)  # 10 min of steps; later steps overwrite from the start
    n = 0
    with MujocoSimulator(enable_visualization=False) as sim:
        kwargs: dict[str, Any] = {} if q0 is None else {"initial_q": q0}
        sim.add_robot(**kwargs)
        with SimulationServer(sim, hostname_candidates=[LOOPBACK]) as server:
            print(READY, flush=True)
            t_start = time.perf_counter()
            next_t = t_start
            while not stop:
                t0 = time.perf_counter()
                for rs in server.robot_servers:
                    rs.process_commands()
                sim.step()
                for rs in server.robot_servers:
                    rs.send_state()
                t1 = time.perf_counter()
                times[n % times.size] = t1 - t0
                n += 1
                if realtime:
                    next_t = max(next_t + 1e-3, t1 - 2e-3)  # catch up at most 2 ms, never burst
                    delay = next_t - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
            wall = time.perf_counter() - t_start
    if stats_path:
        k = min(n, times.size)
        us = times[:k] * 1e6 if k else np.zeros(1)
        Path(stats_path).write_text(
            json.dumps(
                {
                    "steps": n,
                    "p50_us": float(np.percentile(us, 50)),
                    "p99_us": float(np.percentile(us, 99)),
                    "max_us": float(us.max()),
                    "wall_s": wall,
                }
            )
        )


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description="franky-sim server on 127.0.0.1 (lapwrench tests/bench)")
    n = ARM_SPECS["fr3"].n_joints  # franky-sim simulates an FR3
    p.add_argument("--q0", help=f"initial joint configuration, {n} comma-separated values (rad)")
    p.add_argument("--stats", help="write per-step compute time statistics (JSON) here on exit")
    p.add_argument("--no-realtime", action="store_true", help="run as fast as possible")
    a = p.parse_args(argv)
    q0 = None
    if a.q0 is not None:
        try:
            q0 = tuple(float(v) for v in a.q0.split(","))
        except ValueError:
            p.error(f"--q0 needs {n} comma-separated numbers, got {a.q0!r}")
        if len(q0) != n:
            p.error(f"--q0 needs {n} values")
        if not all(math.isfinite(v) for v in q0):
            p.error(f"--q0 needs finite values, got {a.q0!r}")
    _serve(q0, a.stats, not a.no_realtime)


if __name__ == "__main__":
    main()
