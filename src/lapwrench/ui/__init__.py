"""``lapwrench ui``: a browser page (viser) to guide the simulated scope by hand, live.

The simulated world and the controller run at real time through the one control loop
(:class:`lapwrench.sim.loop.ClosedLoop`, safety supervisor included); the page shows the scene,
the laparoscope view and live plots, and drives the hand, the instruments and the parameters.

Modules, one job each:

- :mod:`.session`: the simulated session: the closed loop, the hand's and the instruments' inputs,
  holds and resumes, parameter changes, per-cycle callbacks (e.g. a telemetry publisher).
- :mod:`.inputs`: validation of the page's values and the hand's force model (no viser).
- :mod:`.playback`: the paper's scenarios played in the session (:mod:`lapwrench.sim.scripts`).
- :mod:`.history`: the scrolling window of plotted signals.
- :mod:`.runner`: the thread stepping the session at wall-clock pace, measuring the real-time factor.
- :mod:`.view`: the laparoscope view rendered in its own thread, annotated.
- :mod:`.scene`: the 3D scene from the MuJoCo geoms, and the force arrows.
- :mod:`.controls`, :mod:`.params`, :mod:`.plots`: the page's panels.
- :mod:`.untrusted`: what viser refuses from a client (garbage on the WebSocket), one line each.
- :mod:`.app`: the viser server tying them together; :mod:`.cli`: the ``ui`` command.
"""
