"""lapwrench.study.runner on real Ray: a small study on local Ray with 2 CPUs (rows, resume, a failure
kept as a row), and a two-node cluster started with ``ray start`` on this machine."""

from __future__ import annotations

import math
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
import yaml

from lapwrench.study.runner import ClusterError, check_reachable, run_study, start_ray
from lapwrench.study.spec import StudyError, from_dict
from lapwrench.study.table import ResultTable

pytestmark = pytest.mark.slow

# grip at time scale 0.05: a 0.5° view change, three short runs per job (a few seconds each).
# safety.max_residual_force = 0.01 N trips the supervisor at once: that job fails, as a row.
STUDY = {
    "name": "small",
    "scenarios": ["grip"],
    "seeds": 2,
    "time_scale": 0.05,
    "detector": "projected",
    "grid": {"safety.max_residual_force": [20.0, 0.01]},
    "sample": {"world.surgeon_force": {"uniform": [0.9, 1.1]}},
}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_unreachable_cluster_is_a_clear_error() -> None:
    with pytest.raises(ClusterError, match=r"cannot reach the Ray cluster at 127\.0\.0\.1:1"):
        check_reachable("127.0.0.1:1")
    for bad in ("nonsense", "host:", ":80", "host:99999"):
        with pytest.raises(ClusterError, match="not HOST:PORT"):
            check_reachable(bad)


def _ray_cli() -> str:
    ray = shutil.which("ray", path=str(Path(sys.executable).parent))
    assert ray, "the ray command comes with the study extra"
    return ray


def _start_node(args: list[str], temp: Path, log: str) -> subprocess.Popen:
    # with the test's RAY_AUTH_* (see below); no drain on SIGTERM (Ray 2.60 waits up to 30 s for the node to
    # drain, here for a GCS that the same SIGTERM to the process group has already stopped)
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "RAY_GRACEFUL_SHUTDOWN_DRAIN_TIMEOUT_S": "0"}
    with open(temp / log, "wb") as err:  # a file, not a pipe nobody reads
        return subprocess.Popen([_ray_cli(), "start", "--block", "--num-cpus=1", "--node-ip-address=127.0.0.1",
                                 "--disable-usage-stats", *args], stdout=subprocess.DEVNULL, stderr=err,
                                env=env, start_new_session=True, cwd=temp)


def _wait_for_head(address: str, head: subprocess.Popen, timeout_s: float = 90.0) -> None:
    """Until the head's GCS port accepts connections (a second node can join from then on)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            check_reachable(address, timeout_s=1.0)
            return
        except ClusterError:
            assert head.poll() is None, f"ray start --head ended with code {head.returncode}"
            assert time.monotonic() < deadline, f"the Ray head did not come up at {address}"
            time.sleep(0.2)


def _wait_for_nodes(address: str, n: int, timeout_s: float = 90.0) -> None:
    """Until ``n`` nodes are alive: one driver process that joins the cluster once and asks it again and again."""
    code = ("import ray, sys, time\n"
            "ray.init(address=sys.argv[1], logging_level='ERROR')\n"
            "alive = lambda: sum(1 for x in ray.nodes() if x['Alive'])\n"
            "end = time.monotonic() + float(sys.argv[3])\n"
            "while alive() < int(sys.argv[2]) and time.monotonic() < end:\n"
            "    time.sleep(0.2)\n"
            "print(alive())")
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        left = max(1.0, deadline - time.monotonic())
        out = subprocess.run([sys.executable, "-c", code, address, str(n), str(left)], capture_output=True, text=True,
                             timeout=left + 60)
        if out.stdout.strip().isdigit() and int(out.stdout.strip()) >= n:
            return
        time.sleep(1.0)
    raise AssertionError(f"{n} Ray nodes did not come up at {address}")


def _stop(procs: list[subprocess.Popen]) -> None:
    """SIGTERM to every node at once, then wait for each (SIGKILL after 30 s)."""
    running = [p for p in procs if p.poll() is None]
    for proc in running:
        os.killpg(proc.pid, signal.SIGTERM)
    for proc in running:
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def test_two_node_cluster_through_address(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``ray start --head`` plus a second node on other ports: the study runs through ``lapwrench sweep
    --address`` and its rows come from both nodes. Every process of the cluster, and this driver, share one auth token
    (Ray 2.60 turns token authentication on by itself when ~/.ray/auth_token exists)."""
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    monkeypatch.setenv("RAY_AUTH_TOKEN", secrets.token_hex(32))
    port = _free_port()
    address = f"127.0.0.1:{port}"
    head = _start_node(["--head", f"--port={port}", "--include-dashboard=false"], tmp_path, "head.log")
    nodes = [head]
    try:
        _wait_for_head(address, head)
        nodes.append(_start_node([f"--address={address}"], tmp_path, "node.log"))
        _wait_for_nodes(address, 2)
        # The driver is `lapwrench sweep --address` in a process of its own: Ray keeps the auth token of
        # the first ray.init of a process, and this test process may have run Ray before.
        study = tmp_path / "study.yaml"
        study.write_text(yaml.safe_dump({**STUDY, "seeds": 4, "grid": {}}))
        out = tmp_path / "out"
        proc = subprocess.run([sys.executable, "-m", "lapwrench.cli", "sweep", str(study), "--out", str(out),
                               "--address", address, "--quiet"], capture_output=True, text=True, timeout=600,
                              env={**os.environ, "MUJOCO_GL": "egl"})
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert "ran 4 jobs (0 failed)" in proc.stdout and "on 2 node(s)" in proc.stdout, proc.stdout
        rows = pd.read_parquet(out / "runs.parquet")
        assert rows.run_id.nunique() == 4 and (rows.status == "ok").all()
        assert rows.node.nunique() == 2, rows.node.value_counts()
    finally:
        _stop(nodes)


@pytest.fixture(scope="module")
def local_ray() -> Iterator[None]:
    """One embedded Ray with 2 CPUs, started as ``lapwrench sweep`` starts it, for this module's studies:
    run_study uses a Ray this process runs already and leaves it running."""
    import ray

    start_ray(None, 2)
    yield
    ray.shutdown()


def test_small_study_rows_resume_and_failures(tmp_path: Path, local_ray: None) -> None:
    import ray

    spec = from_dict(STUDY)
    outcome, _ = run_study(spec, tmp_path, progress=False)
    assert ray.is_initialized()  # the caller's Ray is left running
    rows = pd.read_parquet(tmp_path / "runs.parquet")
    assert outcome.ran == 4 and outcome.skipped == 0 and outcome.failed == 2
    ok = rows[rows.status == "ok"]
    failed = rows[rows.status == "failed"]
    assert len(ok) == 2 * 3  # two good jobs, three grip levels each
    assert sorted(ok.label.unique()) == ["high", "low", "medium"]
    assert len(failed) == 2 and failed.label.isna().all()
    assert failed.error.str.contains("safety supervisor stopped").all()
    assert (failed["p.safety.max_residual_force"] == 0.01).all()
    assert failed.config.str.contains("max_residual_force: 0.01").all()  # kept with its configuration
    assert ok["m.rcm_error_max_mm"].notna().all()
    assert rows.run_id.nunique() == 4 and rows.node.nunique() == 1

    again, _ = run_study(spec, tmp_path, progress=False)
    assert again.ran == 0 and again.skipped == 4
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "runs.parquet"), rows)

    retried, _ = run_study(spec, tmp_path, progress=False, retry_failed=True)
    assert retried.ran == 2 and retried.skipped == 2 and retried.failed == 2
    assert len(pd.read_parquet(tmp_path / "runs.parquet")) == len(rows)


def test_a_running_ray_refuses_address_and_workers_and_a_bad_save_interval(tmp_path: Path, local_ray: None) -> None:
    spec = from_dict(STUDY)
    for kwargs in ({"workers": 2}, {"address": "auto"}):
        with pytest.raises(ValueError, match="Ray already runs in this process"):
            run_study(spec, tmp_path, progress=False, **kwargs)
    for bad in (0.0, -1.0, math.nan, math.inf, True):
        with pytest.raises(ValueError, match="save_every_s must be a finite number > 0"):
            run_study(spec, tmp_path, progress=False, save_every_s=bad)
    assert not (tmp_path / "runs.parquet").exists()  # refused before anything ran


def test_a_table_of_another_study_is_refused_before_ray_starts(tmp_path: Path) -> None:
    """Rows of two studies would mix in the report: the folder is refused, nothing is run or rewritten."""
    import sys as system

    table = ResultTable(tmp_path)
    table.add([{"run_id": "0" * 16, "study": "other", "scenario": "grip", "status": "ok"}])
    table.save()
    before = (tmp_path / "runs.parquet").read_bytes()
    ray_before = "ray" in system.modules and system.modules["ray"].is_initialized()
    with pytest.raises(StudyError, match="holds rows of study 'other', not 'small'"):
        run_study(from_dict(STUDY), tmp_path, progress=False)
    assert (tmp_path / "runs.parquet").read_bytes() == before
    assert ("ray" in system.modules and system.modules["ray"].is_initialized()) == ray_before


def _session(sid: int) -> list[str]:
    """The command lines of the processes of session ``sid`` (ps)."""
    ps = subprocess.run(["ps", "-o", "args=", "--sid", str(sid)], capture_output=True, text=True)
    return [line for line in ps.stdout.splitlines() if line.strip()]


def test_ctrl_c_while_ray_starts_leaves_no_ray_process_behind(tmp_path: Path) -> None:
    """Ctrl-C once Ray's dashboard agent runs, in the middle of ray.init: the agent and the runtime-env
    agent outlived the sweep (their raylet gone), until killed by hand. The signal now waits for the
    start to finish, then Ray is shut down whole: no process of the sweep's session is left."""
    study = tmp_path / "study.yaml"
    study.write_text(yaml.safe_dump({**STUDY, "grid": {}}))
    proc = subprocess.Popen([sys.executable, "-m", "lapwrench.cli", "sweep", str(study), "--out", str(tmp_path / "out"),
                             "--workers", "1", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "MUJOCO_GL": "egl"}, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # a terminal's job
    deadline = time.monotonic() + 240
    while proc.poll() is None and time.monotonic() < deadline and not any(
            "DashboardAgent" in line or "dashboard/agent.py" in line for line in _session(proc.pid)):
        time.sleep(0.02)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 130 and err.startswith("lapwrench sweep: interrupted; "), err
    deadline = time.monotonic() + 60  # Ray's own shutdown: its processes end within seconds
    while _session(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.5)
    left = _session(proc.pid)
    for pid in subprocess.run(["ps", "-o", "pid=", "--sid", str(proc.pid)], capture_output=True,
                              text=True).stdout.split():
        os.kill(int(pid), signal.SIGKILL)  # this test's own processes, were any left
    assert left == []


def test_auto_is_checked_at_the_address_it_stands_for(monkeypatch: pytest.MonkeyPatch) -> None:
    """--address auto connects to RAY_ADDRESS or to the cluster `ray start` wrote down last (a file `ray stop`
    leaves behind): a cluster gone since made Ray retry for minutes, unchecked. Now refused at once."""
    port = _free_port()  # nothing listens there
    monkeypatch.setenv("RAY_ADDRESS", f"127.0.0.1:{port}")
    with pytest.raises(ClusterError, match=rf"cannot reach the Ray cluster at auto \(127\.0\.0\.1:{port}\)"):
        check_reachable("auto")


def test_a_host_name_too_long_for_dns_is_a_clear_error() -> None:
    """A label over 63 characters: the IDNA codec's UnicodeError went through as a traceback."""
    with pytest.raises(ClusterError, match="not a valid host name"):
        check_reachable("h" * 300 + ":6379")
