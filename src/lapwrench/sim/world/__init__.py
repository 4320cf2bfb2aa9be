"""The robot in the loop: a Franka-like joint position servo driving the MuJoCo world.

:class:`SimWorld` steps arm + laparoscope + phantom at 1 kHz with joint position references and
reads physical ground truth (trocar force, incision, RCM error, joint torques) and camera frames.
Timing, the servo law and the cost of a tick are described in :mod:`lapwrench.sim.world.stepping`.

Modules, one job each:

- :mod:`.core`: :class:`SimWorld` itself: construction (servo gains, views of ``MjData``, kernel
  binding) and the reset to rest; it is assembled from the mixins below.
- :mod:`.stepping`: the 1 kHz tick (servo references, physics substeps, stability checks).
- :mod:`.kernels`: the tick's compiled glue (numba) and the constants it reads, :data:`CONTROL_DT`.
- :mod:`.readings`: joint state and torques, frame poses, the phantom's ground truth.
- :mod:`.loads`: the hand wrench, the housing load and the instruments.
- :mod:`.rendering`: camera frames.
- :mod:`.model_facts`: facts about the compiled model worked out once (contiguous index runs,
  whether the mocap poses matter).
- :mod:`.gains`: :class:`JointServoGains`; :mod:`.errors`: :class:`SimulationUnstableError`.
"""

from lapwrench.sim.world.core import SimWorld
from lapwrench.sim.world.errors import SimulationUnstableError
from lapwrench.sim.world.gains import JointServoGains
from lapwrench.sim.world.kernels import CONTROL_DT

__all__ = ["CONTROL_DT", "JointServoGains", "SimWorld", "SimulationUnstableError"]
