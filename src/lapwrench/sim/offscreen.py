"""The laparoscope view of a :class:`~lapwrench.sim.world.SimWorld` rendered in a child process, so the
simulation steps on while a frame is drawn.

A 640 x 480 frame costs 20-30 ms on a software GL (llvmpipe), more than the 40 ms between two 25 fps
frames leave a 1 kHz loop that runs a few times faster than real time. :class:`OffscreenRenderer`
sends the state a frame is drawn from (:meth:`SimWorld.render_state`: the joints and the mocap poses
at the last ``mj_forward``, a few hundred bytes) to a child process holding a copy of the world's
model and an offscreen renderer set up like :meth:`SimWorld.render`; the child recomputes the poses
(MuJoCo's position stage: kinematics, centres of mass, cameras and lights, deterministic) and draws,
while the caller goes on; :meth:`OffscreenRenderer.result` collects the frame later. The image is
the one :meth:`SimWorld.render` draws at the same state, pixel for pixel (tests/sim/test_offscreen.py).

One frame is in flight at a time. The child is started (spawned: no fork of a process holding a GL
context) on the first frame, and ends with :meth:`OffscreenRenderer.close`, with its parent, or when
the renderer is garbage collected.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import weakref
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import mujoco

START_TIMEOUT_S = 120.0  # spawning imports MuJoCo and creates a GL context; a busy machine is slow


def render_worker(model: Any, width: int, height: int, camera: str, conn: Connection) -> None:
    """The child: renders the view of ``camera`` (the laparoscope's: :func:`scope_view_option`) of
    ``model`` for each (qpos, mocap_pos, mocap_quat) received and sends the RGB bytes back; None (or the
    parent gone) ends it. Ctrl-C is the parent's. It imports MuJoCo and this module only."""
    import os
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("MUJOCO_GL", "egl")  # (inherited from the parent, which set it before importing MuJoCo)
    import mujoco

    try:
        data = mujoco.MjData(model)
        renderer = make_renderer(model, width, height)
    except Exception as exc:  # no GL: the parent raises with this message
        conn.send(f"{type(exc).__name__}: {exc}")
        return
    option = scope_view_option()
    conn.send("ready")
    try:
        while (msg := conn.recv()) is not None:
            data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = msg
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            mujoco.mj_camlight(model, data)
            renderer.update_scene(data, camera=camera, scene_option=option)
            conn.send_bytes(renderer.render().reshape(-1))  # 1-D: send_bytes sends len() items
    except (EOFError, BrokenPipeError, ConnectionResetError):  # the parent went away
        pass
    finally:
        renderer.close()


def _stop(conn: Connection, process: Any) -> None:
    """End the child: None on the pipe, then a join (and a kill if it hangs)."""
    with contextlib.suppress(OSError):
        conn.send(None)
    conn.close()
    process.join(5.0)
    if process.is_alive():
        process.kill()
        process.join(1.0)


class OffscreenRenderer:
    """The view of the laparoscope ``camera`` of ``world`` (its camera's size) drawn in a child process
    (module docstring).

    :meth:`start` sends the world's current render state; :meth:`result` waits for that frame.
    """

    def __init__(self, world: Any, camera: str) -> None:
        self.world = world
        cam = world.scene.config.camera
        self.width, self.height = int(cam.width), int(cam.height)
        self.camera = camera
        self._conn: Connection | None = None
        self._finalizer: weakref.finalize | None = None
        self.in_flight = False

    def _spawn(self) -> Connection:
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        args = (self.world.model, self.width, self.height, self.camera, child)
        process = ctx.Process(target=render_worker, args=args,
                              name="lapwrench-sim-render", daemon=True)
        process.start()
        child.close()
        reply = parent.recv() if parent.poll(START_TIMEOUT_S) else "no reply"
        if reply != "ready":
            _stop(parent, process)
            raise RuntimeError(f"the camera's render process did not start: {reply}")
        self._finalizer = weakref.finalize(self, _stop, parent, process)
        return parent

    def start(self) -> bool:
        """Begin drawing the world's current view; False (nothing sent) when the world has no render
        state (:meth:`SimWorld.render_state`) or a frame is already in flight."""
        state = self.world.render_state()
        if state is None or self.in_flight:
            return False
        if self._conn is None:
            self._conn = self._spawn()
        self._conn.send(state)
        self.in_flight = True
        return True

    def result(self) -> np.ndarray:
        """The frame :meth:`start` began (RGB uint8, height x width x 3), waiting for it if needed."""
        if not self.in_flight or self._conn is None:
            raise RuntimeError("no frame in flight: call start() first")
        buf = bytearray(self.width * self.height * 3)
        try:
            self._conn.recv_bytes_into(buf)
        except (EOFError, OSError) as exc:
            raise RuntimeError(f"the camera's render process ended: {exc}") from exc
        finally:
            self.in_flight = False
        return np.frombuffer(buf, np.uint8).reshape(self.height, self.width, 3)

    def close(self) -> None:
        """End the child process (a frame in flight is dropped)."""
        if self._finalizer is not None:
            self._finalizer()
        self._conn = None
        self.in_flight = False


def make_renderer(model: mujoco.MjModel, width: int, height: int) -> mujoco.Renderer:
    """An offscreen renderer as the laparoscope's frames are drawn: no shadows, reflections or skybox."""
    import mujoco
    r = mujoco.Renderer(model, height=height, width=width)
    r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
    r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
    r.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = False
    return r


def release_context() -> None:
    """Leave no GL context current on this thread. MuJoCo's renderer makes its context current when it is
    built and when it draws, and leaves it so; with EGL a context current on one thread can be neither
    drawn with nor freed on another (EGL_BAD_ACCESS): ``ui --foxglove`` draws the live view on the sim
    thread and closes the world on the main thread. Other back ends keep their own rules."""
    if os.environ.get("MUJOCO_GL") == "egl":
        from mujoco.egl import EGL

        EGL.eglReleaseThread()


def scope_view_option() -> mujoco.MjvOption:
    """The laparoscope's visual options: what is never in its view is not drawn (:data:`UNSEEN_BY_SCOPE_GROUP`):
    the arm, and the room outside the phantom's closed housing, whose large faces would be shaded only to be
    covered by the housing's (a quarter of a frame's cost on a software GL); the same image."""
    import mujoco

    from lapwrench.sim.scene.names import UNSEEN_BY_SCOPE_GROUP

    opt = mujoco.MjvOption()
    opt.geomgroup[UNSEEN_BY_SCOPE_GROUP] = 0
    return opt
