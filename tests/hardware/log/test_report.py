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


def json_log(path: Path, cycles: list[bytes], events: tuple[bytes, ...] = (), stats: bytes | None = None) -> Path:
    """A log of JSON messages on the run log's topics (as the JSON-only logger, or another program,
    writes them), with the bytes given: ``json.loads`` takes NaN, Infinity and integers of any size."""
    from mcap.writer import Writer

    from lapwrench.hardware.log import CYCLE_TOPIC, EVENT_TOPIC, STATS_TOPIC

    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="test")
        for topic, payloads in ((CYCLE_TOPIC, cycles), (EVENT_TOPIC, events), (STATS_TOPIC, [stats] if stats else [])):
            channel = writer.register_channel(topic=topic, message_encoding="json", schema_id=0)
            for i, data in enumerate(payloads):
                writer.add_message(channel, log_time=i, publish_time=i, data=data)
        writer.finish()
    return path


def command(*argv: str) -> subprocess.CompletedProcess[str]:
    """``lapwrench`` in a subprocess (its stderr whole, Python's warnings included); 120 s at most."""
    script = "import sys; from lapwrench.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", script, *argv], capture_output=True, text=True, timeout=120)


def strict_json(path: Path) -> Any:
    """The JSON file at ``path``, refusing NaN and Infinity (which strict JSON readers refuse)."""

    def refuse(name: str) -> None:
        raise AssertionError(f"{path.name} holds {name}")

    return json.loads(path.read_text(), parse_constant=refuse)


def test_values_of_any_kind_or_size_give_a_quiet_report_in_strict_json(tmp_path: Path) -> None:
    """Values a damaged or foreign log may hold: a NaN or overflowing time, text where numbers belong, an
    integer beyond any float, 1e308 (1e3 x it overflows: matplotlib's "arange: cannot compute length"
    ended the report), NaN in the logger's stats and in events (written into summary.json and
    events.json as NaN, which is not JSON), a cycle without mode. The report is written, stderr stays
    empty (numpy's overflow and matplotlib's empty-legend warnings went there), the JSON is strict."""
    good = {"t": 0.0, "mode": "idle", "supervisor": "running", "alarm": False, "rcm_error": 1e-3, "q": [0.1] * 7}
    cycles = [
        b'{"t": NaN, "mode": "idle"}',
        b'{"t": "soon"}',
        b'{"t": 1e308}',
        json.dumps({**good, "t": 0.001, "rcm_error": 1e308, "q": "abc", "wrenches": [1, 2], "telemetry": [3],
                    "ft_force": {"x": 1}, "alarm": "yes", "compute_us": 1e308}).encode(),
        json.dumps({**good, "t": 0.002, "q": [1, "a", None], "wrenches": {"rcm": "abc"}, "telemetry": {"cue": [1]},
                    "mode": None, "supervisor": 5}).encode(),
        json.dumps({**good, "t": 0.003}).encode()[:-1] + b', "compute_us": 1' + b"0" * 400 + b"}",
        json.dumps({"t": 0.004}).encode(),
    ]
    events = (b'{"kind": "x", "time": NaN, "value": Infinity}', b'{"kind": "y", "time": 1e308}')
    path = json_log(tmp_path / "odd.mcap", cycles, events, stats=b'{"cycles": Infinity, "dropped": NaN}')
    proc = command("log-report", str(path), "--out", str(tmp_path / "report"))
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert "logger: None cycles written, None dropped" in proc.stdout
    summary = strict_json(tmp_path / "report" / "summary.json")
    assert summary["cycles"] == 4 and summary["duration_s"] == pytest.approx(0.003)  # the cycles with a time
    assert summary["rcm_error_max_mm"] is None  # 1e308 m in mm overflows: no value rather than Infinity
    assert summary["log_stats"] == {"cycles": None, "dropped": None}
    assert strict_json(tmp_path / "report" / "events.json")[0] == {"kind": "x", "time": None, "value": None}


def test_a_cycle_with_thousands_of_joints_is_reported_with_the_first_few(tmp_path: Path) -> None:
    """A joint vector of 5000 values (a damaged record) asked matplotlib for 5000 panels: log-report
    ran for hours. Now at most MAX_PANELS joints are drawn, and summary.json says what was left out."""
    q = [0.1] * 5000
    fields = {"q": q, "q_cmd": q, "mode": "idle", "supervisor": "running", "alarm": False}
    cycles = [json.dumps({"t": 0.001 * k, **fields}).encode() for k in range(3)]
    proc = command("log-report", str(json_log(tmp_path / "long.mcap", cycles)), "--out", str(tmp_path / "report"))
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    from lapwrench.hardware.log.report import MAX_PANELS

    left = strict_json(tmp_path / "report" / "summary.json")["left_out_of_plots"]
    assert left == [f"joints beyond the first {MAX_PANELS} (of 5000)"]


def test_a_folder_name_that_is_not_utf8_is_printed_escaped(
    long_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path
) -> None:
    """With stdout strict UTF-8 (a UTF-8 locale other than C.UTF-8), printing the written files ended
    log-report with a UnicodeEncodeError traceback after the report was written."""
    import os

    out = tmp_path / os.fsdecode(b"plots-\xff")
    script = "import sys; from lapwrench.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.run([sys.executable, "-c", script, "log-report", str(long_log[0]), "--out", str(out)],
                          capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONIOENCODING": "utf-8:strict"})
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert f"{tmp_path}/plots-\\xff/summary.json" in proc.stdout.splitlines()
    assert (out / "summary.json").is_file()


def test_a_report_into_a_used_folder_leaves_nothing_of_the_earlier_one(
    long_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The report of a log with telemetry, then of one without, in the same folder: the first one's
    cue_telemetry.png stayed beside the second report. A report cut short (here: a plot that cannot be
    written) left the earlier summary.json beside its new plots, as if complete."""
    with_telemetry = tmp_path / "cue.mcap"
    with RunLogger(with_telemetry, {"robot": "test"}, telemetry={"zoom": ("spread",)}) as log:
        for k in range(50):
            log.cycle(record(k, telemetry={"zoom": (0.1 * k,)}))
    out = tmp_path / "report"
    assert report(with_telemetry, out, capsys)[0] == 0 and (out / "cue_telemetry.png").exists()
    code, printed, _ = report(long_log[0], out, capsys)
    assert code == 0 and "cue_telemetry.png" not in printed
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["summary.json", "events.json", "rcm_error.png", "wrenches.png", "mode.png", "joint_commands.png"])
    (out / "joint_commands.png").unlink()
    (out / "joint_commands.png").mkdir()  # the next report stops there
    code, _, err = report(with_telemetry, out, capsys)
    assert code == 2 and "cannot report" in err
    assert not (out / "summary.json").exists() and not (out / "cue_telemetry.png").exists()
