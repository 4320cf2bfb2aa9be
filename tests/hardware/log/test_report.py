"""``lapwrench log-report``: one line and exit 2 for unreadable files, truncated and foreign logs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from hardware.log.support import record, report

from lapwrench.hardware.log import (
    LogFileError,
    RunLogger,
    load_log,
)


def test_files_that_cannot_be_read_give_one_line_and_exit_2(
    long_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    full, _ = long_log
    data = full.read_bytes()
    files = {
        "header.mcap": data[:20],  # inside the header record: no cycle at all
        "magic.mcap": data[:5],
        "garbage.mcap": b"not a log\n" * 100,
        "empty.mcap": b"",
        "damaged.mcap": data[: len(data) // 3] + bytes(64) + data[len(data) // 3 + 64 :],  # complete, corrupt
    }
    for name, content in files.items():
        (tmp_path / name).write_bytes(content)
    (tmp_path / "folder.mcap").mkdir()
    cases = {
        "header.mcap": "truncated MCAP file (20 bytes, no summary/footer) with no complete /lapwrench/cycle message",
        "magic.mcap": "truncated MCAP file (5 bytes, cut inside the magic)",
        "garbage.mcap": "not an MCAP file",
        "empty.mcap": "empty file (0 bytes), not an MCAP log",
        "damaged.mcap": "corrupt MCAP file",
        "folder.mcap": "is a directory, not a log file",
        "none.mcap": "no such log file",
    }
    for name, words in cases.items():
        path = tmp_path / name
        code, out, err = report(path, tmp_path / "report", capsys)
        assert code == 2 and not out, (name, out)
        assert err.startswith(f"lapwrench log-report: {path}: {words}") and len(err.strip().splitlines()) == 1, err
        if name == "header.mcap":  # readable as far as it goes: nothing
            assert load_log(path, allow_truncated=True).cycles == []
        else:
            with pytest.raises(LogFileError):
                load_log(path, allow_truncated=True)
    assert not (tmp_path / "report").exists()


def test_the_command_line_reports_a_truncated_log_and_refuses_a_foreign_one(
    long_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path
) -> None:
    full, _ = long_log
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    foreign = tmp_path / "foreign.mcap"
    foreign.write_text("not a log\n")
    script = "import sys; from lapwrench.cli import main; sys.exit(main(sys.argv[1:]))"
    for path, code, words in ((cut, 0, "is truncated (no summary/footer); read "), (foreign, 2, "not an MCAP file")):
        proc = subprocess.run(
            [sys.executable, "-c", script, "log-report", str(path), "--out", str(tmp_path / "report")],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert proc.returncode == code and words in proc.stderr, proc.stderr
        assert "Traceback" not in proc.stdout + proc.stderr and len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("out", ["", "a-file"])
def test_a_bad_out_folder_is_refused_before_the_log_is_read(out: str, tmp_path: Path) -> None:
    """``--out ''`` used to write the plots into the current folder, and a file as ``--out`` was found only
    after the whole log had been read."""
    (tmp_path / "a-file").write_text("x")
    script = "import sys; from lapwrench.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.run(
        [sys.executable, "-c", script, "log-report", str(tmp_path / "missing.mcap"), "--out", out],
        capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 2 and "argument --out" in proc.stderr and "missing.mcap" not in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]


def test_the_report_plots_the_cues_telemetry_and_lists_its_fields(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "run.mcap"
    with RunLogger(path, {"robot": "test"}, telemetry={"keep_out": ("distance", "barrier")}) as log:
        for k in range(200):
            log.cycle(record(k, telemetry={"keep_out": (0.01 * k, max(0.0, 50.0 - k))}))
    code, out, _ = report(path, tmp_path / "report", capsys)
    assert code == 0 and str(tmp_path / "report" / "cue_telemetry.png") in out.splitlines()
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    assert summary["telemetry"] == {"keep_out": ["distance", "barrier"]}


def test_a_log_without_telemetry_has_no_telemetry_plot(
    long_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = report(long_log[0], tmp_path / "report", capsys)
    assert code == 0 and "cue_telemetry.png" not in out
    assert json.loads((tmp_path / "report" / "summary.json").read_text())["telemetry"] == {}
