"""lapwrench.sim.scene.materials: the materials every geom names exist, and the procedural tissue
texture is the same on every build (so renders and datasets are reproducible)."""

from __future__ import annotations

import mujoco
import numpy as np

from lapwrench.sim.scene.build import Scene
from lapwrench.sim.scene.materials import add_materials

MATERIALS = ("tissue", "organ", "gauze", "metal", "black", "skin", "housing", "port", "floor")


def compiled() -> mujoco.MjModel:
    spec = mujoco.MjSpec()
    add_materials(spec)
    return spec.compile()


def test_the_materials_the_scene_names_are_added() -> None:
    m = compiled()
    assert sorted(m.material(i).name for i in range(m.nmat)) == sorted(MATERIALS)
    tissue = m.texture("tissue")
    assert (tissue.width[0], tissue.height[0], tissue.nchannel[0]) == (512, 512, 3)
    assert m.mat_texid[m.material("organ").id][mujoco.mjtTextureRole.mjTEXROLE_RGB] == tissue.id


def test_the_tissue_texture_is_reproducible_and_tissue_coloured() -> None:
    a, b = compiled(), compiled()
    ta, tb = (m.tex_data[m.tex_adr[m.texture("tissue").id]:][: 512 * 512 * 3] for m in (a, b))
    np.testing.assert_array_equal(ta, tb)
    rgb = ta.reshape(-1, 3).astype(float).mean(axis=0)
    assert rgb[0] > rgb[1] + 40 and rgb[0] > rgb[2] + 40  # red dominates: flesh, not grey


def test_every_material_a_geom_of_the_world_uses_exists(panda_scene: Scene) -> None:
    m = panda_scene.model
    used = {m.material(int(i)).name for i in m.geom_matid if i >= 0}
    assert used <= set(MATERIALS) and {"tissue", "skin", "metal"} <= used
