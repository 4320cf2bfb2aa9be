"""The arm registry (:mod:`lapwrench.robot.arms`): every spec loads in both engines and agrees with itself.

Each registered arm's description loads in Pinocchio and MuJoCo with the spec's joints, its limit
tables are consistent with the description, its start poses lie inside the limits with the scope
straight down, and the controller holds the RCM on its virtual model. The FR3 needs franky-sim
(skipped without it).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from lapwrench.config import ConfigError, load
from lapwrench.robot.arms import ARM_SPECS, MAX_JOINTS, RobotDescriptionError, arm_spec
from lapwrench.robot.description import FRAME_E, ScopeGeometry
from lapwrench.robot.limits import arm_limits, franka_limits, joint_torque_limits
from lapwrench.robot.model import RobotModel
from lapwrench.robot_kinds import NOT_SHIPPED, ROBOT_KINDS
from lapwrench.sim.scene.arm import build_arm_spec, flange_pose_at
from lapwrench.virtual import HandScript, home_pose, run_virtual

KINDS = list(ARM_SPECS)


def model_of(kind: str) -> RobotModel:
    """The arm's Pinocchio model; the test is skipped if its description's package is missing."""
    try:
        return RobotModel(kind)
    except RobotDescriptionError as exc:
        pytest.skip(str(exc))


def test_the_registry_is_the_list_the_config_accepts() -> None:
    assert tuple(ARM_SPECS) == ROBOT_KINDS
    assert set(ROBOT_KINDS) >= {"panda", "fr3", "ur5", "xarm7"}
    assert max(s.n_joints for s in ARM_SPECS.values()) == MAX_JOINTS
    assert [k for k, s in ARM_SPECS.items() if s.hardware] == ["panda", "fr3"]
    assert {s.n_joints for s in ARM_SPECS.values()} >= {6, 7}  # 6-DoF and 7-DoF arms ship


@pytest.mark.parametrize("kind", KINDS)
def test_spec_loads_in_pinocchio_and_mujoco_with_the_same_joints(kind: str) -> None:
    spec = arm_spec(kind)
    model = model_of(kind)
    names = [model.model.names[i] for i in range(1, model.model.njoints)]
    assert names == list(spec.joint_names) and model.nq == model.nv == spec.n_joints
    m = build_arm_spec(kind).compile()
    assert [m.joint(i).name for i in range(m.njnt)] == list(spec.joint_names)
    assert m.nq == spec.n_joints
    lo, hi = model.limits.position_lower, model.limits.position_upper
    np.testing.assert_allclose(m.jnt_range[:, 0], lo, atol=1e-9)
    np.testing.assert_allclose(m.jnt_range[:, 1], hi, atol=1e-9)


@pytest.mark.parametrize("kind", KINDS)
def test_limit_tables_are_positive_and_match_the_description(kind: str) -> None:
    model = model_of(kind)
    lim = model.limits
    for name in ("velocity", "acceleration", "jerk", "torque", "torque_rate"):
        v = getattr(lim, name)
        assert v.shape == (model.nv,) and np.all(np.isfinite(v)) and np.all(v > 0), name
    assert np.all(lim.position_lower < lim.position_upper)
    np.testing.assert_array_equal(lim.torque, model.model.effortLimit)  # the published torques, also the URDF's
    assert np.all(lim.velocity <= model.model.velocityLimit + 1e-9)  # never faster than the description allows
    np.testing.assert_array_equal(joint_torque_limits(kind), lim.torque)
    np.testing.assert_array_equal(arm_limits(kind).jerk, franka_limits(kind).jerk)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("pose", ["home_pose", "sim_start_pose"])
def test_start_poses_lie_well_inside_the_limits_with_the_scope_straight_down(kind: str, pose: str) -> None:
    model = model_of(kind)
    q = np.array(getattr(arm_spec(kind), pose))
    margin = np.minimum(q - model.limits.position_lower, model.limits.position_upper - q)
    assert np.all(margin > 0.3), margin
    d_z = model.kinematics(q, np.zeros(model.nv)).d_z
    assert d_z @ np.array([0.0, 0.0, -1.0]) > np.cos(np.radians(0.1))


@pytest.mark.parametrize("kind", KINDS)
def test_sim_start_puts_the_flange_over_the_trocar_area_in_both_engines(kind: str) -> None:
    """Flange 0.482 m above the base, 0.5 m in front, where the scene puts the trocar below it; MuJoCo's
    flange pose is Pinocchio's."""
    model = model_of(kind)
    q0 = arm_spec(kind).sim_start_pose
    pose = model.frame_pose(np.array(q0), FRAME_E)
    np.testing.assert_allclose(pose.translation, [0.5, 0.0, 0.482], atol=2e-3)
    p, R = flange_pose_at(kind, ScopeGeometry(), tuple(q0))
    np.testing.assert_allclose(p, pose.translation, atol=1e-6)
    np.testing.assert_allclose(R, pose.rotation, atol=1e-6)


def test_a_spec_needs_one_value_per_joint() -> None:
    spec = arm_spec("ur5")
    with pytest.raises(ValueError, match="sim_start_pose"):
        dataclasses.replace(spec, sim_start_pose=spec.sim_start_pose[:-1])
    with pytest.raises(ValueError, match=r"limits\.torque"):
        dataclasses.replace(spec, limits=dataclasses.replace(spec.limits, torque=(1.0,) * (spec.n_joints + 1)))


@pytest.mark.parametrize("name", ["ur5e", "gen3", "kuka"])
def test_an_unshipped_arm_is_refused_in_one_line(name: str) -> None:
    with pytest.raises(ValueError) as exc:
        arm_spec(name)
    text = str(exc.value)
    assert "\n" not in text
    assert ("mujoco-menagerie" in text) == (name in NOT_SHIPPED)
    with pytest.raises(ConfigError, match=r"^config key 'robot.kind'") as cexc:
        load().replace(robot={"kind": name})
    assert cexc.value.key == "robot.kind" and "\n" not in str(cexc.value)


@pytest.mark.parametrize("kind", KINDS)
def test_the_config_accepts_every_registered_arm(kind: str) -> None:
    assert load().replace(robot={"kind": kind}).robot.kind == kind


@pytest.mark.parametrize("kind", KINDS)
def test_the_controller_holds_the_rcm_on_each_arms_virtual_model(kind: str) -> None:
    """3 s on the controller's own model: a 6 N push on the gripped handle, then release."""
    model_of(kind)
    cfg = load().replace(robot={"kind": kind})
    hand = HandScript(
        force=lambda t: np.array([6.0, 0.0, 0.0]) if 0.5 <= t < 2.0 else np.zeros(3),
        delta=lambda t: 2.0 if t < 2.2 else 0.0,
    )
    _, log = run_virtual(cfg, 3.0, hand)
    assert log.alarm is None
    q = log.array("q_ref")
    assert np.max(np.abs(q - home_pose(kind))) > 1e-3  # the push moved the arm
    assert np.max(log.array("rcm_error")) < 1e-3  # m: the RCM held within 1 mm


def test_the_armature_and_servos_use_each_arms_torque_limits() -> None:
    from lapwrench.sim.scene.arm import add_joint_servos

    for kind in ("ur5", "xarm7"):
        spec = build_arm_spec(kind)
        add_joint_servos(spec, kind)
        m: mujoco.MjModel = spec.compile()
        np.testing.assert_array_equal(m.jnt_actfrcrange[:, 1], arm_spec(kind).limits.torque)
