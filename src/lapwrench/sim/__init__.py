"""MuJoCo simulation of the laparoscope-holding robot (issue 3).

- :func:`lapwrench.sim.scene.build_scene` builds the world from the shared robot description.
- :class:`lapwrench.sim.world.SimWorld` steps it at 1 kHz with a Franka-like joint position servo and
  reads physical ground truth (trocar force, incision, RCM error, joint torques) and camera frames.

Import the submodules directly; this package does not import MuJoCo on its own.
"""
