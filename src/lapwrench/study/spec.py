"""The study file (``lapwrench sweep STUDY.yaml``) and the jobs it expands to.

A study runs every scenario for every seed at every point of a grid, each point completed by random
draws (surgeon variability, say)::

    name: trocar-and-gain
    scenarios: [grip, rcm-disturbance]
    seeds: 10                      # or a list [0, 4, 7], or {start: 100, count: 50}
    config: null                   # base configuration: a YAML file or a preset (default: the paper's)
    time_scale: 1.0                # shorten the scenarios (0.05-1)
    detector: shipped              # the tracking scenarios' detector (shipped, classical, projected, a model path)
    grid:                          # every combination
      viscous.k_t: [100, 150, 200]
      world.trocar_stiffness: [0.5, 1.0, 2.0]
    sample:                        # drawn anew for every job (seeded: the same study draws the same values)
      world.surgeon_force: {normal: [1.0, 0.15], min: 0.5, max: 1.5}
      world.surgeon_speed: {uniform: [0.8, 1.25]}
    report:
      metrics: [completion_time_s, rcm_error_max_mm, trocar_force_max_N]
      pareto: [completion_time_s, rcm_error_max_mm]
      compare:                     # a figure of the paper beside the study's distribution
        - {label: "Fig. 4, high grip", scenario: grip, run: high, metric: completion_time_s, paper: 6.32, unit: s}

Every key and value is checked when the file is loaded (:func:`load_study`), before anything runs;
a problem is a :class:`StudyError` naming the file and the key.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lapwrench import config as config_mod
from lapwrench.config_yaml import YamlConfigError, cut, parse, read_text, short
from lapwrench.sim.scenarios import SCENARIOS
from lapwrench.study.space import Dist, SpaceError, apply, check_dist, check_key, is_number, parse_dist


@dataclass(frozen=True)
class Comparison:
    """One figure of the paper beside the study's distribution of the same quantity."""

    label: str  # e.g. "Fig. 4 completion time, high grip"
    scenario: str  # rows' "scenario"
    run: str | None  # rows' "label" (None: all runs of the scenario)
    metric: str  # a row column, e.g. "m.completion_time_s"
    paper: float | None  # the paper's value (None: no value given)
    unit: str = ""


@dataclass(frozen=True)
class ReportSpec:
    """What the report shows: the parameters to split by, the metrics, the trade-off and the comparisons."""

    title: str
    params: tuple[str, ...]  # row columns "p.<key>" to split distributions by
    metrics: tuple[str, ...]  # columns "m.<name>" whose distributions to show
    pareto: tuple[str, str] | None = ("m.completion_time_s", "m.rcm_error_max_mm")  # (x, y), both minimised
    compare: tuple[Comparison, ...] = ()


MAX_SEED = 2**32 - 1
MAX_NAME_CHARS = 100  # a study's name is its results folder's name
MAX_JOBS = 100_000  # a study bigger than this is almost surely a typo in a grid
DETECTORS = ("shipped", "classical", "projected")
DEFAULT_METRICS = ("m.completion_time_s", "m.rcm_error_max_mm", "m.trocar_force_max_N", "m.force_back_below_5N_after_s")
TOP_KEYS = {"name", "scenarios", "seeds", "config", "time_scale", "detector", "grid", "sample", "report"}


class StudyError(ValueError):
    """A bad study file; the message names the file and the key."""


@dataclass(frozen=True)
class Job:
    """One simulated run of a scenario: its seed, its parameter point, and the full inputs it runs with."""

    scenario: str
    seed: int
    params: dict[str, Any]
    config: dict[str, Any]  # the resolved configuration (lapwrench.config.to_dict)
    world: dict[str, Any]  # the resolved WorldVariation.to_dict()
    time_scale: float
    detector: str

    @property
    def run_id(self) -> str:
        """16 hex digits identifying everything the run depends on: a rerun of the same job is skipped."""
        key = {"scenario": self.scenario, "seed": self.seed, "config": self.config, "world": self.world,
               "time_scale": self.time_scale, "detector": self.detector}
        text = json.dumps(key, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class StudySpec:
    name: str
    scenarios: tuple[str, ...]
    seeds: tuple[int, ...]
    base: config_mod.Config
    time_scale: float = 1.0
    detector: str = "shipped"
    grid: dict[str, tuple[Any, ...]] = field(default_factory=dict)
    sample: dict[str, Dist] = field(default_factory=dict)
    report: ReportSpec = field(default_factory=lambda: ReportSpec(title="study", params=(), metrics=DEFAULT_METRICS))

    @property
    def params(self) -> tuple[str, ...]:
        return (*self.grid, *self.sample)

    def n_jobs(self) -> int:
        points = math.prod(len(v) for v in self.grid.values())
        return len(self.scenarios) * len(self.seeds) * points


def expand(spec: StudySpec) -> list[Job]:
    """Every job of the study, in a fixed order. A job's random draws depend on its seed and grid point
    only, so every scenario of one seed sees the same surgeon."""
    keys = list(spec.grid)
    points = list(itertools.product(*(spec.grid[k] for k in keys)))
    jobs = []
    for g, point in enumerate(points):
        for seed in spec.seeds:
            rng = np.random.default_rng([seed, g])
            params = dict(zip(keys, point, strict=True))
            params.update({k: d.draw(rng) for k, d in spec.sample.items()})
            try:
                cfg, world = apply(spec.base, params)
            except SpaceError as exc:  # two keys each fine alone but inconsistent together
                raise StudyError(f"study '{spec.name}', point {short(params)}: {exc}") from exc
            for scenario in spec.scenarios:
                jobs.append(Job(scenario, seed, params, config_mod.to_dict(cfg), world.to_dict(), spec.time_scale,
                                spec.detector))
    return jobs


# --------------------------------------------------------------------------- parsing


def _seeds(value: Any) -> tuple[int, ...]:
    count = value if isinstance(value, int) else value.get("count") if isinstance(value, dict) else None
    if isinstance(count, int) and not isinstance(count, bool) and count > MAX_JOBS:
        raise StudyError(f"'seeds' asks for {short(count)} seeds: more than {MAX_JOBS} runs")
    if isinstance(value, int) and not isinstance(value, bool):
        seeds = tuple(range(value))
    elif isinstance(value, list):
        seeds = tuple(value)
    elif isinstance(value, dict) and set(value) == {"start", "count"}:
        start, count = value["start"], value["count"]
        if not all(isinstance(x, int) and not isinstance(x, bool) for x in (start, count)):
            raise StudyError(f"'seeds' start and count must be whole numbers, got {short(value)}")
        seeds = tuple(range(start, start + count))
    else:
        raise StudyError(f"'seeds' must be a count, a list or {{start, count}}, got {short(value)}")
    if not seeds:
        raise StudyError("'seeds' gives no seed")
    for s in seeds:
        if not (isinstance(s, int) and not isinstance(s, bool) and 0 <= s <= MAX_SEED):
            raise StudyError(f"'seeds' holds {short(s)}: a seed is a whole number from 0 to 2^32-1")
    if len(set(seeds)) != len(seeds):
        raise StudyError("'seeds' lists a seed twice")
    return seeds


def _metric(name: Any, where: str) -> str:
    if not isinstance(name, str) or not name:
        raise StudyError(f"'{where}' must name a metric such as rcm_error_max_mm, got {short(name)}")
    return name if name[:2] in ("m.", "s.", "p.") else f"m.{name}"


def _report(data: Any, name: str) -> ReportSpec:
    if data is None:
        data = {}
    if not isinstance(data, dict) or set(data) - {"metrics", "pareto", "compare"}:
        raise StudyError(f"'report' takes metrics, pareto and compare, got {short(data)}")
    metrics = data.get("metrics", list(DEFAULT_METRICS))
    if not isinstance(metrics, list):
        raise StudyError(f"'report.metrics' must be a list, got {short(metrics)}")
    pareto = data.get("pareto", ["completion_time_s", "rcm_error_max_mm"])
    if pareto is not None and not (isinstance(pareto, list) and len(pareto) == 2):
        raise StudyError(f"'report.pareto' must be [x metric, y metric] or null, got {short(pareto)}")
    compare = data.get("compare", [])
    if not isinstance(compare, list):
        raise StudyError(f"'report.compare' must be a list, got {short(compare)}")
    rows = []
    for i, c in enumerate(compare):
        where = f"report.compare[{i}]"
        if not isinstance(c, dict) or not {"label", "scenario", "metric"} <= set(c) or set(c) - {
                "label", "scenario", "run", "metric", "paper", "unit"}:
            raise StudyError(f"'{where}' takes label, scenario, metric and optional run, paper, unit; got {short(c)}")
        if not isinstance(c["scenario"], str) or c["scenario"] not in SCENARIOS:
            raise StudyError(f"'{where}.scenario' {short(c['scenario'])} is not a scenario")
        paper = c.get("paper")
        if paper is not None and not is_number(paper):
            raise StudyError(f"'{where}.paper' must be a number, got {short(paper)}")
        rows.append(Comparison(str(c["label"]), c["scenario"], None if c.get("run") is None else str(c["run"]),
                               _metric(c["metric"], where), None if paper is None else float(paper),
                               str(c.get("unit", ""))))
    return ReportSpec(
        title=f"Study '{name}'",
        params=(),
        metrics=tuple(_metric(m, "report.metrics") for m in metrics),
        pareto=None if pareto is None else (_metric(pareto[0], "report.pareto"), _metric(pareto[1], "report.pareto")),
        compare=tuple(rows),
    )


def _base(value: Any) -> config_mod.Config:
    if value is not None and not isinstance(value, str):
        raise StudyError(f"'config' must be a YAML file or preset name, got {short(value)}")
    try:
        return config_mod.load(value)
    except config_mod.ConfigError as exc:
        raise StudyError(f"'config': {exc}") from exc


def _name(value: Any) -> str:
    """The study's name, stripped: it names the results folder (``reports/sweeps/<name>``), so it must be
    a plain folder name; a path (``../../etc/x``) would write outside that folder."""
    if not isinstance(value, str) or not value.strip():
        raise StudyError(f"'name' must be text, got {short(value)}")
    name = value.strip()
    if len(name) > MAX_NAME_CHARS:
        raise StudyError(f"'name' {short(name)} is longer than {MAX_NAME_CHARS} characters")
    if any(c in name for c in "/\\\0") or name in (".", ".."):
        raise StudyError(f"'name' {short(name)} must be a plain folder name (no '/', '\\' or '..')")
    if not name.isprintable():  # a line break or an escape: a folder name no shell lists plainly, a broken title
        raise StudyError(f"'name' {short(name)} must be printable text (no line break, tab or control character)")
    return name


def _check_model(detector: str, base: config_mod.Config) -> None:
    """Load a model file given as ``detector`` now, the way ``lapwrench demo --detector`` does: a missing or
    corrupt model is refused before Ray starts, not found by every run failing. The named detectors
    (the shipped model, classical, projected) come with the package."""
    if detector in DETECTORS:
        return
    from lapwrench.sim.demo import DemoError, check_detector

    try:
        check_detector(detector, base)
    except DemoError as exc:
        raise StudyError(str(exc)) from exc


def check_top(data: Any, known: set[str], what: str) -> dict[str, Any]:
    """``data`` if it is a mapping of known keys; StudyError naming the first unknown one."""
    if not isinstance(data, dict):
        raise StudyError(f"a {what} is a mapping with {', '.join(sorted(known))}")
    unknown = sorted(set(data) - known, key=str)
    if unknown:
        raise StudyError(f"unknown key {short(unknown[0])} (known: {', '.join(sorted(known))})")
    return data


def from_dict(data: Any, source: str = "study") -> StudySpec:
    """Validate a parsed study and build its :class:`StudySpec`."""
    data = check_top(data, TOP_KEYS, "study")
    name = _name(data.get("name", Path(source).stem))
    scenarios = data.get("scenarios")
    if not isinstance(scenarios, list) or not scenarios:
        raise StudyError(f"'scenarios' must list scenario names ({', '.join(SCENARIOS)})")
    for s in scenarios:
        if not isinstance(s, str) or s not in SCENARIOS:
            raise StudyError(f"'scenarios' holds {short(s)}, not a scenario ({', '.join(SCENARIOS)})")
    if len(set(scenarios)) != len(scenarios):  # the same jobs twice: twice the rows, counted twice in the report
        raise StudyError("'scenarios' lists a scenario twice")
    ts = data.get("time_scale", 1.0)
    if not (is_number(ts) and 0.05 <= ts <= 1.0):
        raise StudyError(f"'time_scale' must be a number from 0.05 to 1, got {short(ts)}")
    detector = data.get("detector", "shipped")
    if not isinstance(detector, str) or not (detector in DETECTORS or Path(detector).suffix in (".onnx", ".pt")):
        raise StudyError(f"'detector' must be one of {', '.join(DETECTORS)} or a model path, got {short(detector)}")
    base = _base(data.get("config"))
    _check_model(detector, base)
    grid_in, sample_in = data.get("grid") or {}, data.get("sample") or {}
    if not isinstance(grid_in, dict) or not isinstance(sample_in, dict):
        raise StudyError("'grid' and 'sample' must be mappings of parameter keys")
    grid: dict[str, tuple[Any, ...]] = {}
    sample: dict[str, Dist] = {}
    try:
        for key, values in grid_in.items():
            if not isinstance(values, list) or not values:
                raise SpaceError(f"'{key}' must list its values, got {short(values)}")
            resolved = check_key(base, key, tuple(values))
            if len(set(resolved)) != len(resolved):
                raise SpaceError(f"'{key}' lists the same value twice")
            grid[key] = tuple(values)
        for key, d in sample_in.items():
            if key in grid:
                raise SpaceError(f"'{key}' is both in the grid and sampled")
            sample[key] = parse_dist(key, d)
            check_dist(base, key, sample[key])
    except SpaceError as exc:
        raise StudyError(f"{'grid' if key in grid_in else 'sample'}: {exc}") from exc
    report = dataclasses.replace(_report(data.get("report"), name), params=(*grid, *sample))
    spec = StudySpec(name, tuple(scenarios), _seeds(data.get("seeds", 1)), base, float(ts), detector,
                     grid, sample, report)
    if spec.n_jobs() > MAX_JOBS:
        raise StudyError(f"{spec.n_jobs()} runs: more than {MAX_JOBS}; narrow the grid or the seeds")
    return spec


def read_file(path: str | Path, what: str) -> tuple[Any, str]:
    """The parsed YAML of a study or tuning file and its name for messages (the config's safe reader:
    size, encoding, aliases and tags are refused); StudyError naming the file."""
    source = cut(str(path), 100)
    try:
        data, _lines = parse(read_text(Path(path), source))
    except YamlConfigError as exc:
        text = str(exc).replace("config file", f"{what} file")
        raise StudyError(text if source in text else f"{source}: {text}") from exc
    return data, source


def load_study(path: str | Path) -> StudySpec:
    """Read and validate a study file; every problem is a :class:`StudyError` naming the file."""
    data, source = read_file(path, "study")
    try:
        return from_dict(data, str(path))
    except StudyError as exc:
        raise StudyError(f"{source}: {exc}") from exc
