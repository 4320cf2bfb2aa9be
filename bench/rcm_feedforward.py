"""Benchmark: the RCM error with and without ``rcm.feedforward`` (README, "Where the printed paper and this
code part ways", item 9), on the controller's virtual dynamics, the same starts and pushes for both.

Three groups of ``--starts`` runs each, ``--seconds`` long, a hand at δ = 2 pushing with a constant force
of 10-30 N and a torque of up to 1.2 N m (5-30 N, 0.5 N m from home):

- ``ur5_wrist``: the UR5 with its wrist near the singularity (|q5| 0.03-0.15 rad), the rest of its
  home pose moved by 0.2 rad;
- ``panda_ill_conditioned``: the Panda at the poses of least lateral manipulability the search finds
  (the lateral RCM task's smallest singular value minimised from random starts, scipy's L-BFGS-B
  inside the joint limits: 0.06-0.18 against 0.64 at home, printed; not singular);
- ``panda_home``: the Panda from its home pose.

Reports each group's largest and median RCM error (mm) off and on, the ratio, and the runs the
supervisor held with an alarm. Last line: one JSON object.

    python bench/rcm_feedforward.py [--starts N] [--seconds S] [--seed K]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Callable

import numpy as np
from scipy.optimize import minimize

from lapwrench.config import Config, load
from lapwrench.controller import Controller
from lapwrench.rcm.geometry import lateral_rcm_jacobian, lateral_task
from lapwrench.virtual import HandScript, home_pose, run_virtual

Start = tuple[str, np.ndarray, np.ndarray, np.ndarray]  # robot kind, q0, force (N, in {H}), torque (N m)


def config(kind: str, feedforward: bool) -> Config:
    base = load()
    return dataclasses.replace(base, robot=dataclasses.replace(base.robot, kind=kind),
                               rcm=dataclasses.replace(base.rcm, feedforward=feedforward))


def push(rng: np.random.Generator, lo: float, hi: float) -> np.ndarray:
    f = rng.uniform(-1.0, 1.0, 3)
    return f * rng.uniform(lo, hi) / np.linalg.norm(f)


def lateral_sigma_min(ctrl: Controller, q: np.ndarray) -> float:
    """The smallest singular value of the lateral RCM task (p_R 0.8 L down the shaft) at ``q``."""
    kin = ctrl.model.kinematics(q, np.zeros(q.shape[0]))
    J = lateral_task(kin.R_E, lateral_rcm_jacobian(kin, kin.p_E + 0.8 * ctrl.model.length * kin.d_z))
    return float(np.linalg.svd(J, compute_uv=False)[-1])


def ill_conditioned_panda_pose(ctrl: Controller, rng: np.random.Generator) -> np.ndarray:
    """A Panda pose of least lateral manipulability near a random start (:func:`lateral_sigma_min` minimised)."""
    lim = ctrl.model.limits
    lo, hi = lim.position_lower + 0.051, lim.position_upper - 0.051
    q0 = np.clip(home_pose("panda") + rng.normal(0.0, 0.7, 7), lo + 0.01, hi - 0.01)
    bounds = list(zip(lo, hi, strict=True))
    return np.asarray(minimize(lambda q: lateral_sigma_min(ctrl, q), q0, method="L-BFGS-B", bounds=bounds).x)


def starts(n: int, rng: np.random.Generator) -> dict[str, list[Start]]:
    ur5 = []
    for _ in range(n):
        q = home_pose("ur5") + np.r_[rng.normal(0.0, 0.2, 4), 0.0, rng.normal(0.0, 0.2)]
        q[4] = rng.uniform(0.03, 0.15) * rng.choice([-1.0, 1.0])
        ur5.append(("ur5", q, push(rng, 10.0, 30.0), rng.uniform(-1.2, 1.2, 3)))
    panda = Controller(config("panda", True))
    ill = [("panda", ill_conditioned_panda_pose(panda, rng), push(rng, 10.0, 30.0), rng.uniform(-1.0, 1.0, 3))
           for _ in range(n)]
    sigma = [lateral_sigma_min(panda, s[1]) for s in ill]
    print(f"panda_ill_conditioned: lateral task's smallest singular value {min(sigma):.3f}-{max(sigma):.3f} "
          f"(home {lateral_sigma_min(panda, home_pose('panda')):.3f})")
    home = [("panda", home_pose("panda"), push(rng, 5.0, 30.0), rng.uniform(-0.5, 0.5, 3)) for _ in range(n)]
    return {"ur5_wrist": ur5, "panda_ill_conditioned": ill, "panda_home": home}


def constant(v: np.ndarray) -> Callable[[float], np.ndarray]:
    return lambda t: v


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=20, help="runs per group (default 20)")
    ap.add_argument("--seconds", type=float, default=1.5, help="length of each run (default 1.5 s)")
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    controllers: dict[tuple[str, bool], Controller] = {}
    out: dict[str, float] = {}
    for group, runs in starts(args.starts, np.random.default_rng(args.seed)).items():
        errors: dict[bool, list[float]] = {False: [], True: []}
        holds = {False: 0, True: 0}
        for kind, q0, force, torque in runs:
            for ff in (False, True):
                cfg = config(kind, ff)
                ctrl = controllers.setdefault((kind, ff), Controller(cfg))
                hand = HandScript(constant(force), constant(torque), lambda t: 2.0)
                _, log = run_virtual(cfg, args.seconds, hand, q0=q0, controller=ctrl)
                errors[ff].append(float(log.array("rcm_error").max() * 1e3))
                holds[ff] += log.alarm is not None
        off, on = np.array(errors[False]), np.array(errors[True])
        print(f"{group}: {len(runs)} runs, RCM error max off {off.max():.3f} / on {on.max():.3f} mm, "
              f"median {np.median(off):.3f} / {np.median(on):.3f} mm, holds {holds[False]} / {holds[True]}")
        out |= {f"{group}_rcm_max_off_mm": round(float(off.max()), 4),
                f"{group}_rcm_max_on_mm": round(float(on.max()), 4),
                f"{group}_max_ratio_off_to_on": round(float(off.max() / max(on.max(), 1e-9)), 1),
                f"{group}_holds_off": holds[False], f"{group}_holds_on": holds[True]}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
