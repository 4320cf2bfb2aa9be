"""lapwrench: laparoscope-holding robot control through unified equivalent wrenches.

Implements Li et al., "Autonomous Laparoscope Control through Unified Mechanics-Based
Representation of Multimodal Intraoperative Information". Every cue (RCM position, handle
force/torque gated by a tactile grip array, instrument detections, damping) becomes a wrench;
the RCM wrench acts in the task space, the others in its dynamically consistent null space.
"""

__version__ = "0.1.0"
