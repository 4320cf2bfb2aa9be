"""``python -m lapwrench`` is the ``lapwrench`` command: the same entry point, exit codes and messages."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def run(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "lapwrench", *argv], capture_output=True, text=True, timeout=300,
                          check=False, env={**os.environ, "MUJOCO_GL": "egl"})


def test_python_m_lapwrench_lists_the_commands() -> None:
    proc = run("--help")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("usage: lapwrench ") and "log-report" in proc.stdout and "sweep" in proc.stdout


def test_python_m_lapwrench_refuses_a_bad_argument_as_the_command_does() -> None:
    proc = run("virtual", "--duration", "nan")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.splitlines()[-1] == (
        "lapwrench virtual: error: argument --duration: must be a number from 0.1 to 600, got 'nan'")


def test_python_m_lapwrench_runs_a_command(tmp_path: Path) -> None:
    proc = run("virtual", "--duration", "0.2", "--quiet", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "virtual_metrics.json").is_file()
