"""The simulated laparoscope camera, and the handover of frames drawn in the background.

- :class:`SimCamera`: frames of the world's laparoscope view at 25 fps, rendered headless without
  shadows, either at once or in a child process (:mod:`lapwrench.sim.offscreen`) while the
  simulation steps on.
- :class:`PendingFrame`, :func:`frame_hold`: a frame being drawn in the background and how long the
  closed loop (:class:`lapwrench.sim.loop.ClosedLoop`) may step before it hands it over.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lapwrench.sim.offscreen import OffscreenRenderer
from lapwrench.sim.scene.names import CAMERA_NAME
from lapwrench.sim.sensors import SampleAndHold, check_rate
from lapwrench.sim.world import SimWorld

NO_IMAGE = np.zeros((0, 0, 3), np.uint8)  # what an image-free (projected) detector is shown


@dataclass(frozen=True)
class PendingFrame:
    """A frame being drawn in the background: its capture time, the mode then, and the simulated time
    by which it is handed over."""

    t: float
    mode: str
    deliver_by: float


def frame_hold(fps: float, latency: float | str, image_free: bool) -> float:
    """How long (s) a frame may be drawn in the background: until the next frame, and until the detector's
    result on it is due when the detector looks at the image."""
    period = 1.0 / fps
    if image_free:
        return period
    return min(period, float(latency)) if latency != "measured" else 0.0


class SimCamera:
    """Laparoscope frames at ``fps`` (default 25), rendered headless without shadows.

    With ``draw=False`` it keeps the frame clock only: a due frame is 'captured' as :data:`NO_IMAGE`,
    nothing is rendered (for an image-free detector, projected geometry, with no one to show the frames
    to: the detections come at the same capture times as with frames drawn).

    :meth:`capture` renders a due frame at once. With ``background`` a due frame can instead be
    begun (:meth:`begin`) in a child process (:class:`~lapwrench.sim.offscreen.OffscreenRenderer`)
    while the simulation steps on, and collected later (:meth:`finish`): the same image, drawn from
    the world's state at the capture time. :meth:`close` ends the child. :attr:`frame` and :attr:`stamp`
    are the latest frame drawn and its capture time (s), always updated together.
    """

    def __init__(self, world: SimWorld, fps: float = 25.0, *, background: bool = False, draw: bool = True) -> None:
        check_rate(fps, "camera")
        self.fps = fps
        self.world = world
        self.draws = draw
        self._clock = SampleAndHold(fps)
        self.frame: np.ndarray | None = None if draw else NO_IMAGE
        self.stamp = -np.inf
        self.offscreen = OffscreenRenderer(world, CAMERA_NAME) if background and draw else None
        self._begun = False
        self._begun_at = -np.inf

    def capture(self, t: float) -> bool:
        """Render a new frame if one is due at ``t``; returns True when it did."""
        if self._clock.due(t):
            if self.draws:
                self.frame = self.world.render()
            self.stamp = t
            return True
        return False

    def begin(self, t: float) -> bool:
        """If a frame is due at ``t``: start drawing it (in the child process when ``background``, else
        now) and return True; :meth:`finish` gives it. A frame begun and not finished is dropped."""
        if not self._clock.due(t):
            return False
        self._begun_at = t
        self._begun = True
        off = self.offscreen
        if off is not None:
            if off.in_flight:
                off.result()  # the previous frame, never collected
            if off.start():
                return True
        # no background, or no forward to draw from: now
        self.frame, self.stamp = self.world.render() if self.draws else NO_IMAGE, t
        return True

    def finish(self) -> np.ndarray:
        """The frame of the last :meth:`begin` (waits for the child process if it is drawing it)."""
        if not self._begun:
            raise RuntimeError("no frame begun: call begin() first")
        self._begun = False
        if self.offscreen is not None and self.offscreen.in_flight:
            self.frame, self.stamp = self.offscreen.result(), self._begun_at  # frame and stamp go together
        assert self.frame is not None
        return self.frame

    def close(self) -> None:
        """End the background render process, if any."""
        if self.offscreen is not None:
            self.offscreen.close()
