"""Names of the scene's bodies, joints, sites, sensors and cameras that other modules look up.

The builders in this package create the elements under these names; the world, the sensors and the
dataset renderer find them by name in the compiled model.
"""

from __future__ import annotations

from lapwrench.robot.description import FRAME_H

# Names other modules may rely on.
FT_FORCE_SENSOR = "handle_ft_force"
FT_TORQUE_SENSOR = "handle_ft_torque"
CAMERA_NAME = "lap_camera"
# The geom group of what the laparoscope never sees: the arm with the scope's outside, and the room around
# the phantom's closed housing (floor, table). Its view (lapwrench.sim.offscreen.scope_view_option) skips it.
UNSEEN_BY_SCOPE_GROUP = 1
OVERVIEW_CAMERA_NAME = "overview"
TROCAR_BODY = "trocar"
SLEEVE_BODY = "trocar_sleeve"
TROCAR_WELD = "trocar_weld"
HANDLE_BODY = FRAME_H
HOUSING_BODY = "housing"
INCISION_BODY = "incision"
INCISION_JOINTS = ("incision_x", "incision_y")
HOUSING_JOINTS = ("housing_x", "housing_y")
RING_GEOM_PREFIX = "incision_ring_"
INSTRUMENT_BODIES = ("instrument_left", "instrument_right")
PORT_SITES = ("port_left", "port_right")
INSTRUMENT_TIP_SITES = ("instrument_left_tip", "instrument_right_tip")
NEEDLE_BODY = "needle"
GAUZE_BODIES = ("gauze_1", "gauze_2")
ORGAN_BODY = "organ"
