"""The laparoscope view for the page, annotated with the detections and the tracking deadbands
ε1 (white) and ε2 (yellow).

Rendering a frame costs tens of milliseconds on a software GL and MuJoCo's renderer holds Python's
GIL meanwhile: done in the simulation's process it would stall the 1 kHz loop. So frames are
rendered in a child process (:func:`render_worker`) from the same scene: the sim thread only copies
the positions (joints, instruments) when the view asks (microseconds, in
:meth:`LaparoscopeView.on_tick`), and the view thread sends them to the child and waits for the
frame, without holding the GIL. When the session's detector renders frames itself (the shipped
YOLO model), the view takes those frames instead of rendering twice.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from lapwrench.config import Config, from_dict, to_dict
from lapwrench.controller import TickResult
from lapwrench.sim.scene.names import CAMERA_NAME
from lapwrench.spawn import quiet_process, start_quiet
from lapwrench.ui.session import Session
from lapwrench.ui.snapshot import Snapshot

MIN_FPS = 5.0  # the view's lowest frame rate when the simulation falls behind
RENDER_NICE = 5  # the render process's niceness above the simulation's: on a busy machine frames wait


def render_worker(cfg_data: dict[str, Any], scale: float, conn: Connection, nice: int = RENDER_NICE) -> None:
    """The render process: builds the scene of ``cfg_data`` (a config as a mapping), then for each
    (qpos, mocap_pos, mocap_quat) received renders the laparoscope view (the arm hidden) at ``scale``
    times the camera's size and sends the RGB bytes back; None ends it. Software GL (llvmpipe) is
    kept to one thread: the other core runs the simulation. The process runs at niceness ``nice``
    (if that is not below its own). Ctrl-C is the parent's to handle (it ends this process with
    None); a parent that is gone (end of the pipe) ends it too, quietly."""
    import os
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("LP_NUM_THREADS", "1")
    with contextlib.suppress(OSError):  # when the two compete for a core, the simulation goes first
        os.setpriority(os.PRIO_PROCESS, 0, max(nice, os.getpriority(os.PRIO_PROCESS, 0)))
    import mujoco

    from lapwrench.sim.offscreen import make_renderer, scope_view_option
    from lapwrench.sim.scene.build import build_scene
    from lapwrench.sim.scene.config import SceneConfig

    cfg = from_dict(cfg_data)
    model = build_scene(SceneConfig.from_config(cfg)).model
    data = mujoco.MjData(model)
    width, height = view_size(cfg, scale)
    renderer = make_renderer(model, width, height)  # set up as the simulation's laparoscope frames are
    option = scope_view_option()  # the arm is never in the laparoscope's view
    conn.send("ready")
    try:
        while (msg := conn.recv()) is not None:
            data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = msg
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            renderer.update_scene(data, camera=CAMERA_NAME, scene_option=option)
            conn.send_bytes(renderer.render().tobytes())
    except (EOFError, BrokenPipeError):  # the parent went away without saying so
        pass
    finally:
        renderer.close()


def next_due(due: float, period: float, now: float) -> float:
    """When the frame after the one due at ``due`` is due (s): one ``period`` later, so that the frame
    rate holds however long each frame took; a frame later than a whole period starts the count
    again from ``now`` (no burst of frames to catch up)."""
    due += period
    return due if due > now - period else now


def view_size(cfg: Config, scale: float) -> tuple[int, int]:
    """(width, height) of the page's view: the camera's image times ``scale``."""
    return max(16, round(cfg.camera.width * scale)), max(16, round(cfg.camera.height * scale))


def annotate(frame: np.ndarray, cfg: Config, snapshot: Snapshot | None) -> np.ndarray:
    """The frame with the ε1 (white) and ε2 (yellow) circles about the principal point, each
    detection's box (green) and tracking point (red), and a label (time, mode), as the demo's video
    draws them (:func:`lapwrench.sim.video.annotate_frame`); the frame may be a scaled camera image."""
    import cv2

    img = np.ascontiguousarray(frame.copy())
    s = img.shape[1] / cfg.camera.width
    c = (round(cfg.camera.u0 * s), round(cfg.camera.v0 * s))
    cv2.circle(img, c, round(cfg.tracking.epsilon1 * s), (255, 255, 255), 1, cv2.LINE_AA)
    cv2.circle(img, c, round(cfg.tracking.epsilon2 * s), (255, 255, 0), 1, cv2.LINE_AA)
    if snapshot is None:
        return img
    for box, point in snapshot.detections:
        x0, y0, x1, y1 = (round(v * s) for v in box)
        cv2.rectangle(img, (x0, y0), (x1, y1), (0, 255, 0), 1)
        cv2.circle(img, (round(point[0] * s), round(point[1] * s)), 3, (255, 0, 0), -1)
    label = f"t={snapshot.t:6.2f} s  {snapshot.mode}"
    cv2.putText(img, label, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return img


class LaparoscopeView:
    """Annotated laparoscope frames of a session at up to ``fps`` (register :meth:`on_tick` in
    ``session.on_tick``, then :meth:`start`). ``on_image`` is called with each new frame (on this
    view's thread). Frames are rendered at ``scale`` times the camera's size, in a process of
    niceness ``render_nice()`` (asked when it starts). While ``keeping_up()``
    is false (the simulation runs slower than real time) the frame rate is halved, down to
    :data:`MIN_FPS`, and it climbs back toward ``fps`` once it is true again."""

    def __init__(self, session: Session, fps: float = 25.0, scale: float = 0.5,
                 on_image: Callable[[np.ndarray], None] | None = None,
                 keeping_up: Callable[[], bool] | None = None,
                 render_nice: Callable[[], int] = lambda: RENDER_NICE) -> None:
        if not (0.0 < fps <= 60.0):
            raise ValueError(f"view fps must be in (0, 60], got {fps}")
        if not (0.1 <= scale <= 1.0):
            raise ValueError(f"view scale must be in [0.1, 1], got {scale}")
        self.session = session
        self.fps = float(fps)
        self.scale = float(scale)
        self.keeping_up = keeping_up
        self.render_nice = render_nice
        self.rate = self.fps  # the frame rate aimed at now: lowered while the simulation falls behind
        self.on_image = on_image
        self.frames = 0
        self.measured_fps = float("nan")
        self.image: np.ndarray | None = None
        self.error: str | None = None
        self._lock = threading.Lock()
        self._want = threading.Event()
        self._have = threading.Event()
        self._state: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._camera_frame: np.ndarray | None = None
        self._camera_stamp = -np.inf
        self._snapshot: Snapshot | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._process: Any = None
        self._conn: Connection | None = None

    # -- sim thread ---------------------------------------------------------------------------
    def on_tick(self, session: Session, result: TickResult | None) -> None:
        """Copy what the next frame needs, if one was asked for (runs in the sim thread)."""
        if not self._want.is_set():
            return
        closed = session.closed
        cam = closed.camera
        with self._lock:
            if cam is not None and cam.draws:  # the loop renders: reuse its frames
                if cam.stamp <= self._camera_stamp or cam.frame is None:
                    return
                self._camera_stamp = cam.stamp
                self._camera_frame = cam.frame
            else:
                d = closed.world.data
                self._camera_frame = None
                self._state = (d.qpos.copy(), d.mocap_pos.copy(), d.mocap_quat.copy())
            self._snapshot = session.snapshot
        self._want.clear()
        self._have.set()

    # -- view thread --------------------------------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="lapwrench-ui-view", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        self._want.set()
        self._have.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def _start_renderer(self) -> None:
        ctx = mp.get_context("spawn")  # no fork of a threaded process with GL state
        parent, child = ctx.Pipe()
        args = (to_dict(self.session.cfg), self.scale, child, self.render_nice())
        process = start_quiet(quiet_process(ctx, render_worker, args, name="lapwrench-ui-render", daemon=True))
        self._process = process  # only a started process: _run joins it
        child.close()
        if not parent.poll(120.0) or parent.recv() != "ready":
            raise RuntimeError("the render process did not start")
        self._conn = parent

    def _render(self, state: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        if self._conn is None:
            self._start_renderer()
        assert self._conn is not None
        self._conn.send(state)
        width, height = view_size(self.session.cfg, self.scale)
        return np.frombuffer(self._conn.recv_bytes(), np.uint8).reshape(height, width, 3)

    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # no GL, or a renderer failure: the page says so, the sim goes on
            self.error = f"laparoscope view stopped: {type(exc).__name__}: {exc}"
        finally:
            if self._conn is not None:
                with contextlib.suppress(OSError):
                    self._conn.send(None)
                self._conn.close()
            if self._process is not None:
                self._process.join(5.0)
                if self._process.is_alive():
                    self._process.terminate()

    def _adapt(self) -> None:
        """Once a second: halve the frame rate while the simulation falls behind, raise it by a
        quarter while it keeps up."""
        if self.keeping_up is None:
            return
        if self.keeping_up():
            self.rate = min(self.fps, self.rate * 1.25)
        else:
            self.rate = max(min(MIN_FPS, self.fps), self.rate * 0.5)

    def _loop(self) -> None:
        t_window, n_window = time.perf_counter(), 0
        due = t_window  # when the next frame is due: a fixed rate, not a pause after each frame
        while not self._stop.is_set():
            self._have.clear()
            self._want.set()
            if not self._have.wait(1.0) or self._stop.is_set():
                continue  # the sim is paused or held up: ask again
            with self._lock:
                frame, state, snapshot = self._camera_frame, self._state, self._snapshot
            if frame is None:
                if state is None:
                    continue
                frame = self._render(state)
            self.image = annotate(frame, self.session.cfg, snapshot)
            self.frames += 1
            n_window += 1
            if self.on_image is not None:
                self.on_image(self.image)
            now = time.perf_counter()
            if now - t_window >= 1.0:
                self.measured_fps = n_window / (now - t_window)
                t_window, n_window = now, 0
                self._adapt()
            due = next_due(due, 1.0 / self.rate, time.perf_counter())
            time.sleep(max(0.0, due - time.perf_counter()))
