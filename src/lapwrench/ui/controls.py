"""The page's controls: the status line, hand-guiding, instruments and scenario buttons.

Every callback goes through :meth:`Controls.guarded`: a bad value (NaN from a slider, an unknown
choice) or any other failure is shown on the page's error line and never reaches the sim thread.

A push, a torque, a grip or a drag never outlives the page that set it: when a page that set the
hand closes or reloads (its connection ends), the hand lets go (:meth:`Controls.client_left`). A
gizmo position that is not three finite numbers ends the drag and puts the gizmo back on the handle.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from lapwrench.ui.inputs import (
    GIZMO_STIFFNESS,
    GRIP_LEVELS,
    MAX_DELTA,
    MAX_HAND_FORCE,
    MAX_HAND_TORQUE,
    UiInputError,
    checked_choice,
)
from lapwrench.ui.playback import PLAYABLE
from lapwrench.ui.runner import RealTimeRunner
from lapwrench.ui.session import DETECTORS, INSTRUMENT_REACH, Session
from lapwrench.ui.snapshot import Snapshot

GIZMO_SCALE = 0.12  # m, the length of the handle gizmo's arrows in the scene


def status_text(snapshot: Snapshot | None, rtf: float, paused: bool, view_fps: float) -> str:
    """The status line: time, real-time factor, mode, grip gain, RCM error, holds and alarms."""
    if snapshot is None:
        return "starting…"
    speed = "paused" if paused else f"{rtf:.2f}× real time" if np.isfinite(rtf) else "…"
    fps = f"{view_fps:.0f} fps" if np.isfinite(view_fps) else "… fps"
    held = f" · **HELD: {snapshot.held}**" if snapshot.held else ""
    extra = "".join([" · incision shifted" if snapshot.disturbance else "",
                     f" · playing {snapshot.script_name} ({snapshot.script_time:.1f} s)" if snapshot.script else ""])
    alarms = f"\n\nalarms: {'; '.join(snapshot.alarms)}" if snapshot.alarms else ""
    return (f"t = {snapshot.t:.2f} s · {speed} · view {fps} · mode **{snapshot.mode}** · δ = {snapshot.delta:.2f}"
            f" · RCM error {snapshot.rcm_error_mm:.2f} mm{held}{extra}{alarms}")


def gizmo_position(value: object) -> np.ndarray | None:
    """The gizmo's position as 3 finite floats, or None (a page can send anything)."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None
    return v if v.shape == (3,) and bool(np.all(np.isfinite(v))) else None


class Controls:
    """Builds the controls in ``gui`` and wires them to the session and the runner."""

    def __init__(self, server: Any, session: Session, runner: RealTimeRunner) -> None:
        self.server = server
        self.session = session
        self.runner = runner
        gui = server.gui
        self.status = gui.add_markdown("starting…")
        self.error = gui.add_markdown("")
        self.resume_button = gui.add_button("Resume after hold", visible=False)
        self.resume_button.on_click(self.guarded(lambda _e: session.resume()))
        self.dragging = False
        # the gizmo's drag events (viser's event loop) and follow_handle (the page thread) both set the
        # hand's pull: one at a time, or a drag's end could be followed by the page thread's last pull and
        # leave the hand pulling after the release
        self._gizmo_lock = threading.RLock()
        self.hand_clients: set[int] = set()  # the pages (client ids) that set the hand since it last let go
        self._build_hand(gui)
        self._build_instruments(gui)
        self._build_scenarios(gui)
        self.gizmo = self._add_gizmo()
        server.on_client_disconnect(self.client_left)

    def _add_gizmo(self) -> Any:
        gizmo = self.server.scene.add_transform_controls("/handle_gizmo", scale=GIZMO_SCALE, disable_rotations=True)
        on_gizmo = self.guarded(self.gizmo_event)

        async def on_gizmo_in_order(event: Any) -> None:
            """On viser's event loop, so start, updates and end arrive in order (a plain callback runs
            in a thread pool, where a late update could follow the end and leave the hand pushing)."""
            on_gizmo(event)

        gizmo.on_update(on_gizmo_in_order)
        return gizmo

    def guarded(self, fn: Callable[[Any], None]) -> Callable[[Any], None]:
        """``fn`` with its errors shown on the page instead of raised."""
        def call(event: Any) -> None:
            try:
                fn(event)
            except UiInputError as exc:
                self.show_error(str(exc))
            except Exception as exc:  # never let the page's input crash the server
                self.show_error(f"{type(exc).__name__}: {exc}")
            else:
                self.show_error("")
        return call

    def by_hand(self, fn: Callable[[Any], None]) -> Callable[[Any], None]:
        """:meth:`guarded` ``fn`` for an input of the hand: the page that sent it is noted
        (:meth:`client_left` lets go when it closes)."""
        def call(event: Any) -> None:
            self._note_client(event)
            fn(event)
        return self.guarded(call)

    def _note_client(self, event: Any) -> None:
        client_id = getattr(event, "client_id", None)
        if client_id is not None:
            with self._gizmo_lock:
                self.hand_clients.add(int(client_id))

    def client_left(self, client: Any) -> None:
        """A page closed or reloaded (viser's disconnect callback): if it set the hand since the hand last
        let go, the hand lets go, so no push, torque, grip or drag stays on without its page."""
        with self._gizmo_lock:
            if getattr(client, "client_id", None) not in self.hand_clients:
                return
            self.dragging = False
            self.session.hand.set_gizmo(np.zeros(3))
        self._let_go()
        self.show_error("a page that was setting the hand closed: the hand let go")

    def show_error(self, message: str) -> None:
        text = f"**Error:** {message}" if message else ""
        if text != self.error.content:
            self.error.content = text

    # -- hand ---------------------------------------------------------------------------------
    def _build_hand(self, gui: Any) -> None:
        hand = self.session.hand
        with gui.add_folder("Hand on the handle"):
            self.grip = gui.add_button_group("grip", tuple(GRIP_LEVELS))
            self.delta = gui.add_slider("grip δ", 0.0, MAX_DELTA, 0.05, 0.0)
            self.azimuth = gui.add_slider("push direction (deg)", -180.0, 180.0, 5.0, 0.0)
            self.magnitude = gui.add_slider("push (N)", 0.0, MAX_HAND_FORCE, 0.5, 0.0)
            self.torque = gui.add_slider("torque about shaft (N m)", -MAX_HAND_TORQUE, MAX_HAND_TORQUE, 0.05, 0.0)
            self.release = gui.add_button("Let go")
            gui.add_markdown(f"Drag the gizmo at the handle: {GIZMO_STIFFNESS / 100:.0f} N per cm across the shaft, "
                             f"at most {MAX_HAND_FORCE:.0f} N. Arrows: hand red, trocar orange, cues by colour.")
        self.grip.on_click(self.by_hand(lambda e: hand.set_grip_level(e.target.value)))
        k_H = lambda: self.session.cfg.interaction.k_H  # noqa: E731 - read when used: parameters change
        self.delta.on_update(self.by_hand(lambda e: hand.set_grip_delta(e.target.value, k_H())))
        push = self.by_hand(lambda _e: hand.set_push(self.azimuth.value, self.magnitude.value))
        self.azimuth.on_update(push)
        self.magnitude.on_update(push)
        self.torque.on_update(self.by_hand(lambda e: hand.set_twist(e.target.value)))
        self.release.on_click(self.guarded(lambda _e: self._let_go()))

    def _let_go(self) -> None:
        with self._gizmo_lock:
            self.hand_clients.clear()
        self.session.hand.release()
        self.magnitude.value = 0.0
        self.torque.value = 0.0
        self.delta.value = 0.0

    def gizmo_event(self, event: Any) -> None:
        """A drag event of the handle gizmo (start, update or end; from viser): the hand's pull follows it."""
        self._note_client(event)
        with self._gizmo_lock:
            snap = self.session.snapshot
            position = gizmo_position(event.target.position)
            if event.phase == "end" or snap is None or position is None:
                self.dragging = False
                self.session.hand.set_gizmo(np.zeros(3))
                if position is None:  # follow_handle puts it back on the handle
                    raise UiInputError(f"handle gizmo: a position must be 3 finite numbers, got "
                                       f"{str(event.target.position)[:60]}")
                return
            self.dragging = True
            self.session.hand.set_gizmo(position - snap.hand_point)

    def follow_handle(self, snapshot: Snapshot) -> None:
        """Keep the gizmo on the handle while it is not dragged; while dragged, its pull follows the
        handle (a spring between the handle and the gizmo)."""
        with self._gizmo_lock:
            position = gizmo_position(self.gizmo.position)
            if position is None:  # a page sent a bad position: the drag ends, the gizmo goes back
                self.dragging = False
                self.session.hand.set_gizmo(np.zeros(3))
                if np.shape(self.gizmo.position) != (3,):  # its position can no longer be set: a new gizmo
                    self.gizmo.remove()
                    self.gizmo = self._add_gizmo()
                self.gizmo.position = snapshot.hand_point
            elif not self.dragging:
                if np.max(np.abs(position - snapshot.hand_point)) > 1e-4:
                    self.gizmo.position = snapshot.hand_point
            else:
                self.session.hand.set_gizmo(position - snapshot.hand_point)

    # -- instruments --------------------------------------------------------------------------
    def _build_instruments(self, gui: Any) -> None:
        r = INSTRUMENT_REACH
        self.instrument_inputs: list[tuple[Any, Any, Any]] = []
        with gui.add_folder("Instruments", expand_by_default=False):
            for i, name in enumerate(("left", "right")[: len(self.session.instruments)]):
                shown = gui.add_checkbox(f"show {name} instrument", False)
                x = gui.add_slider(f"{name} x (m)", -r, r, 0.002, 0.0)
                y = gui.add_slider(f"{name} y (m)", -r, r, 0.002, 0.0)

                def place(_e: Any, i: int = i, s: Any = shown, x: Any = x, y: Any = y) -> None:
                    self.session.set_instrument(i, s.value, x.value, y.value)

                update = self.guarded(place)
                for h in (shown, x, y):
                    h.on_update(update)
                self.instrument_inputs.append((shown, x, y))
            self.detector = gui.add_dropdown("detector (resets)", DETECTORS, initial_value=self.session.detector)
        self.detector.on_update(self.guarded(lambda e: self._reset_with(e.target.value)))

    # -- scenarios ----------------------------------------------------------------------------
    def _build_scenarios(self, gui: Any) -> None:
        with gui.add_folder("Scenarios"):
            self.shift = gui.add_checkbox("shift the incision 10 mm (Fig. 5)", False)
            self.play = {name: gui.add_button(f"Play {label}") for name, label in PLAYABLE.items()}
            self.stop_script = gui.add_button("Stop the scenario")
            gui.add_markdown("A scenario plays from where the scope is (Reset first to start as in the paper); "
                             "its hand and instruments move, and yours still push.")
            self.pause = gui.add_button("Pause")
            self.reset = gui.add_button("Reset")
        self.shift.on_update(self.guarded(lambda e: self.session.set_disturbance(bool(e.target.value))))
        for name, button in self.play.items():

            def play(_e: Any, name: str = name) -> None:
                self.session.play(name)

            button.on_click(self.guarded(play))
        self.stop_script.on_click(self.guarded(lambda _e: self.session.stop_script()))
        self.pause.on_click(self.guarded(lambda _e: self._toggle_pause()))
        self.reset.on_click(self.guarded(lambda _e: self._in_background(self._reset)))

    def _reset_with(self, detector: object) -> None:
        """Reset with another detector, checked here (an error raised in the background could be
        overwritten on the page by this callback's success)."""
        choice = checked_choice(detector, "detector", DETECTORS)
        self._in_background(lambda: self._reset(detector=choice))

    def _toggle_pause(self) -> None:
        self.runner.paused = not self.runner.paused
        self.pause.label = "Play" if self.runner.paused else "Pause"

    def _reset(self, detector: str | None = None) -> None:
        self.status.content = "resetting…"
        self.session.reset(detector=detector)
        self.shift.value = False
        for i, (shown, x, y) in enumerate(self.instrument_inputs):
            self.session.set_instrument(i, shown.value, x.value, y.value)
        self.runner.clear_error()
        self.pause.label = "Pause"

    def _in_background(self, fn: Callable[[], None]) -> None:
        """Run a slow action (a reset builds a new world) off the page's callback thread."""
        def run() -> None:
            try:
                fn()
            except Exception as exc:  # shown on the page
                self.show_error(f"{type(exc).__name__}: {exc}")
        threading.Thread(target=run, name="lapwrench-ui-reset", daemon=True).start()

    # -- every page frame ---------------------------------------------------------------------
    def refresh(self, snapshot: Snapshot | None, view_fps: float) -> None:
        """The status line, the resume button and errors from the sim thread (the gizmo follows the
        handle in :meth:`follow_handle`, called more often)."""
        text = status_text(snapshot, self.runner.rtf, self.runner.paused, view_fps)
        if text != self.status.content:
            self.status.content = text
        held = snapshot is not None and snapshot.held is not None
        if self.resume_button.visible != held:
            self.resume_button.visible = held
        for message in self.session.pending_errors() + ([self.runner.error] if self.runner.error else []):
            self.show_error(message)
