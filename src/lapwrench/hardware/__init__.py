"""The hardware path: a Franka through pylibfranka, the 1 kHz loop and run logs.

* :mod:`~lapwrench.hardware.franka`: :class:`FrankaRobot` (pylibfranka joint position control).
* :mod:`~lapwrench.hardware.runner`: :class:`ControlLoop`, sensors → controller → supervisor → robot.
* :mod:`~lapwrench.hardware.log`: MCAP run logs and their report plots.
* :mod:`~lapwrench.hardware.cli`: ``lapwrench run`` and ``lapwrench log-report``.
* :mod:`~lapwrench.hardware.frankysim`: franky-sim on loopback in a child process (tests, bench).

The safety supervisor every command passes is :mod:`lapwrench.safety.supervisor`. The simulated robot
with the same interface is :class:`lapwrench.sim.robot.SimRobot`. Submodules
are imported directly; this package imports nothing heavy on its own.
"""
