"""Fixed sizes of the real-time bus's slots and rings, shared by the bus layout and the cycle codec."""

from __future__ import annotations

MAX_POINTS = 16
"""Instrument points the instruments slot holds (more detections are cut, best first)."""
TACTILE_N = 64
EVENT_BYTES = 320
