"""The page's controls: the status line and errors shown instead of raised."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from lapwrench.config import Config
from lapwrench.ui.controls import Controls, status_text
from lapwrench.ui.inputs import UiInputError
from lapwrench.ui.playback import PLAYABLE
from lapwrench.ui.runner import RealTimeRunner
from lapwrench.ui.session import Session

viser = pytest.importorskip("viser")


@pytest.fixture
def controls(cfg: Config) -> Iterator[Controls]:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    session = Session(cfg)
    runner = RealTimeRunner(session.step, lambda: session.time)
    try:
        yield Controls(server, session, runner)
    finally:
        server.stop()
        session.closed.world.close()


def test_status_text_says_speed_mode_and_holds(controls: Controls) -> None:
    assert status_text(None, 1.0, False, 25.0) == "starting…"
    session = controls.session
    for _ in range(20):
        session.step()
    snap = session.snapshot
    assert snap is not None
    text = status_text(snap, 0.8, False, 12.0)
    assert "0.80× real time" in text and "mode **idle**" in text and "12 fps" in text
    assert "paused" in status_text(snap, float("nan"), True, float("nan"))
    held = snap.__class__(**{**snap.__dict__, "held": "rcm_error: too far", "alarms": ("t = 1 s: rcm",)})
    assert "HELD: rcm_error: too far" in status_text(held, 1.0, False, 25.0)


def test_errors_from_page_callbacks_are_shown_not_raised(controls: Controls) -> None:
    def bad(_event: object) -> None:
        raise UiInputError("push magnitude (N): must be a finite number, got nan")

    controls.guarded(bad)(None)
    assert "must be a finite number" in controls.error.content
    controls.guarded(lambda _e: 1 / 0)(None)
    assert "ZeroDivisionError" in controls.error.content
    controls.guarded(lambda _e: None)(None)
    assert controls.error.content == ""


def test_refresh_shows_resume_only_while_held_and_keeps_the_gizmo_on_the_handle(controls: Controls) -> None:
    session = controls.session
    for _ in range(20):
        session.step()
    snap = session.snapshot
    assert snap is not None
    controls.refresh(snap, 25.0)
    assert not controls.resume_button.visible
    controls.follow_handle(snap)
    np.testing.assert_allclose(controls.gizmo.position, snap.hand_point, atol=1e-6)
    held = snap.__class__(**{**snap.__dict__, "held": "rcm_error"})
    controls.refresh(held, 25.0)
    assert controls.resume_button.visible


def test_every_playable_scenario_has_a_button_and_the_status_line_says_which_one_plays(controls: Controls) -> None:
    assert set(controls.play) == set(PLAYABLE)
    session = controls.session
    session.play("workflow")
    for _ in range(20):
        session.step()
    snap = session.snapshot
    assert snap is not None
    assert "playing workflow (0.0 s)" in status_text(snap, 1.0, False, 25.0)
    session.stop_script()
    for _ in range(10):
        session.step()
    assert "playing" not in status_text(session.snapshot, 1.0, False, 25.0)


def test_a_drag_end_during_the_page_threads_pull_update_leaves_the_hand_released(controls: Controls) -> None:
    """The drag's end (viser's event loop) can arrive while the page thread is updating the pull of a
    dragged gizmo (follow_handle). It must win: after it, no pull is left on the hand. Here the end is
    sent from another thread at the moment follow_handle sets the pull; without mutual exclusion the
    page thread's pull lands after the end and the hand keeps pulling (the CI failure of
    test_app's gizmo drag: 'timed out waiting for the gizmo's release')."""
    import threading
    from types import SimpleNamespace

    session = controls.session
    for _ in range(20):
        session.step()
    snap = session.snapshot
    assert snap is not None
    controls.gizmo.position = snap.hand_point + np.array([0.01, 0.0, 0.0])
    controls.gizmo_event(SimpleNamespace(phase="update", target=controls.gizmo))
    assert controls.dragging and np.any(session.hand.gizmo)
    hand_set = session.hand.set_gizmo
    ender = threading.Thread(target=controls.gizmo_event, args=(SimpleNamespace(phase="end", target=controls.gizmo),))

    def set_gizmo_while_the_end_arrives(pull: np.ndarray) -> None:
        if not ender.is_alive() and ender.ident is None:
            ender.start()
            ender.join(0.3)  # the end's thread runs now, unless it must wait for this update to finish
        hand_set(pull)

    session.hand.set_gizmo = set_gizmo_while_the_end_arrives  # type: ignore[method-assign]
    try:
        controls.follow_handle(snap)
        ender.join(5.0)
    finally:
        session.hand.set_gizmo = hand_set  # type: ignore[method-assign]
    assert not controls.dragging
    assert not np.any(session.hand.gizmo)
