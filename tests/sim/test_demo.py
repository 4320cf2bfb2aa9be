"""``lapwrench demo``: the report, its reproducibility, the video, and the inputs it refuses."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import NoReturn

import pytest

from lapwrench.config import Config
from lapwrench.sim import demo as demo_mod
from lapwrench.sim.results import ScenarioOptions
from lapwrench.sim.world import SimulationUnstableError

pytestmark = pytest.mark.slow  # full scenarios in the MuJoCo world


def _physics_metrics(path: Path) -> dict:
    data = json.loads(path.read_text())
    runs = data["scenarios"]["rcm-disturbance"]["runs"]
    wall_clock = ("real_time_factor", "loop_compute_p50_us", "loop_compute_p99_us", "loop_over_budget_cycles")
    return {k: {m: v for m, v in r.items() if m not in wall_clock} for k, r in runs.items()}


def test_demo_writes_a_report_and_a_seed_reproduces_its_metrics(tmp_path: Path) -> None:
    metrics = []
    for k in range(2):
        out = tmp_path / f"run{k}"
        plan = demo_mod.plan_demo(out, ["rcm-disturbance"], seed=3, time_scale=0.5, video=False)
        demo_mod.run_demo(plan, progress=False)
        for f in ("report.md", "metrics.json", "rcm_disturbance.png", "configs/rcm-disturbance.yaml"):
            assert (out / f).is_file(), f
        assert "Incision disturbance" in (out / "report.md").read_text()
        metrics.append(_physics_metrics(out / "metrics.json"))
    assert metrics[0] == metrics[1]


def test_demo_video_of_a_tracking_scenario(tmp_path: Path) -> None:
    plan = demo_mod.plan_demo(tmp_path, ["needle-search"], time_scale=0.2, video=True)
    plan = demo_mod.DemoPlan(**{**plan.__dict__, "printed_damping_check": False})
    demo_mod.run_demo(plan, progress=False)
    mp4 = tmp_path / "needle-search.mp4"
    assert mp4.is_file() and mp4.stat().st_size > 10_000
    import imageio.v3 as iio

    frames = iio.imread(mp4, index=None)
    assert frames.shape[1:] == (480, 640, 3)
    assert len(frames) == pytest.approx(26.0 * 0.2 * 25, abs=3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"scenarios": ["grip", "laparotomy"]}, "unknown scenario 'laparotomy'"),
        ({"scenarios": [""]}, r"unknown scenario '' \(an empty name\)"),
        ({"scenarios": ["grip,zoom"]}, r"unknown scenario 'grip,zoom'.*separated by spaces"),
        ({"config": "/nonexistent/c.yaml"}, "config file not found"),
        ({"time_scale": 3.0}, "time scale"),
        ({"detector": "/nonexistent/model.onnx"}, "detector must be.*not found"),
        ({"detector": "/tmp"}, "detector must be.*is not a file"),  # a folder: there, but no model
    ],
)
def test_bad_demo_inputs_fail_before_any_simulation(tmp_path: Path, kwargs: dict, match: str) -> None:
    with pytest.raises(demo_mod.DemoError, match=match):
        demo_mod.plan_demo(tmp_path / "out", **kwargs)
    assert not (tmp_path / "out" / "report.md").exists()


def test_the_printed_euler_step_with_the_printed_damping_is_refused_before_any_simulation(tmp_path: Path) -> None:
    cfg = tmp_path / "explicit.yaml"
    cfg.write_text("motion: {integrator: explicit}\n")
    with pytest.raises(demo_mod.DemoError, match=r"motion\.integrator: explicit.*viscous\.k_t.*semi_implicit"):
        demo_mod.plan_demo(tmp_path / "out", config=str(cfg))
    assert not (tmp_path / "out").exists()
    cfg.write_text("motion: {integrator: explicit}\nviscous: {k_t: 1.0, k_t_unguided: 1.0}\n")
    demo_mod.plan_demo(tmp_path / "out", config=str(cfg), scenarios=["grip"])  # within its bound: planned


def test_malformed_config_and_unwritable_folder(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("tracking: {epsilon1: 300}\n")
    with pytest.raises(demo_mod.DemoError, match="epsilon2"):
        demo_mod.plan_demo(tmp_path / "out", config=str(bad))
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(demo_mod.DemoError, match="not writable"):
        demo_mod.plan_demo(blocker / "sub")


def test_unstable_simulation_stops_without_a_valid_report(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def explode(cfg: Config, opts: ScenarioOptions) -> NoReturn:
        raise SimulationUnstableError(1.234, "shaft-incision contact force |F| (N)", "912.0")

    monkeypatch.setitem(demo_mod.SCENARIOS, "rcm-disturbance", explode)
    (tmp_path / "report.md").write_text("stale report from an earlier run")
    plan = demo_mod.plan_demo(tmp_path, ["rcm-disturbance"], video=False, workers=1)  # the patch is in-process
    with pytest.raises(demo_mod.DemoError, match=r"t = 1\.2340 s.*contact force"):
        demo_mod.run_demo(plan, progress=False)
    assert not (tmp_path / "report.md").exists()
    assert not (tmp_path / "metrics.json").exists()
    assert "contact force" in (tmp_path / "FAILED.txt").read_text()


def test_a_scenario_failing_in_a_worker_process_stops_the_demo(tmp_path: Path) -> None:
    """With workers, the scenarios run in spawned processes; a safety stop there still ends the demo
    with a message and FAILED.txt, no report (a 10 µm RCM bound: the incision shift trips it)."""
    plan = demo_mod.plan_demo(tmp_path, ["rcm-disturbance"], video=False, workers=2, time_scale=0.2)
    strict = plan.configs["rcm-disturbance"].replace(safety={"max_rcm_error": 1e-5})
    bad = dataclasses.replace(plan, configs={"rcm-disturbance": strict})
    with pytest.raises(demo_mod.DemoError, match=r"rcm-disturbance.*stopped"):
        demo_mod.run_demo(bad, progress=False)
    assert (tmp_path / "FAILED.txt").exists() and not (tmp_path / "report.md").exists()


def test_demo_refuses_a_control_rate_other_than_the_simulated_franka(tmp_path: Path) -> None:
    cfg = tmp_path / "rate.yaml"
    cfg.write_text("robot: {control_rate_hz: 500}\n")
    with pytest.raises(demo_mod.DemoError, match="control_rate_hz must be 1000"):
        demo_mod.plan_demo(tmp_path / "out", config=str(cfg))


def _group(pgid: int) -> list[int]:
    """The processes of process group ``pgid`` still running (zombies aside)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            found.append(int(stat.parent.name))
    return found


def _workers_started(pgid: int) -> bool:
    for pid in _group(pgid):
        try:
            if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                return True
        except OSError:
            continue
    return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_to_the_demo_writes_failed_txt_and_leaves_no_worker(tmp_path: Path, sig: signal.Signals) -> None:
    """SIGTERM or SIGHUP to the demo alone (its workers busy) ends it as Ctrl-C does: FAILED.txt in place
    of the previous report, one line, exit 128 + the signal, and its worker processes stopped."""
    (tmp_path / "report.md").write_text("an earlier report\n")
    env = {**os.environ, "MUJOCO_GL": "egl"}
    cmd = [sys.executable, "-m", "lapwrench.cli", "demo", "--out", str(tmp_path),
           "--scenarios", "grip", "rcm-disturbance",
           "--time-scale", "0.5", "--no-video", "--detector", "projected", "--workers", "2", "--quiet"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        while not _workers_started(proc.pid):
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.1)
        proc.send_signal(sig)
        _out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 128 + sig, err
    assert err.decode().strip() == f"lapwrench demo: stopped by {sig.name}; no report was written"
    assert (tmp_path / "FAILED.txt").read_text().startswith(f"stopped by {sig.name}")
    assert not (tmp_path / "report.md").exists()
    for _ in range(300):  # the workers end with the demo (the resource tracker too)
        if not _group(proc.pid):
            break
        time.sleep(0.1)
    assert _group(proc.pid) == []
