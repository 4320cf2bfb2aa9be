"""The error the simulated world raises when it diverges (:mod:`lapwrench.sim.world.errors`): what it
carries, how it reads, and who catches it."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from lapwrench.robot.errors import RobotError
from lapwrench.sim.world import SimulationUnstableError, SimWorld


def test_it_names_the_time_the_quantity_and_the_value() -> None:
    exc = SimulationUnstableError(1.23456, "shaft-incision contact force |F| (N)", "912.0")
    assert (exc.time, exc.quantity, exc.value) == (1.23456, "shaft-incision contact force |F| (N)", "912.0")
    assert str(exc) == "simulation unstable at t = 1.2346 s: shaft-incision contact force |F| (N) = 912.0"


@pytest.mark.parametrize(("value", "shown"), [(0.0123, "0.0123"), (float("nan"), "nan"), ("non-finite", "non-finite")])
def test_a_number_or_a_word_reads_as_given(value: float | str, shown: str) -> None:
    assert str(SimulationUnstableError(0.0, "state (qpos/qvel)", value)).endswith(f"state (qpos/qvel) = {shown}")


def test_it_is_a_robot_error() -> None:
    """The loop catches a failing robot as RobotError (logs it, disconnects, re-raises): the simulated
    robot's divergence takes the same path as a real robot's fault."""
    with pytest.raises(RobotError, match="simulation unstable"):
        raise SimulationUnstableError(2.0, "state (qpos/qvel)", "non-finite")
    assert issubclass(SimulationUnstableError, RuntimeError)


def test_the_world_raises_it_on_a_non_finite_reference(world: SimWorld) -> None:
    world.step(world.scene.q0)
    q = world.scene.q0.copy()
    q[2] = np.nan
    with pytest.raises(SimulationUnstableError) as info:
        world.step(q)
    assert info.value.quantity == "joint reference q_ref"
    assert info.value.time == pytest.approx(0.001)
    assert str(info.value).startswith("simulation unstable at t = 0.0010 s: joint reference q_ref = array([")


def test_it_survives_a_process_boundary() -> None:
    """Scenarios run in worker processes (the demo, the sweeps). Both turn this error into text inside
    the worker today; an exception that escapes a worker comes back to the parent pickled."""
    exc = SimulationUnstableError(0.5, "insertion depth of the incision along the shaft (m)", "-0.0010")
    back = pickle.loads(pickle.dumps(exc))
    assert (back.time, back.quantity, back.value, str(back)) == (exc.time, exc.quantity, exc.value, str(exc))
