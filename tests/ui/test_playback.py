"""Paper scenarios played in the live session: the script moves the hand and the instruments, the
page's hand is added on top, and the page's instruments come back at the end."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from lapwrench.config import Config
from lapwrench.sim.scripts import NeedleSearch, ViewAdjustment, Workflow
from lapwrench.ui.inputs import UiInputError
from lapwrench.ui.playback import DEFAULT_GRIP, PLAYABLE, ScriptPlayer, make_script
from lapwrench.ui.session import Session


def run(session: Session, seconds: float) -> None:
    for _ in range(round(seconds * 1000)):
        session.step()


@pytest.fixture
def session(cfg: Config) -> Iterator[Session]:
    s = Session(cfg, seed=1)
    yield s
    s.closed.world.close()


def test_every_playable_scenario_has_a_script_and_unknown_names_are_refused() -> None:
    assert {"needle-search", "workflow", "view-adjustment"} <= set(PLAYABLE)
    assert isinstance(make_script("needle-search"), NeedleSearch)
    assert isinstance(make_script("workflow"), Workflow)
    fig4 = make_script("view-adjustment", grip_force=0.0)
    assert isinstance(fig4, ViewAdjustment) and fig4.grip_force == DEFAULT_GRIP
    assert make_script("needle-search").duration == 26.0  # full length on the page
    with pytest.raises(UiInputError):
        make_script("grip")


def test_the_player_adds_the_page_hand_to_the_script_hand(session: Session) -> None:
    world = session.closed.world  # not stepped: both players see the same scope
    alone, with_page = (ScriptPlayer(make_script("workflow"), t0=5.0) for _ in range(2))
    assert alone.elapsed(5.25) == pytest.approx(0.25)
    push, twist = np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, 0.1])
    for t in (5.0, 5.001, 5.002):
        grip, finished = alone.apply(world, t, np.zeros(3), np.zeros(3), 0.0)
        script_force, script_torque = world.hand_force(), world.hand_torque()
        grip2, _ = with_page.apply(world, t, push, twist, 40.0)
        assert (grip, grip2, finished) == (30.0, 40.0, False)  # the firmer grip
        assert np.linalg.norm(script_force) > 0.0
        assert world.hand_force() == pytest.approx(script_force + push)
        assert world.hand_torque() == pytest.approx(script_torque + twist)
    assert alone.apply(world, 45.0, np.zeros(3), np.zeros(3), 0.0)[1]  # 40 s after it started


def test_needle_search_plays_on_the_page_and_the_tracking_follows_its_instrument(session: Session) -> None:
    with pytest.raises(UiInputError):
        session.play("nonsense")
    run(session, 0.2)
    session.play("needle-search")
    run(session, 1.5)
    snap = session.snapshot
    assert snap is not None and snap.script and snap.script_name == "needle-search"
    assert snap.script_time == pytest.approx(1.5, abs=0.02)
    assert len(snap.detections) == 1  # the script brought an instrument into view
    assert snap.mode == "tracking"
    assert session.held is None


def test_the_page_can_still_push_while_a_scenario_plays_and_stopping_it_restores_the_instruments(
    session: Session,
) -> None:
    session.play("workflow")
    session.hand.set_push(0.0, 10.0)
    run(session, 0.3)
    snap = session.snapshot
    assert snap is not None and snap.script_name == "workflow"
    _, d = session.closed.world.shaft_axis()
    page_push, _ = session.hand.wrench(d)
    assert np.linalg.norm(snap.hand_force - page_push) > 0.5  # the script's hand pushes too
    session.hand.set_push(0.0, 0.0)
    session.stop_script()
    run(session, 0.3)
    snap = session.snapshot
    assert snap is not None and not snap.script and snap.script_name == ""
    assert np.linalg.norm(snap.hand_force) == 0.0
    assert len(snap.detections) == 0  # the page shows no instrument: it went back into its port


def test_the_scripted_view_adjustment_ends_by_itself(session: Session) -> None:
    session.hand.set_grip_level("high")
    session.play("view-adjustment")
    run(session, 0.01)
    assert session.snapshot is not None and session.snapshot.script_name == "view-adjustment"
    run(session, 8.0)
    assert session.snapshot is not None and not session.snapshot.script
