"""The cameras and how the world renders: the laparoscope camera's pinhole intrinsics, the tip
camera, the external overview camera and the offscreen/visual settings.

The tip camera has the paper's pinhole intrinsics (image u along x_C, v along y_C, looking along
+z_C, OpenCV convention; checked by rendering to within 0.3 px).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from lapwrench.config import CameraConfig
from lapwrench.sim.scene.names import CAMERA_NAME, OVERVIEW_CAMERA_NAME

_PAPER_CAMERA = CameraConfig()


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of the laparoscope camera, in pixels (defaults: the configuration's,
    i.e. the paper's Sec. IV-A values)."""

    width: int = _PAPER_CAMERA.width
    height: int = _PAPER_CAMERA.height
    fx: float = _PAPER_CAMERA.fx
    fy: float = _PAPER_CAMERA.fy
    u0: float = _PAPER_CAMERA.u0
    v0: float = _PAPER_CAMERA.v0

    @classmethod
    def from_config(cls, cam: CameraConfig) -> CameraIntrinsics:
        return cls(cam.width, cam.height, cam.fx, cam.fy, cam.u0, cam.v0)

    def project(self, p_c: np.ndarray) -> np.ndarray:
        """Pixel coordinates (u, v) of points given in the camera frame {C} (shape (..., 3))."""
        p = np.asarray(p_c, dtype=float)
        z = p[..., 2]
        return np.stack([self.fx * p[..., 0] / z + self.u0, self.fy * p[..., 1] / z + self.v0], axis=-1)


def add_scope_camera(tip: mujoco.MjsBody, cam: CameraIntrinsics) -> None:
    """The laparoscope camera on the scope tip body ({C}) with the intrinsics ``cam``."""
    # MuJoCo cameras look along -z with y up; {C} looks along +z with y down: rotate pi about x.
    c = tip.add_camera(name=CAMERA_NAME, pos=[0, 0, 0], quat=[0, 1, 0, 0])
    c.resolution = [cam.width, cam.height]
    c.sensor_size = [cam.width * 1e-5, cam.height * 1e-5]  # 10 um "pixels"; only ratios matter
    c.focal_pixel = [cam.fx, cam.fy]
    # MuJoCo's principal point is an offset from the sensor centre in OpenGL window coordinates,
    # whose pixel centres sit at +0.5 (OpenCV's at integers); the signs were checked by rendering.
    c.principal_pixel = [cam.width / 2.0 - (cam.u0 + 0.5), cam.height / 2.0 - (cam.v0 + 0.5)]


def add_overview_camera(spec: mujoco.MjSpec, incision: np.ndarray) -> None:
    """External camera looking at robot and phantom (for figures like the paper's Fig. 5a)."""
    eye = incision + np.array([0.55, -1.0, 0.55])
    target = np.array([incision[0] * 0.6, incision[1], incision[2] + 0.15])
    fwd = target - eye
    fwd /= np.linalg.norm(fwd)
    x = np.cross(fwd, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(x, fwd)
    R = np.column_stack([x, y, -fwd])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, R.ravel())
    spec.worldbody.add_camera(name=OVERVIEW_CAMERA_NAME, pos=list(eye), quat=list(quat), fovy=50.0)


def configure_rendering(spec: mujoco.MjSpec, cam: CameraIntrinsics, incision: np.ndarray) -> None:
    """Offscreen buffer, headlight, clipping planes and the free camera's view of the world."""
    vis = spec.visual
    vis.global_.offwidth = max(1280, cam.width)
    vis.global_.offheight = max(960, cam.height)
    vis.quality.shadowsize = 0
    # No multisampling: on llvmpipe (software GL, this project's headless default) 4x MSAA doubles the
    # cost of a 640x480 frame (65 -> 33 ms in one interleaved run under load), and the shipped detector
    # scores the same on frames drawn without it (bench/detect.py, 200 freshly rendered test images:
    # mAP50 0.963 with 4x, 0.963 without; recall 0.931 / 0.928, one box of 306).
    vis.quality.offsamples = 0
    vis.headlight.ambient = [0.25, 0.25, 0.25]
    vis.headlight.diffuse = [0.45, 0.45, 0.45]
    vis.headlight.specular = [0.1, 0.1, 0.1]
    spec.stat.extent = 1.5
    spec.stat.center = [incision[0] / 2, incision[1] / 2, incision[2] / 2]
    vis.map.znear = 0.002 / 1.5  # 2 mm near clip: the scope camera looks at tissue 2-15 cm away
    vis.map.zfar = 10.0
