"""The plugin example (examples/cue-plugin): installed like a user would, it adds a sensor input and a
cue that a YAML file switches on, with no change to lapwrench (issue 13)."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import setuptools

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "cue-plugin"

# Run in a child process with the plugin on PYTHONPATH, so importlib.metadata sees its entry points.
RUN = """
import json, sys
import numpy as np
from lapwrench.config import load
from lapwrench.sim.loop import ClosedLoop, Trace
cfg = load(sys.argv[1])
loop = ClosedLoop(cfg, seed=0)
trace = Trace()
while loop.t < 3.5:
    loop.world.set_hand_wrench()
    loop.record(trace, loop.step(0.0))
print(json.dumps({
    "cues": [c.name for c in loop.controller.python_cues],
    "t": trace["t"].tolist(),
    "pressed": trace["cue:pedal_home.pressed"].tolist(),
    "angle_deg": trace["cue:pedal_home.angle_deg"].tolist(),
    "force_N": np.linalg.norm(trace["cue:pedal_home"][:, 3:], axis=1).tolist(),
}))
"""


def _builds_wheels_offline() -> bool:
    """Whether this interpreter builds a setuptools wheel without build isolation (no download):
    setuptools >= 70.1 has bdist_wheel itself, older ones need the wheel package."""
    major, minor = (int(x) for x in setuptools.__version__.split(".")[:2])
    return (major, minor) >= (70, 1) or importlib.util.find_spec("wheel") is not None


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The example installed with pip into a directory of its own (from a copy: the build leaves
    files beside the sources)."""
    root = tmp_path_factory.mktemp("plugin")
    src, target = root / "src", root / "site"
    shutil.copytree(EXAMPLE, src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    cmd = [sys.executable, "-m", "pip", "install", "--no-deps", "--target", str(target), str(src)]
    if _builds_wheels_offline():
        cmd[4:4] = ["--no-build-isolation", "--no-index"]  # nothing fetched at all
    env = {**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return target


def test_the_example_registers_one_cue_and_one_input(site: Path) -> None:
    entry_points = next(site.glob("*.dist-info")).joinpath("entry_points.txt").read_text()
    assert "[lapwrench.cues]\npedal_home = lapwrench_pedal_cue:PedalHomeCue" in entry_points
    assert "[lapwrench.inputs]\npedal = lapwrench_pedal_cue:PEDAL" in entry_points
    assert [p.name for p in site.glob("*.py")] == ["lapwrench_pedal_cue.py"]  # one file


def test_the_pedal_brings_the_view_home_only_while_pressed(site: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(site), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run([sys.executable, "-c", RUN, str(EXAMPLE / "pedal.yaml")], capture_output=True, text=True,
                          env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["cues"] == ["pedal_home"]
    t, pressed, angle, force = (out[k] for k in ("t", "pressed", "angle_deg", "force_N"))
    before = [i for i, x in enumerate(t) if x < 1.0]
    during = [i for i, x in enumerate(t) if 1.05 <= x < 3.0]
    # pedal up: no wrench, the view stays 10 deg from home
    assert not any(pressed[i] for i in before) and max(force[i] for i in before) == 0.0
    assert min(angle[i] for i in before) > 9.5
    # pedal down (the simulated schedule presses it at 1 s): the cue pulls and the view comes home
    assert all(pressed[i] for i in during) and force[during[0]] > 4.0
    assert angle[during[-1]] < 1.0
    # released at 3 s: the wrench is gone again
    assert all(force[i] == 0.0 for i, x in enumerate(t) if x >= 3.05)


def test_a_config_naming_the_cue_without_the_plugin_is_one_line_error() -> None:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    code = "from lapwrench.config import load\nimport sys\ntry:\n    load(sys.argv[1])\nexcept Exception as e:\n" \
           "    print(type(e).__name__, e)\n"
    proc = subprocess.run([sys.executable, "-c", code, str(EXAMPLE / "pedal.yaml")], capture_output=True, text=True,
                          env=env, timeout=120)
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ConfigError") and "pedal_home" in lines[0]


@pytest.mark.slow  # a dry run through the real-time process
def test_on_the_robot_path_the_pedal_driver_feeds_the_cue_through_the_real_time_process(
    site: Path, tmp_path: Path
) -> None:
    """`lapwrench run --dry-run`: the plugin's driver (InputSpec.open) runs in the parent, its value
    reaches the 1 kHz loop through a shared-memory slot, and the cue's wrench is in the run's log."""
    from lapwrench.hardware.log import read_log

    env = {**os.environ, "PYTHONPATH": str(site), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    log = tmp_path / "run.mcap"
    # the plugin's path is under test, not the machine's timing: a busy CI machine can miss 20 wall-clock
    # deadlines in a row (the deadline alarm, exit 1, has tests of its own), so that stop is off here
    cmd = [sys.executable, "-m", "lapwrench.cli", "run", "--dry-run", "--duration", "6", "--log", str(log),
           "--config", str(EXAMPLE / "pedal.yaml"), "--max-misses", "0", "--rt-priority", "0"]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]  # the summary names an alarm
    assert "example pedal" in proc.stderr  # the driver is named among the devices
    cycles = read_log(log)[0]
    force = [sum(x * x for x in c["wrenches"]["pedal_home"][3:]) ** 0.5 for c in cycles]
    assert max(force) > 1.0 and min(force) == 0.0  # pressed part of the time (2 s of every 4), released the rest
