"""The parameters that define the simulated world: :class:`PhantomConfig` and :class:`SceneConfig`.

Both validate themselves on construction; :meth:`SceneConfig.from_config` derives the world a
controller configuration runs in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lapwrench.config import Config
from lapwrench.robot.arms import arm_spec
from lapwrench.robot.description import RobotKind, ScopeGeometry
from lapwrench.sim.scene.arm import default_initial_configuration
from lapwrench.sim.scene.camera import CameraIntrinsics


@dataclass(frozen=True)
class PhantomConfig:
    """Abdominal phantom parameters (SI units).

    ``wall_stiffness`` is the lateral stiffness of the abdominal wall at the incision (~1 N/mm), in
    series with the ring contact. ``housing_stiffness`` holds the phantom on the table: a
    lateral load F shifts a free housing by F / housing_stiffness.
    """

    wall_stiffness: float = 1000.0
    wall_damping: float = 30.0
    incision_mass: float = 0.1
    trocar_mass: float = 0.03
    trocar_timeconst: float = 0.002
    ring_segments: int = 16
    ring_tube_radius: float = 0.003
    housing_mass: float = 3.0
    housing_stiffness: float = 2000.0
    housing_damping: float = 160.0
    size_x: float = 0.36
    size_y: float = 0.32
    depth: float = 0.17
    wall_thickness: float = 0.024
    tissue_depth: float = 0.145
    port_offsets: tuple[tuple[float, float], tuple[float, float]] = ((0.03, 0.09), (0.03, -0.09))

    def __post_init__(self) -> None:
        positive = (
            "wall_stiffness",
            "wall_damping",
            "incision_mass",
            "trocar_mass",
            "trocar_timeconst",
            "ring_tube_radius",
            "housing_mass",
            "housing_stiffness",
            "housing_damping",
            "size_x",
            "size_y",
            "depth",
            "wall_thickness",
            "tissue_depth",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"phantom.{name} must be a positive finite number, got {value!r}")
        if self.ring_segments < 6:
            raise ValueError(f"phantom.ring_segments must be >= 6, got {self.ring_segments!r}")
        if self.tissue_depth >= self.depth:
            raise ValueError("phantom.tissue_depth must be smaller than phantom.depth")


@dataclass(frozen=True)
class SceneConfig:
    """Everything that defines the simulated world.

    ``armature`` (kg m^2) is the reflected rotor inertia added to every arm joint, as in MuJoCo
    Menagerie's Franka models; set 0 for a pure rigid-body arm (the mass matrix then equals
    Pinocchio's). ``rcm_lambda0`` places the incision at ``lambda0 * L`` from lap_E along the shaft
    in the initial configuration (paper eq. 18).
    """

    kind: RobotKind = "panda"
    scope: ScopeGeometry = field(default_factory=ScopeGeometry)
    phantom: PhantomConfig = field(default_factory=PhantomConfig)
    camera: CameraIntrinsics = field(default_factory=CameraIntrinsics)
    timestep: float = 0.0005
    armature: float = 0.1
    q0: tuple[float, ...] | None = None
    rcm_lambda0: float = 0.8

    def __post_init__(self) -> None:
        arm = arm_spec(self.kind)  # ValueError (one line) for an arm that is not registered
        if not (0.0 < self.timestep <= 0.001 and 0.001 / self.timestep == round(0.001 / self.timestep)):
            raise ValueError(f"timestep must divide the 1 ms control period, got {self.timestep!r}")
        if not (math.isfinite(self.armature) and self.armature >= 0.0):
            raise ValueError(f"armature must be >= 0, got {self.armature!r}")
        if not (0.0 < self.rcm_lambda0 < 1.0):
            raise ValueError(f"rcm_lambda0 must lie in (0, 1), got {self.rcm_lambda0!r}")
        n = arm.n_joints
        if self.q0 is not None and len(self.q0) != n:
            raise ValueError(f"q0 needs {n} joint values, got {len(self.q0)}")

    @classmethod
    def from_config(cls, cfg: Config) -> SceneConfig:
        """The world a controller configuration runs in: same robot, scope, camera and RCM place."""
        return cls(
            kind=cfg.robot.kind,
            scope=ScopeGeometry.from_config(cfg.scope),
            camera=CameraIntrinsics.from_config(cfg.camera),
            rcm_lambda0=cfg.scope.lambda0,
        )

    def initial_configuration(self) -> np.ndarray:
        """q0 of this config (the default one unless given)."""
        return default_initial_configuration(self.kind) if self.q0 is None else np.array(self.q0, float)
