"""The page: a viser server showing and steering a :class:`~lapwrench.ui.session.Session`.

Three threads besides viser's own: the sim thread (:class:`~lapwrench.ui.runner.RealTimeRunner`,
the 1 kHz ticks at wall-clock pace), the view thread (:class:`~lapwrench.ui.view.LaparoscopeView`,
the laparoscope frames, each sent to the page as it comes, at the view's own frame rate) and the
page thread (:meth:`UiApp.run_forever` or :meth:`UiApp.start`), which draws the latest snapshot
into the scene at :data:`PAGE_HZ` (and at once when a snapshot first shows a changed hand, so a push
is not kept waiting for the next update), refreshes the plots at :data:`PLOT_HZ` and the status line.
Neither steps the simulation, so a slow browser slows the page, not the control loop.

What a client sends that viser refuses is told in one line each, rate-limited
(:class:`~lapwrench.ui.untrusted.UntrustedClients`), instead of a library's traceback.
"""

from __future__ import annotations

import contextlib
import errno
import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from lapwrench.config import Config
from lapwrench.ui.controls import Controls
from lapwrench.ui.params import ParamsPanel
from lapwrench.ui.plots import LivePlots, plot_specs
from lapwrench.ui.runner import RealTimeRunner
from lapwrench.ui.scene import SceneDrawer, cue_color
from lapwrench.ui.session import Session
from lapwrench.ui.untrusted import PageServer, UntrustedClients
from lapwrench.ui.view import RENDER_NICE, LaparoscopeView, view_size

PAGE_HZ = 20.0  # scene updates per second
EARLIEST_DRAW = 0.025  # s after the last update: a changed hand is drawn at once, but no sooner than this
PLOT_HZ = 4.0  # status line and plot refreshes per second


@dataclass(frozen=True)
class UiOptions:
    """How the page runs: where it listens, the session's seed and detector, the view's frame rate."""

    host: str = "127.0.0.1"
    port: int = 8080
    seed: int = 0
    detector: str = "projected"
    view_fps: float = 25.0
    view_scale: float = 0.5  # the view is rendered at this fraction of the camera's 640 x 480


class UiApp:
    """The viser server with the session, the runner, the view and the page's panels."""

    def __init__(self, cfg: Config, options: UiOptions | None = None) -> None:
        self.options = opts = options or UiOptions()
        self.server = PageServer(host=opts.host, port=opts.port, label="lapwrench", verbose=False)  # never shared
        if opts.port and self.server.get_port() != opts.port:  # viser tries the next ports when one is taken
            self.server.stop()
            raise OSError(errno.EADDRINUSE, os.strerror(errno.EADDRINUSE))
        self.untrusted = UntrustedClients(self.server)  # a client's garbage: one line, not a traceback
        with contextlib.ExitStack() as undo:  # a failed start ends what it started, newest first
            undo.callback(self.untrusted.close)
            undo.callback(self.server.stop)
            self.session = Session(cfg, seed=opts.seed, detector=opts.detector)
            undo.callback(self.session.closed.world.close)
            self._build_page(opts)
            undo.pop_all()  # started: nothing to undo

    def _build_page(self, opts: UiOptions) -> None:
        """The runner, the scene, the panels and the view (in :meth:`__init__`, after the session)."""
        self.runner = RealTimeRunner(self.session.step, lambda: self.session.time)
        # No shadows and no environment map (image-based lighting): in a browser without a GPU (software
        # WebGL) they cost most of each frame, and a busy browser takes the CPU the simulation needs.
        self.server.scene.configure_default_lights(True, cast_shadow=False)
        self.server.scene.configure_environment_map(None)
        self.server.initial_camera.position = (1.25, -0.75, 0.85)
        self.server.initial_camera.look_at = (0.5, 0.0, 0.3)
        world = self.session.closed.world
        self.scene = SceneDrawer(self.server, world.model, world.data)
        names = [c.name for c in self.session.closed.controller.cues]
        self.cue_colors = {n: cue_color(n, i) for i, n in enumerate(names)}
        gui = self.server.gui
        self.controls = Controls(self.server, self.session, self.runner)
        self.params = ParamsPanel(gui, self.session)
        panel = gui.add_panel()  # the view and the plots in a column of their own, left of the scene
        with panel.add_tab("Laparoscope view and live plots"):
            width, height = view_size(self.session.cfg, opts.view_scale)
            self.image = gui.add_image(np.zeros((height, width, 3), np.uint8), format="jpeg", jpeg_quality=80)
            self.plots = LivePlots(gui, self.session.history, plot_specs(names, self.cue_colors))
        panel.dock_left()
        panel.set_width(400)
        # The render process runs RENDER_NICE below the sim thread's priority: behind the simulation,
        # but level with the browser when the sim thread was granted its higher priority.
        self.view = LaparoscopeView(self.session, fps=opts.view_fps, scale=opts.view_scale,
                                    on_image=self._show_image, keeping_up=self.runner.kept_up,
                                    render_nice=lambda: (self.runner.nice or 0) + RENDER_NICE)
        self.session.on_tick.append(self.view.on_tick)
        self.page_frames = 0
        self.images_sent = 0  # view images sent to the page
        self._stop = threading.Event()
        self._wake = threading.Event()  # set by the sim thread when a snapshot first shows a changed hand
        self.session.on_hand_snapshot.append(self._wake.set)
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        return f"http://{self.options.host}:{self.port}"

    # -- life cycle ---------------------------------------------------------------------------
    def start(self) -> None:
        """Start the sim, the view and the page threads; returns at once."""
        self.runner.start()
        self.view.start()
        self._thread = threading.Thread(target=self._page_loop, name="lapwrench-ui-page", daemon=True)
        self._thread.start()

    def request_stop(self) -> None:
        """Ask :meth:`run_forever` to stop (from a signal handler or another thread)."""
        self._stop.set()
        self._wake.set()

    def run_forever(self) -> None:
        """Start, then wait until interrupted (Ctrl-C) or :meth:`request_stop`, then stop."""
        self.start()
        try:
            while not self._stop.is_set():
                time.sleep(0.2)
        except KeyboardInterrupt:
            pass
        finally:
            self.stop()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        self.runner.stop()
        self.view.stop()
        if self._thread is not None:
            self._thread.join(5.0)
        self.server.stop()
        self.untrusted.close()
        self.session.closed.world.close()

    # -- the page thread ----------------------------------------------------------------------
    def _page_loop(self) -> None:
        """Draw every 1 / :data:`PAGE_HZ` s, and at once (but not within :data:`EARLIEST_DRAW` of the last
        update) when the sim thread has a snapshot that shows a changed hand: a push on the page reaches
        the scene without waiting up to a whole period."""
        period, plot_every = 1.0 / PAGE_HZ, max(1, round(PAGE_HZ / PLOT_HZ))
        k = 0
        while not self._stop.is_set():
            t0 = time.perf_counter()
            self._wake.clear()
            try:
                self.draw(slow=k % plot_every == 0)
            except Exception as exc:  # a drawing bug must not take the server down: show it
                self.controls.show_error(f"page update: {type(exc).__name__}: {exc}")
            k += 1
            time.sleep(max(0.0, EARLIEST_DRAW - (time.perf_counter() - t0)))
            self._wake.wait(max(0.0, period - (time.perf_counter() - t0)))

    def draw(self, slow: bool = True) -> None:
        """One page update: the scene; with ``slow``, the status line and the plots
        too (each a React re-render on the page, costly on a software-rendered browser)."""
        snap = self.session.snapshot
        if snap is not None:
            with self.server.atomic():
                self.scene.update(snap, self.cue_colors)
        if snap is not None:
            self.controls.follow_handle(snap)
        if slow:
            self.controls.refresh(snap, self.view.measured_fps)
            if self.view.error:
                self.controls.show_error(self.view.error)
            self.params.show_applied()
            self.plots.refresh()
        self.page_frames += 1

    # -- the view thread -----------------------------------------------------------------------
    def _show_image(self, image: np.ndarray) -> None:
        """Send a new laparoscope frame to the page (JPEG-encoded by viser; runs on the view thread)."""
        self.image.image = image
        self.images_sent += 1

    def stats(self) -> dict[str, Any]:
        """Figures for the command line and the tests: real-time factor, per-tick wall time, view fps."""
        return {"rtf": self.runner.rtf, "tick_ms": self.runner.step_seconds * 1e3,
                "view_fps": self.view.measured_fps, "sim_time": self.session.time}
