"""``lapwrench identify-grip LOG``: the grip's mass and centre of mass from a run's log (not in the paper).

The handle's F/T sensor reads the weight of the grip beyond it (``scope.grip_mass`` at ``scope.grip_com``,
:mod:`lapwrench.wrenches.grip_weight`), which the user must enter for their own handle. A run in which
the scope turned while nobody touched the handle gives both, without a motion program of its own:
this reads the log's cycles (:func:`~lapwrench.hardware.log.iter_messages`, one at a time), keeps those

- with the handle untouched: a tactile reading whose grip gain δ (eq 7,
  :func:`~lapwrench.wrenches.interaction.grip_gain`, with the run's ``interaction`` section) is 0; a
  log without any tactile reading is refused unless ``--assume-untouched`` (then a cycle without one
  counts as untouched),
- with the arm nearly still: every measured |q̇| at most ``--max-speed`` (the grip's inertia is left
  out of the model),
- with finite joints, velocities, force and torque,

evenly subsamples them to :data:`MAX_SAMPLES`, computes R_H at each one's measured joints with the robot
model of the run ({H} is parallel to {E}) and fits (:func:`~lapwrench.hardware.grip_fit.fit_grip`).

The run's configuration is the one the log's meta message carries (``lapwrench run`` writes it);
``--config`` replaces it (and stands in when the log has none: then the defaults), ``--robot`` replaces
its arm. A truncated log (the run was killed) is read as far as it goes, with a line on stderr, as
``lapwrench log-report`` does. Every bad input is one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from array import array
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from lapwrench import config as config_mod
from lapwrench.cli_types import display_path, float_in
from lapwrench.hardware.grip_fit import GripFit, GripFitError, fit_grip
from lapwrench.hardware.log.reader import LogFileError, check_log_file, iter_messages
from lapwrench.hardware.log.topics import CYCLE_TOPIC, META_TOPIC

__all__ = [
    "DEFAULT_MAX_SPEED", "MAX_SAMPLES", "GripIdentifyError", "GripSamples", "add_identify_grip_arguments",
    "config_snippet", "identify", "identify_grip_main", "log_meta", "read_samples", "report", "run_config",
]

MAX_SAMPLES = 20_000  # readings fitted at most (evenly spaced among the kept cycles)
DEFAULT_MAX_SPEED = 0.05  # rad/s: the fastest joint of a cycle counted as still
MAX_SPEED_LIMIT = 5.0  # rad/s: beyond any arm's joint speed
_ROW = 6  # force and torque of a kept cycle (beside its joints)


class GripIdentifyError(ValueError):
    """A log or option ``identify-grip`` cannot use; the message is one line saying what to do."""


class GripSamples(NamedTuple):
    """What a log gives the fit: rotations of {H} in {B} (N, 3, 3), forces and torques in {H} (N, 3) of the
    cycles picked, and how many cycles the log has (read, for a truncated one), how many of them have
    the handle untouched, and how many of those also the arm still and every value finite (``kept``;
    at most :data:`MAX_SAMPLES` of them evenly spaced are picked)."""

    R_H: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    cycles: int
    untouched: int
    kept: int
    truncated: bool


class _Kept:
    """The kept cycles' numbers, in flat growing arrays (a long log never holds its cycles as dicts)."""

    def __init__(self) -> None:
        self.q = array("d")
        self.rest = array("d")
        self.nq = 0


def run_config(meta: Mapping[str, Any] | None, config: str | None, robot: str | None) -> config_mod.Config:
    """The run's configuration: ``config`` (a file or preset) if given, else the log's ``meta["config"]``,
    else the defaults; with ``robot`` as its arm if given. :class:`GripIdentifyError` if it does not load."""
    logged = None if meta is None else meta.get("config")
    try:
        if config is not None:
            cfg = config_mod.load(config)
        elif isinstance(logged, dict):
            try:
                cfg = config_mod.from_dict(logged)
            except config_mod.ConfigError as exc:
                raise GripIdentifyError(f"the log's configuration does not load ({exc}); give --config") from exc
        elif logged is not None:  # not the defaults in silence: the run may have had another arm or grip
            raise GripIdentifyError(f"the log's configuration is not a mapping of sections (a {type(logged).__name__});"
                                    " give --config")
        else:
            cfg = config_mod.load()
        return cfg if robot is None else cfg.replace(robot={"kind": robot})
    except config_mod.ConfigError as exc:
        raise GripIdentifyError(str(exc)) from exc


def log_meta(path: str | Path) -> dict[str, Any] | None:
    """The log's meta message (``lapwrench run`` writes its configuration there), None without one."""
    messages = iter_messages(path, [META_TOPIC], allow_truncated=True)
    try:
        meta = next((m for _, m in messages), None)
    finally:
        messages.close()  # type: ignore[attr-defined]
    return meta if isinstance(meta, dict) else None


def _vector(c: Mapping[str, Any], key: str, n: int | None = None) -> np.ndarray | None:
    """A cycle's field as a 1-D float array (None when absent, not a list of numbers, of another
    length or not finite: a foreign or damaged log's ``"q": "abc"`` is a missing value, not a crash)."""
    v = c.get(key)
    if not isinstance(v, list | tuple) or (n is not None and len(v) != n):
        return None
    if not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v):
        return None  # None (a missing value), text, a nested list
    try:
        a = np.asarray(v, dtype=float)
    except OverflowError:  # an integer beyond any float
        return None
    return a if a.ndim == 1 and np.isfinite(a).all() else None


def _untouched(c: Mapping[str, Any], cfg: config_mod.Config, assume_untouched: bool) -> tuple[bool, bool]:
    """(untouched, has tactile) of one cycle: δ = 0 by eq (7) with the run's interaction section; no
    reading counts as untouched only when assumed."""
    from lapwrench.wrenches.interaction import grip_gain

    tactile = c.get("tactile")
    if tactile is None:
        return assume_untouched, False
    values = _vector(c, "tactile")
    if values is None:
        return False, True
    i = cfg.interaction
    delta, _ = grip_gain(values, float(i.k_H), int(i.k_min), float(i.contact_threshold))
    return delta == 0.0, True


def read_samples(
    path: str | Path, *, config: str | None = None, robot: str | None = None, assume_untouched: bool = False,
    max_speed: float = DEFAULT_MAX_SPEED, max_samples: int = MAX_SAMPLES,
) -> GripSamples:
    """The untouched, still cycles of the log at ``path`` (module docstring), with the run's configuration
    (:func:`run_config`). :class:`GripIdentifyError` or :class:`~lapwrench.hardware.log.reader.LogFileError`
    (one line each) for a log that gives none."""
    try:
        check_log_file(path)
        truncated = False
    except LogFileError:
        check_log_file(path, allow_truncated=True)  # raises for what cannot be read at all
        truncated = True
    cfg = run_config(log_meta(path), config, robot)
    kept, cycles, untouched, with_tactile = _Kept(), 0, 0, 0
    for _, c in iter_messages(path, [CYCLE_TOPIC], allow_truncated=True):
        cycles += 1
        free, has_tactile = _untouched(c, cfg, assume_untouched)
        with_tactile += has_tactile
        if not free:
            continue
        untouched += 1
        q, dq = _vector(c, "q"), _vector(c, "dq")
        force, torque = _vector(c, "ft_force", 3), _vector(c, "ft_torque", 3)
        if q is None or dq is None or force is None or torque is None or dq.size != q.size:
            continue
        if float(np.abs(dq).max()) > max_speed or (kept.nq and q.size != kept.nq):
            continue
        kept.nq = q.size
        kept.q.extend(q)
        kept.rest.extend((*force, *torque))
    _check_counts(path, cycles, with_tactile, untouched, len(kept.rest) // _ROW, assume_untouched, max_speed, truncated)
    return _samples(kept, cfg, cycles, untouched, truncated, max_samples)


def _check_counts(
    path: str | Path, cycles: int, with_tactile: int, untouched: int, kept: int, assume_untouched: bool,
    max_speed: float, truncated: bool,
) -> None:
    if cycles == 0:
        cut = " (truncated before its first complete cycle)" if truncated else ""
        raise GripIdentifyError(f"{path}: no {CYCLE_TOPIC} messages{cut}")
    if with_tactile == 0 and not assume_untouched:
        raise GripIdentifyError(f"{path}: no tactile readings in {cycles} cycles, so a gripped handle cannot be told"
                                " from an untouched one; give --assume-untouched if nobody touched the handle")
    if untouched == 0:
        raise GripIdentifyError(f"{path}: the handle was gripped (or its tactile reading missing) in all {cycles}"
                                " cycles; record a run in which the scope turns while nobody touches the handle")
    if kept == 0:
        raise GripIdentifyError(f"{path}: of {untouched} untouched cycles none had the arm still (every |dq| <="
                                f" {max_speed:g} rad/s) with finite joints and F/T readings; raise --max-speed or"
                                " let the scope rest at a few orientations")


def _samples(
    kept: _Kept, cfg: config_mod.Config, cycles: int, untouched: int, truncated: bool, max_samples: int
) -> GripSamples:
    """The kept cycles, evenly subsampled to ``max_samples``, with R_H at their joints."""
    from lapwrench.robot.description import ScopeGeometry
    from lapwrench.robot.model import RobotModel

    q = np.frombuffer(kept.q, dtype=float).reshape(-1, kept.nq)
    rest = np.frombuffer(kept.rest, dtype=float).reshape(-1, _ROW)
    n = q.shape[0]
    pick = np.unique(np.linspace(0, n - 1, min(n, max_samples)).round().astype(int))
    model = RobotModel(cfg.robot.kind, ScopeGeometry.from_config(cfg.scope))
    if model.nq != kept.nq:
        raise GripIdentifyError(f"the log's arm has {kept.nq} joints, the {cfg.robot.kind} {model.nq}: give --robot"
                                " (or --config) of the run")
    R_H = np.empty((pick.size, 3, 3))
    for i, k in enumerate(pick):
        R_H[i] = model.placement_E_into(q[k])[0]  # {H} is parallel to {E}; copied: the view is overwritten
    return GripSamples(R_H, rest[pick, 0:3].copy(), rest[pick, 3:6].copy(), cycles, untouched, n, truncated)


def identify(
    path: str | Path, *, config: str | None = None, robot: str | None = None, assume_untouched: bool = False,
    max_speed: float = DEFAULT_MAX_SPEED,
) -> tuple[GripFit, GripSamples]:
    """The grip fitted from the log at ``path`` and the samples it used (:func:`read_samples`,
    :func:`~lapwrench.hardware.grip_fit.fit_grip`); their errors as they are."""
    samples = read_samples(path, config=config, robot=robot, assume_untouched=assume_untouched, max_speed=max_speed)
    return fit_grip(samples.R_H, samples.force, samples.torque), samples


def config_snippet(fit: GripFit) -> str:
    """The ``scope:`` lines to paste into a configuration (0.1 g and 0.1 mm resolution)."""
    com = ", ".join(f"{x:.4f}" for x in fit.com + 0.0)  # + 0.0: no "-0.0000"
    return f"scope:\n  grip_mass: {fit.mass:.4f}\n  grip_com: [{com}]"


def report(path: str | Path, fit: GripFit, samples: GripSamples) -> str:
    """What ``identify-grip`` prints: the fit and the configuration lines."""

    def vec(v: np.ndarray, scale: float, digits: int) -> str:
        return "[" + ", ".join(f"{x * scale:.{digits}f}" for x in v + 0.0) + "]"

    return "\n".join([
        f"grip identified from {path}: {samples.kept} of {samples.cycles} cycles untouched with the arm still"
        f" ({samples.untouched} untouched), {fit.samples} fitted; tilt span {fit.tilt_span_deg:.1f}°",
        f"  mass            {fit.mass * 1e3:.1f} ± {fit.mass_sigma * 1e3:.1f} g",
        f"  centre of mass  {vec(fit.com, 1e3, 1)} ± {vec(fit.com_sigma, 1e3, 1)} mm in {{H}}",
        f"  force bias      {vec(fit.force_bias, 1.0, 3)} N",
        f"  torque bias     {vec(fit.torque_bias, 1.0, 4)} N m",
        f"  residual RMS    force {fit.force_rms:.3f} N, torque {fit.torque_rms:.4f} N m",
        "paste into the configuration:",
        config_snippet(fit),
    ])


def identify_grip_main(args: argparse.Namespace) -> int:
    """``lapwrench identify-grip``: 0 with the fit printed; 2 with one line on stderr for a bad input."""
    from lapwrench.robot_kinds import ROBOT_KINDS, unknown_kind_message

    try:
        if args.robot is not None and args.robot not in ROBOT_KINDS:
            raise GripIdentifyError(f"--robot {unknown_kind_message(args.robot)}")
        fit, samples = identify(args.log, config=args.config, robot=args.robot,
                                assume_untouched=args.assume_untouched, max_speed=args.max_speed)
    except (GripIdentifyError, GripFitError, LogFileError) as exc:
        print(f"lapwrench identify-grip: {exc}", file=sys.stderr)
        return 2
    if samples.truncated:
        print(f"lapwrench identify-grip: {args.log} is truncated; read {samples.cycles} cycles", file=sys.stderr)
    print(report(display_path(args.log), fit, samples))
    return 0


def add_identify_grip_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``lapwrench identify-grip``."""
    parser.add_argument("log", help="an MCAP run log (lapwrench run --log) in which the scope turned untouched")
    parser.add_argument("--config", help="the run's configuration (default: the one in the log, else the defaults)")
    parser.add_argument("--robot", metavar="NAME", default=None,
                        help="the run's arm: panda, fr3, ur5 or xarm7 (default: the configuration's robot.kind)")
    parser.add_argument("--assume-untouched", action="store_true",
                        help="count cycles without a tactile reading as untouched (a log without tactile data)")
    parser.add_argument(
        "--max-speed", type=float_in(0.0, MAX_SPEED_LIMIT, lo_open=True), default=DEFAULT_MAX_SPEED, metavar="RAD_S",
        help=f"fastest joint speed of a cycle counted as still (rad/s, default {DEFAULT_MAX_SPEED:g})",
    )
