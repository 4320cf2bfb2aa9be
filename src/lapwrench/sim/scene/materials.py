"""Textures and materials of the world: the procedural tissue texture, gauze, metal, skin, floor.

The phantom and the instruments refer to these materials by name, so they are added first.
"""

from __future__ import annotations

import mujoco
import numpy as np


def _organ_texture(size: int = 512, seed: int = 7) -> np.ndarray:
    """Procedural tissue texture: pink-red base, smooth mottling, fine vessels, fat patches (tileable)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    noise = np.zeros((size, size))
    for k in range(1, 8):
        for _ in range(3):
            fx, fy = rng.integers(1, 4 * k + 2, size=2)
            ph = rng.uniform(0, 2 * np.pi, size=2)
            noise += np.sin(2 * np.pi * fx * x + ph[0]) * np.sin(2 * np.pi * fy * y + ph[1]) / k
    noise = (noise - noise.min()) / (np.ptp(noise) + 1e-9)
    base = np.array([168.0, 58.0, 56.0])
    light = np.array([226.0, 132.0, 118.0])
    img = base + (light - base) * noise[..., None]
    img *= rng.uniform(0.94, 1.06, size=(size, size, 1))  # fine grain
    fat = noise > 0.84
    img[fat] = 0.45 * img[fat] + 0.55 * np.array([232.0, 200.0, 128.0])
    vessel = np.array([120.0, 28.0, 48.0])
    for _ in range(10):  # vessels: smooth, branching-free random walks, wrapped (the texture tiles)
        p = rng.uniform(0, size, size=2)
        ang = rng.uniform(0, 2 * np.pi)
        w = int(rng.integers(0, 2))
        for _ in range(400):
            ang += rng.normal(0.0, 0.12)
            p = (p + np.array([np.cos(ang), np.sin(ang)])) % size
            i0, j0 = int(p[1]), int(p[0])
            rows = np.arange(i0 - w, i0 + w + 1) % size
            cols = np.arange(j0 - w, j0 + w + 1) % size
            img[np.ix_(rows, cols)] = 0.7 * img[np.ix_(rows, cols)] + 0.3 * vessel
    return np.clip(img, 0, 255).astype(np.uint8)


def add_materials(spec: mujoco.MjSpec) -> None:
    """Add every texture and material the scene's geoms use (tissue, organ, gauze, metal, ...)."""
    tex = _organ_texture()
    t = spec.add_texture(
        name="tissue",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        width=tex.shape[1],
        height=tex.shape[0],
        nchannel=3,
    )
    t.data = tex.tobytes()
    m = spec.add_material(name="tissue", specular=0.35, shininess=0.6, texrepeat=[1, 1])
    m.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "tissue"
    m = spec.add_material(name="organ", specular=0.5, shininess=0.7, texrepeat=[1, 1], rgba=[0.95, 0.8, 0.8, 1])
    m.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "tissue"
    spec.add_texture(
        name="gauze",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        width=64,
        height=64,
        rgb1=[0.97, 0.97, 0.95],
        rgb2=[0.86, 0.86, 0.84],
    )
    m = spec.add_material(name="gauze", texrepeat=[12, 12], specular=0.05)
    m.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "gauze"
    spec.add_material(name="metal", rgba=[0.78, 0.79, 0.82, 1], specular=1.0, shininess=0.9)
    spec.add_material(name="black", rgba=[0.04, 0.04, 0.05, 1], specular=0.4, shininess=0.5)
    spec.add_material(name="skin", rgba=[0.93, 0.76, 0.66, 1], specular=0.2, shininess=0.3)
    spec.add_material(name="housing", rgba=[0.32, 0.42, 0.55, 1], specular=0.2)
    spec.add_material(name="port", rgba=[0.2, 0.2, 0.22, 1], specular=0.3)
    spec.add_texture(
        name="floor",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        width=256,
        height=256,
        rgb1=[0.55, 0.57, 0.6],
        rgb2=[0.45, 0.47, 0.5],
    )
    m = spec.add_material(name="floor", texrepeat=[8, 8], reflectance=0.0)
    m.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "floor"
