"""``lapwrench sweep`` and ``lapwrench tune`` as a user runs them: bad arguments and files end with one line
and exit code 2 before Ray starts; a sweep killed halfway keeps its finished rows and resumes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

import pandas as pd
import pytest
import yaml

from lapwrench.cli import main
from lapwrench.study.execute import job_rows
from lapwrench.study.spec import expand, load_study
from lapwrench.study.table import ResultTable


def _write(path: Path, data: object) -> Path:
    path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return path


STUDY = {"name": "cli", "scenarios": ["grip"], "seeds": 1, "time_scale": 0.05, "detector": "projected"}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["sweep", "/no/such/study.yaml"], "study file not found"),
        (["sweep", "{dir}"], "is a directory"),
        (["sweep", "{bad}"], "'scenarios' holds 'nope'"),
        (["sweep", "{good}", "--address", "127.0.0.1:1"], "cannot reach the Ray cluster"),
        (["sweep", "{good}", "--address", "x:1", "--workers", "2"], "--workers sizes the embedded Ray"),
        (["sweep", "{good}", "--address", "no-port"], "not HOST:PORT"),
        (["sweep", "{good}", "--out", "{file}"], "--out"),
        (["sweep", "{good}", "--save-every", "0"], "--save-every"),
        (["sweep", "{good}", "--save-every", "-1"], "--save-every"),
        (["sweep", "{good}", "--save-every", "nan"], "--save-every"),
        (["sweep", "{good}", "--save-every", "inf"], "--save-every"),
        (["sweep", "{good}", "--save-every", "soon"], "--save-every"),
        (["sweep", "{normal}"], "give it a min inside the key's range"),
        (["tune", "{normal_tune}"], "give it a min inside the key's range"),
        (["sweep", "{garbage}"], "cannot load as an ONNX model"),
        (["sweep", "{escape}"], "plain folder name"),
        (["sweep", "{good}", "--out", "{other_study}"], "holds the results of study 'another'"),
        (["tune", "{good}"], "'search' must map parameter keys"),
        (["tune", "/no/such/tune.yaml"], "tuning file not found"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str],
                                          message: str) -> None:
    paths = {
        "dir": str(tmp_path),
        "bad": str(_write(tmp_path / "bad.yaml", {**STUDY, "scenarios": ["nope"]})),
        "good": str(_write(tmp_path / "good.yaml", STUDY)),
        "file": str(_write(tmp_path / "afile", "x")),
        "normal": str(_write(tmp_path / "normal.yaml", {**STUDY, "sample": {"rcm.Kp": {"normal": [300, 1000]}}})),
        "normal_tune": str(_write(tmp_path / "normal_tune.yaml", {
            **STUDY, "search": {"rcm.Kp": {"normal": [300, 1000]}}, "objective": {"metric": "completion_time_s"}})),
        "garbage": str(_write(tmp_path / "garbage.yaml", {**STUDY, "detector": str(tmp_path / "garbage.onnx")})),
        "escape": str(_write(tmp_path / "escape.yaml", {**STUDY, "name": "../../etc/x"})),
        "other_study": str(tmp_path / "other"),
    }
    (tmp_path / "garbage.onnx").write_bytes(bytes(range(256)) * 12)
    (tmp_path / "other").mkdir()
    _write(tmp_path / "other" / "study.yaml", {**STUDY, "name": "another"})
    argv = [a.format(**paths) for a in argv]
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own refusals (a --out that is a file)
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert message in err, err
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if "error" in line or line.startswith("lapwrench")]
    assert len(errors) == 1, err  # one line (argparse puts its usage lines before its own)


def test_sweep_help_names_the_save_interval_and_its_default(capsys: pytest.CaptureFixture[str]) -> None:
    from lapwrench.study.runner import SAVE_EVERY_S

    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--save-every SECONDS" in help_text and f"(default {SAVE_EVERY_S:g})" in help_text


@pytest.mark.slow
def test_sweep_killed_halfway_keeps_rows_and_resumes(tmp_path: Path) -> None:
    """SIGTERM in the middle: exit 143 (128 + 15, as every command), a readable table with the finished jobs;
    the same command again runs only the rest and writes the report."""
    # one worker and two jobs in this order: grip (three short runs) and rcm-disturbance (two runs of 6 s
    # simulated, several seconds). The table is saved as soon as a job finishes (--save-every 0.1), so it
    # appears after grip, while rcm-disturbance runs: the kill lands halfway, not during Ray's shutdown
    rows_per_job = {"grip": 3, "rcm-disturbance": 2}
    study = _write(tmp_path / "study.yaml", {**STUDY, "scenarios": list(rows_per_job)})
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "lapwrench.cli", "sweep", str(study), "--out", str(out), "--workers", "1", "--quiet",
           "--save-every", "0.1"]
    env = {**os.environ, "MUJOCO_GL": "egl"}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    table = out / "runs.parquet"
    deadline = time.monotonic() + 240
    while not table.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
    assert table.exists(), proc.communicate()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "lapwrench sweep: stopped by SIGTERM; the finished runs are saved in" in err and "Traceback" not in err
    first = pd.read_parquet(table)
    done = first.run_id.nunique()
    assert done == 1
    assert len(first) == rows_per_job[first.scenario.iloc[0]]  # the whole job
    assert not (out / "runs.parquet.tmp").exists()

    again = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert again.returncode == 0, again.stderr
    assert "ran 1 jobs (0 failed) and skipped 1" in again.stdout
    rows = pd.read_parquet(table)
    assert rows.run_id.nunique() == 2 and len(rows) == sum(rows_per_job.values())
    cells = [c for c in first.columns if first[c].notna().any()]  # an all-missing column may change its dtype
    pd.testing.assert_frame_equal(rows.iloc[: len(first)][cells].reset_index(drop=True), first[cells])  # kept as is
    assert (out / "report.md").exists() and (out / "study.yaml").exists()


@pytest.mark.slow
def test_tiny_tuning_run_writes_a_preset_that_loads_and_passes(tmp_path: Path) -> None:
    tune_file = _write(tmp_path / "tune.yaml", {
        **STUDY, "name": "tiny-tune", "trials": 2,
        "search": {"viscous.k_t": {"uniform": [120.0, 180.0]}},
        "objective": {"metric": "duration_s"},
        "constraints": [{"metric": "rcm_error_max_mm", "max": 5.0}, {"metric": "trocar_force_max_N", "max": 10.0}],
    })
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "lapwrench.cli", "tune", str(tune_file), "--out", str(out),
                           "--workers", "2", "--quiet"], capture_output=True, text=True, timeout=900,
                          env={**os.environ, "MUJOCO_GL": "egl"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    # --quiet: our three lines only (Ray Tune's new output printed its tables even at verbose 0)
    assert [line.split(":")[0] for line in proc.stdout.splitlines()] == ["lapwrench tune", "best", "report"]
    assert "2 of 2 trials met every constraint" in proc.stdout
    assert "check passed" in proc.stdout
    from lapwrench import config as config_mod

    best = config_mod.load(out / "best.yaml")
    trials = pd.read_parquet(out / "trials.parquet")
    assert len(trials) == 2
    assert best.viscous.k_t == pytest.approx(float(trials.iloc[0]["p.viscous.k_t"]))
    assert 120.0 <= best.viscous.k_t <= 180.0
    report = (out / "tune_report.md").read_text()
    assert "2 of 2 trials met every constraint" in report and (out / "tune_tradeoff.png").exists()


@pytest.mark.slow
def test_tune_interrupted_exits_130_and_writes_no_result(tmp_path: Path) -> None:
    """Ctrl-C to the whole process group (as a terminal sends it) while trials run: exit 130, one line saying
    so, and no best.yaml, trials table or report presented as the search's result."""
    tune_file = _write(tmp_path / "tune.yaml", {
        **STUDY, "name": "ctrl-c", "trials": 8, "search": {"rcm.Kp": {"uniform": [300.0, 3000.0]}},
        "objective": {"metric": "completion_time_s"}})
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "lapwrench.cli", "tune", str(tune_file), "--out", str(out),
                             "--workers", "2", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "MUJOCO_GL": "egl"}, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # a terminal's job
    trials_dir = out / "ray_tune" / "ctrl-c"
    deadline = time.monotonic() + 240  # interrupt once Tune has started its trials
    while proc.poll() is None and time.monotonic() < deadline and not any(trials_dir.glob("*/params.json")):
        time.sleep(0.2)
    assert proc.poll() is None, proc.communicate()
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 130, err[-2000:]
    assert "lapwrench tune: interrupted" in err and "Traceback" not in err
    assert not (out / "best.yaml").exists() and not (out / "trials.parquet").exists()
    assert not (out / "tune_report.md").exists()


@pytest.fixture
def kept_signals() -> Iterator[None]:
    """The stop signals' handlers as they were, after the test (lapwrench.cli's main puts them back too)."""
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    yield
    for sig, handler in handlers.items():
        signal.signal(sig, handler)


def _interrupt(*_: object, **__: object) -> NoReturn:
    raise KeyboardInterrupt


def test_an_interrupt_before_any_run_finished_says_nothing_was_saved(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, kept_signals: None
) -> None:
    """Ctrl-C while Ray started said "finished runs are saved in ." without --out (the folder is
    reports/sweeps/<name>), and said so when no run had finished and nothing was saved anywhere."""
    import lapwrench.study.runner

    study = _write(tmp_path / "study.yaml", STUDY)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(lapwrench.study.runner, "run_study", _interrupt)
    assert main(["sweep", str(study), "--quiet"]) == 130
    assert capsys.readouterr().err == "lapwrench sweep: interrupted; no run had finished, nothing was saved\n"

    def one_run_then_interrupt(spec: Any, out: Path, **_: object) -> NoReturn:
        table = ResultTable(out)
        table.add(job_rows(expand(spec)[0], spec.name, None, "RuntimeError: stopped", 1.0))
        table.save()
        raise KeyboardInterrupt

    monkeypatch.setattr(lapwrench.study.runner, "run_study", one_run_then_interrupt)
    assert main(["sweep", str(study), "--quiet"]) == 130
    saved = Path("reports") / "sweeps" / STUDY["name"] / "runs.parquet"
    assert capsys.readouterr().err == (f"lapwrench sweep: interrupted; the finished runs are saved in {saved}; run the "
                                       "same command again to resume\n")
    assert len(pd.read_parquet(saved)) == 1


def test_rows_of_runs_an_edited_study_no_longer_has_are_kept_marked_and_left_out_of_the_report(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], kept_signals: None
) -> None:
    """The study's grid was edited between two sweeps into one folder: the rows of the old grid's runs used to
    stay in the table and in the report, mixed with the new grid's. Now they are kept (in_study false) and
    left out of the report, and the sweep says so; undoing the edit brings them back without a run."""
    out = tmp_path / "out"
    old = _write(tmp_path / "old.yaml", {**STUDY, "grid": {"viscous.k_t": [120.0, 150.0]}})
    new = _write(tmp_path / "new.yaml", {**STUDY, "grid": {"viscous.k_t": [150.0, 180.0]}})
    out.mkdir()
    table = ResultTable(out)
    for study in (old, new):  # every job of both grids already in the table: no Ray
        table.add([r for job in expand(load_study(study)) for r in job_rows(job, "cli", None, "RuntimeError: x", 1.0)
                   if r["run_id"] not in table.done])
    table.save()
    assert main(["sweep", str(new), "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert ("lapwrench sweep: 1 rows of runs this study no longer has (its grid, seeds or scenarios changed) are kept "
            "in the table with in_study = false and left out of this report.") in printed
    rows = pd.read_parquet(out / "runs.parquet")
    assert len(rows) == 3 and rows.groupby("in_study")["p.viscous.k_t"].apply(sorted).to_dict() == {
        False: [120.0], True: [150.0, 180.0]}
    report = (out / "report.md").read_text()
    assert "**Jobs:** 2 " in report and "in_study = false" in report
    assert main(["sweep", str(old), "--out", str(out), "--quiet"]) == 0  # the edit undone: nothing runs
    assert "ran 0 jobs (0 failed) and skipped 2" in capsys.readouterr().out
    rows = pd.read_parquet(out / "runs.parquet")
    assert sorted(rows[rows.in_study]["p.viscous.k_t"]) == [120.0, 150.0] and len(rows) == 3


@pytest.mark.parametrize("command", ["sweep", "tune"])
def test_more_workers_than_this_machine_has_cpus_is_refused_before_ray_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    """``--workers 256`` on two cores started 256 simulations at once, each with its memory, taking turns."""
    from lapwrench.study.runner import available_cpus

    data = STUDY if command == "sweep" else {**STUDY, "search": {"viscous.k_t": {"uniform": [120.0, 180.0]}},
                                             "objective": {"metric": "duration_s"}}
    study = _write(tmp_path / "study.yaml", data)
    cpus = available_cpus()
    assert main([command, str(study), "--out", str(tmp_path / "out"), "--workers", str(cpus + 1), "--quiet"]) == 2
    assert capsys.readouterr().err == (
        f"lapwrench {command}: --workers {cpus + 1}: this process may use {cpus} CPUs; more workers would only take "
        "turns on them, each holding a simulation in memory (--address runs on a cluster)\n")


@pytest.mark.parametrize("command", ["sweep", "tune"])
def test_a_pipe_in_the_results_folder_is_refused_before_ray_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    """A FIFO named runs.parquet (or trials.parquet, report.md...) in --out: the table's read, or a write,
    waited for another program forever (the sweep hung until killed)."""
    data = STUDY if command == "sweep" else {**STUDY, "search": {"viscous.k_t": {"uniform": [120.0, 180.0]}},
                                             "objective": {"metric": "duration_s"}}
    study = _write(tmp_path / "study.yaml", data)
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / ("runs.parquet" if command == "sweep" else "trials.parquet"))
    assert main([command, str(study), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"lapwrench {command}: --out {out} holds ") and "a pipe, socket or device" in err, err


def test_a_report_that_cannot_be_written_is_one_line_and_keeps_the_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], kept_signals: None
) -> None:
    """Every job already in the table (no Ray), but report.md is a folder: the IsADirectoryError of the
    report's writing ended the sweep with a traceback."""
    study = _write(tmp_path / "study.yaml", STUDY)
    out = tmp_path / "out"
    out.mkdir()
    table = ResultTable(out)
    table.add([r for job in expand(load_study(study)) for r in job_rows(job, "cli", None, "RuntimeError: x", 1.0)])
    table.save()
    (out / "report.md").mkdir()
    assert main(["sweep", str(study), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"lapwrench sweep: the runs are saved in {out / 'runs.parquet'}, but the report cannot be "
                          "written: Is a directory") and len(err.splitlines()) == 1, err


def test_tune_results_or_a_check_cut_short_are_said_as_such(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, kept_signals: None
) -> None:
    """After the search: Ctrl-C during the check of best.yaml was reported as "interrupted" only (best.yaml
    left unchecked, unsaid), and a report that cannot be written ended tune with a traceback."""
    import lapwrench.study.tune
    from lapwrench import config as config_mod

    tune_file = _write(tmp_path / "tune.yaml", {**STUDY, "search": {"viscous.k_t": {"uniform": [120.0, 180.0]}},
                                                "objective": {"metric": "completion_time_s"}})
    out = tmp_path / "out"
    best = out / "best.yaml"
    trial = {"p.viscous.k_t": 150.0, "score": 5.0, "objective": 5.0, "excess": 0.0, "failed": 0, "feasible": True}

    def searched(spec: Any, where: Path, **_: object) -> lapwrench.study.tune.TuneOutcome:
        config_mod.dump(config_mod.load(), best)
        return lapwrench.study.tune.TuneOutcome([trial], trial, best)

    monkeypatch.setattr(lapwrench.study.tune, "run_tune", searched)
    monkeypatch.setattr(lapwrench.study.tune, "evaluate_config", _interrupt)
    assert main(["tune", str(tune_file), "--out", str(out), "--quiet"]) == 130
    assert capsys.readouterr().err == ("lapwrench tune: interrupted after the search; best.yaml is written but not "
                                       "checked; no report was written\n")
    monkeypatch.setattr(lapwrench.study.tune, "run_tune",
                        lambda spec, where, **_: lapwrench.study.tune.TuneOutcome([trial], None, None))
    (out / "tune_report.md").mkdir()
    assert main(["tune", str(tune_file), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"lapwrench tune: the trials are saved in {out}, but the report cannot be written: Is a "
                          "directory") and len(err.splitlines()) == 1, err


@pytest.mark.parametrize(("command", "where"), [("sweep", "out"), ("sweep", "study"), ("tune", "out")])
def test_a_path_that_is_not_utf8_is_refused_before_ray_starts(tmp_path: Path, command: str, where: str) -> None:
    """A byte of a Latin-1 name on the command line: Ray reads the process's command line as it starts and
    failed on it ("cannot start or reach a local Ray instance: UnicodeEncodeError"), and Ray Tune's storage
    path with a traceback. Now one line naming the path, before Ray starts and before --out is made."""
    odd = os.fsdecode(b"r\xe9sultats")
    data = STUDY if command == "sweep" else {
        **STUDY, "search": {"viscous.k_t": {"uniform": [120.0, 180.0]}}, "objective": {"metric": "duration_s"}}
    study = _write(tmp_path / (f"{odd}.yaml" if where == "study" else "study.yaml"), data)
    out = tmp_path / (odd if where == "out" else "out")
    proc = subprocess.run([sys.executable, "-m", "lapwrench.cli", command, str(study), "--out", str(out), "--quiet",
                           "--workers", "1"], capture_output=True, text=True, timeout=600,
                          env={**os.environ, "MUJOCO_GL": "egl"})
    assert proc.returncode == 2, proc.stderr
    what = "--out" if where == "out" else "the study file"
    assert proc.stderr.startswith(f"lapwrench {command}: {what} {tmp_path}/r\\xe9sultats")
    assert "is not UTF-8 text, which Ray needs on the command line" in proc.stderr
    assert len(proc.stderr.splitlines()) == 1 and not out.exists()
