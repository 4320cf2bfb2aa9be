"""The tuning run's report: the trade-off the search found (plot and table) and the best configuration."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lapwrench.study.plots import text
from lapwrench.study.tune_spec import TuneSpec

SHOWN_TRIALS = 20


def _num(x: Any) -> float:
    return float(x) if isinstance(x, int | float) and not isinstance(x, bool) else math.nan


def _feasible(trial: dict[str, Any]) -> bool:
    """Whether the trial met every constraint (Ray may hand the flag back as a numpy bool)."""
    return trial.get("feasible") in (True, np.True_)


def plot_tradeoff(trials: Sequence[dict[str, Any]], spec: TuneSpec, path: Path) -> bool:
    """Objective against the summed constraint excess, one point per trial (feasible ones at 0);
    False if no trial has a finite objective."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = [(_num(t.get("excess")), _num(t.get("objective")), _feasible(t)) for t in trials]
    pts = [p for p in pts if math.isfinite(p[0]) and math.isfinite(p[1])]
    if not pts:
        return False
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for meets, color, label in ((True, "tab:green", "meets every constraint"), (False, "tab:red", "breaks one")):
        sel = [p for p in pts if p[2] is meets]
        if sel:
            ax.scatter([p[0] for p in sel], [p[1] for p in sel], c=color, label=label, s=28)
    feasible = [p for p in pts if p[2]]
    if feasible:
        best = min(feasible, key=lambda p: p[1])
        ax.scatter([best[0]], [best[1]], marker="*", s=240, c="gold", edgecolors="k", label="best", zorder=3)
    ax.set_xlabel("summed relative excess over the constraints (0 = all hold)")
    ax.set_ylabel(f"{spec.reduce} {spec.objective[2:]}")
    ax.set_title(f"tune '{spec.name}': {len(trials)} trials")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def write_tune_report(trials: Sequence[dict[str, Any]], spec: TuneSpec, out: Path, *, best_config: Path | None,
                      check: str | None) -> Path:
    """``out/tune_report.md``: the search, the trade-off plot, the best trials, and the check of best.yaml."""
    keys = [f"p.{k}" for k in spec.search]
    lines = [f"# Tuning '{spec.name}'", "",
             f"Scenarios {', '.join(spec.study.scenarios)}, seeds {', '.join(map(str, spec.study.seeds))}, "
             f"time scale {spec.study.time_scale:g}; {len(trials)} trials (Ray Tune, random search).", "",
             f"Objective: minimise the {spec.reduce} of `{spec.objective[2:]}` over every run.", ""]
    if spec.constraints:
        lines += ["Constraints, in every run of every scenario (a failed run breaks them all):", ""]
        lines += [f"- `{c.metric[2:]}` ≤ {c.max:g}" for c in spec.constraints]
        lines.append("")
    feasible = sum(1 for t in trials if _feasible(t))
    lines.append(f"**{feasible} of {len(trials)} trials met every constraint.**")
    lines.append("")
    if best_config is not None:
        lines += [f"Best configuration: `{best_config.name}` (load it with `--config {best_config}`).", ""]
    else:
        lines += ["No trial met every constraint: no configuration was written. Widen the search or the bounds.", ""]
    if check:
        lines += [f"Check of the written configuration, loaded back and run again: {check}", ""]
    if plot_tradeoff(trials, spec, out / "tune_tradeoff.png"):
        lines += ["![trade-off](tune_tradeoff.png)", "",
                  "*Each trial's objective against how far it broke the constraints.*", ""]
    worst = [f"worst.{c.metric}" for c in spec.constraints]
    head = ["#", *[k[2:] for k in keys], "feasible", spec.objective[2:], *[w[8:] + " (worst)" for w in worst]]
    lines += [f"## Best {min(SHOWN_TRIALS, len(trials))} trials", "", "| " + " | ".join(head) + " |",
              "|" + "---|" * len(head)]
    for i, t in enumerate(trials[:SHOWN_TRIALS]):
        cells = [str(i + 1), *[text(t.get(k)) for k in keys], "yes" if _feasible(t) else "no",
                 text(t.get("objective")), *[text(t.get(w)) for w in worst]]
        lines.append("| " + " | ".join(cells) + " |")
    failed_runs = [t for t in trials if t.get("run_error")]
    if failed_runs:
        lines += ["", "## Trials with a failed run (the first failure of each)", ""]
        lines += [f"- {' '.join(str(t['run_error']).split())[:300]}" for t in failed_runs]
    errors = [t for t in trials if t.get("error")]
    if errors:
        lines += ["", "## Trials that raised", ""]
        lines += [f"- {' '.join(str(t['error']).split())[:300]}" for t in errors]
    path = out / "tune_report.md"
    path.write_text("\n".join(lines) + "\n")
    return path
