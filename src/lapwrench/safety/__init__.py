"""Safety checks every control loop runs, in the simulation, the virtual model and on the robot.

* :mod:`~lapwrench.safety.supervisor`: :class:`SafetySupervisor`, the last gate every joint command
  passes, with its stop to rest; every public name of the package is importable from it.
* :mod:`~lapwrench.safety.watches`: its event log, alarm latch and the measured-state watches that
  hold the arm (RCM error, depth, residual force, joint limits, deadlines).
* :mod:`~lapwrench.safety.checks`: the compiled command and joint-limit checks, and
  :func:`~lapwrench.safety.checks.measure_scope`.
* :mod:`~lapwrench.safety.config`: :class:`~lapwrench.safety.config.SupervisorConfig`, the
  supervisor's states and events.

It sits in the loop layer (below ``sim`` and ``hardware``), so every loop can use it. Submodules
are imported directly.
"""
