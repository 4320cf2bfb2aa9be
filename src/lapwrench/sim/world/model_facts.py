"""Facts about the compiled ``MjModel`` that :class:`~lapwrench.sim.world.SimWorld` works out once at
construction: whether an index set is a contiguous run (then it reads views, not copies), whether
the mocap poses (the instruments) can change the dynamics at all, and whether any contact can arise."""

from __future__ import annotations

import mujoco
import numpy as np


def _slice_if_contiguous(idx: np.ndarray) -> slice | np.ndarray:
    """``slice(a, a + n)`` when ``idx`` is a run of consecutive indices (views), else ``idx``."""
    a = int(idx[0])
    return slice(a, a + len(idx)) if np.array_equal(idx, np.arange(a, a + len(idx))) else idx


def contacts_impossible(m: mujoco.MjModel) -> bool:
    """True when collision detection can find nothing: no explicit contact pair, no flex, and no
    contype bit of any geom among the conaffinity bits of any geom (MuJoCo's filter, judged on all the
    geoms at once: a conservative answer). Disabling contacts then changes no result and skips the
    collision pass of every forward evaluation."""
    if m.npair or m.nflex:
        return False
    contype = np.bitwise_or.reduce(m.geom_contype) if m.ngeom else 0
    conaffinity = np.bitwise_or.reduce(m.geom_conaffinity) if m.ngeom else 0
    return not (int(contype) & int(conaffinity))


def mocap_is_inert(m: mujoco.MjModel) -> bool:
    """True when no mocap pose can change the dynamics: the mocap subtrees have no joints and no
    colliding geoms, and no constraint, tendon, flex or actuator refers to them."""
    if m.nmocap == 0:
        return True
    if m.ntendon or m.nflex:
        return False
    inside = np.zeros(m.nbody, bool)
    for b in range(1, m.nbody):  # parents come before children
        inside[b] = m.body_mocapid[b] >= 0 or inside[m.body_parentid[b]]
    if np.any(inside[m.jnt_bodyid]):
        return False
    contacts_on = not (m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT)
    geoms = np.flatnonzero(inside[m.geom_bodyid])
    if contacts_on and np.any((m.geom_contype[geoms] != 0) | (m.geom_conaffinity[geoms] != 0)):
        return False
    site_inside = inside[m.site_bodyid]
    geom_inside = inside[m.geom_bodyid]
    obj = mujoco.mjtObj

    def refers(objtype: int, objid: int) -> bool:
        if objid < 0:
            return False
        if objtype in (int(obj.mjOBJ_BODY), int(obj.mjOBJ_XBODY)):
            return bool(inside[objid])
        if objtype == int(obj.mjOBJ_SITE):
            return bool(site_inside[objid])
        if objtype == int(obj.mjOBJ_GEOM):
            return bool(geom_inside[objid])
        return False

    for e in range(m.neq):
        t = int(m.eq_type[e])
        if t in (int(mujoco.mjtEq.mjEQ_CONNECT), int(mujoco.mjtEq.mjEQ_WELD)):
            ot = int(m.eq_objtype[e])
            if refers(ot, int(m.eq_obj1id[e])) or refers(ot, int(m.eq_obj2id[e])):
                return False
        elif t != int(mujoco.mjtEq.mjEQ_JOINT):
            return False  # tendon/flex/other equalities: not reasoned about
    trn = mujoco.mjtTrn
    for a in range(m.nu):
        t = int(m.actuator_trntype[a])
        if t in (int(trn.mjTRN_SITE), int(trn.mjTRN_SLIDERCRANK)):
            if any(refers(int(obj.mjOBJ_SITE), int(i)) for i in m.actuator_trnid[a]):
                return False
        elif t == int(trn.mjTRN_BODY):
            if refers(int(obj.mjOBJ_BODY), int(m.actuator_trnid[a, 0])):
                return False
        elif t not in (int(trn.mjTRN_JOINT), int(trn.mjTRN_JOINTINPARENT)):
            return False
    return True
