"""Safety checks every control loop runs, in the simulation, the virtual model and on the robot.

* :mod:`~lapwrench.safety.supervisor`: :class:`SafetySupervisor`, the last gate every joint command
  passes, and the measured-state watches that hold the arm.

It sits in the loop layer (below ``sim`` and ``hardware``), so every loop can use it. Submodules
are imported directly.
"""
