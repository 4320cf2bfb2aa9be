"""The tuning file (``lapwrench tune TUNE.yaml``): what to search, over which scenarios, for what.

::

    name: fast-and-safe
    scenarios: [grip, rcm-disturbance, hard-push]
    seeds: [0]                      # every trial runs every scenario with every seed
    time_scale: 0.5
    config: null                    # the starting configuration (file or preset)
    detector: projected
    trials: 16                      # configurations tried
    search:                         # any config key (or world.*), each a distribution
      viscous.k_t: {loguniform: [60, 300]}
      rcm.Kp: {uniform: [1500, 4000]}
    objective: {metric: completion_time_s, reduce: mean}     # minimised over the rows that have it
    constraints:                    # must hold in every row (every run of every scenario)
      - {metric: rcm_error_max_mm, max: 1.0}
      - {metric: trocar_force_max_N, max: 5.0}

A trial whose run fails (the supervisor stopped the arm, say) breaks every constraint.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from lapwrench.config_yaml import short
from lapwrench.study.space import Dist, SpaceError, check_dist, is_number, parse_dist
from lapwrench.study.spec import StudyError, StudySpec, check_top, read_file
from lapwrench.study.spec import from_dict as study_from_dict

MAX_TRIALS = 10_000
REDUCERS = ("mean", "max", "median")
TOP_KEYS = {"name", "scenarios", "seeds", "config", "time_scale", "detector", "trials", "search", "objective",
            "constraints"}


@dataclass(frozen=True)
class Constraint:
    metric: str  # a row column, "m.<name>"
    max: float

    def excess(self, value: float) -> float:
        """How far ``value`` lies beyond the bound, relative to it (0 when it holds; NaN counts as 1)."""
        if value != value:  # NaN
            return 1.0
        return max(0.0, (value - self.max) / max(abs(self.max), 1e-9))


@dataclass(frozen=True)
class TuneSpec:
    study: StudySpec  # scenarios, seeds, base config, time scale, detector (no grid)
    search: dict[str, Dist]
    trials: int
    objective: str  # a row column, "m.<name>"
    reduce: str
    constraints: tuple[Constraint, ...]

    @property
    def name(self) -> str:
        return self.study.name


def _metric(name: Any, where: str) -> str:
    if not isinstance(name, str) or not name:
        raise StudyError(f"'{where}' must name a metric such as completion_time_s, got {short(name)}")
    return name if name.startswith("m.") else f"m.{name}"


def _objective(data: Any) -> tuple[str, str]:
    if not isinstance(data, dict) or "metric" not in data or set(data) - {"metric", "reduce"}:
        raise StudyError(f"'objective' takes metric and optional reduce ({', '.join(REDUCERS)}), got {short(data)}")
    reduce = data.get("reduce", "mean")
    if reduce not in REDUCERS:
        raise StudyError(f"'objective.reduce' must be one of {', '.join(REDUCERS)}, got {short(reduce)}")
    return _metric(data["metric"], "objective.metric"), reduce


def _constraints(data: Any) -> tuple[Constraint, ...]:
    if data is None:
        return ()
    if not isinstance(data, list):
        raise StudyError(f"'constraints' must be a list of {{metric, max}}, got {short(data)}")
    out = []
    for i, c in enumerate(data):
        if not isinstance(c, dict) or set(c) != {"metric", "max"} or not is_number(c["max"]):
            raise StudyError(f"'constraints[{i}]' must be {{metric: name, max: number}}, got {short(c)}")
        out.append(Constraint(_metric(c["metric"], f"constraints[{i}].metric"), float(c["max"])))
    return tuple(out)


def from_dict(data: Any, source: str = "tune") -> TuneSpec:
    """Validate a parsed tuning file and build its :class:`TuneSpec`."""
    data = check_top(data, TOP_KEYS, "tuning file")
    shared = {k: data[k] for k in ("name", "scenarios", "seeds", "config", "time_scale", "detector") if k in data}
    study = study_from_dict(shared, source)
    trials = data.get("trials", 8)
    if not (isinstance(trials, int) and not isinstance(trials, bool) and 1 <= trials <= MAX_TRIALS):
        raise StudyError(f"'trials' must be a whole number from 1 to {MAX_TRIALS}, got {short(trials)}")
    search_in = data.get("search")
    if not isinstance(search_in, dict) or not search_in:
        raise StudyError("'search' must map parameter keys to distributions, e.g. "
                         "viscous.k_t: {uniform: [60, 300]}")
    search: dict[str, Dist] = {}
    for key, d in search_in.items():
        try:
            if str(key).startswith("world.") or key in ("robot", "robot.kind"):
                raise SpaceError(f"'{key}' is part of the world, not a gain: tune searches configuration keys")
            search[key] = parse_dist(key, d)
            check_dist(study.base, key, search[key])
        except SpaceError as exc:
            raise StudyError(f"search: {exc}") from exc
    objective, reduce = _objective(data.get("objective"))
    return TuneSpec(study, search, trials, objective, reduce, _constraints(data.get("constraints")))


def load_tune(path: str) -> TuneSpec:
    """Read and validate a tuning file; every problem is a :class:`StudyError` naming the file."""
    data, source = read_file(path, "tuning")
    try:
        return from_dict(data, str(path))
    except StudyError as exc:
        raise StudyError(f"{source}: {exc}") from exc
