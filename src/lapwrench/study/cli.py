"""The ``lapwrench sweep`` and ``lapwrench tune`` commands.

A bad argument or study file ends with one line ``lapwrench sweep: ...`` on stderr and exit code 2,
before Ray starts. Ctrl-C, SIGTERM and SIGHUP stop a sweep after saving every finished row (exit code
128 + the signal's number: 130, 143, 129; one line saying where they are, or that none had finished);
running it again resumes. The signals are :mod:`lapwrench.cli_signals`' (a second one is ignored while the
rows are saved and Ray stops; one the shell left ignored, as ``nohup`` does SIGHUP, stays ignored). A report
that cannot be written (the disk filled) is one line and exit code 1, the runs kept.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path
from typing import Any

from lapwrench.cli_signals import signal_of, stop_line
from lapwrench.cli_types import display_path, int_in, output_dir, positive_float
from lapwrench.config_yaml import cut, short

ADDRESS_HELP = "an existing Ray cluster (HOST:PORT, or 'auto'); default: start Ray here, embedded"


class StudyUsageError(Exception):
    """A bad argument or file: one line on stderr, exit code 2."""


def add_parsers(sub: Any) -> None:
    """Add ``sweep`` and ``tune`` to ``lapwrench``'s subparsers."""
    sw = sub.add_parser("sweep", help="run a study (STUDY.yaml) on Ray: many seeded runs, a Parquet table, a report")
    sw.add_argument("study", metavar="STUDY.yaml", help="the study file (see studies/paper.yaml)")
    sw.add_argument("--out", type=output_dir, default=None, help="results folder (default reports/sweeps/<name>)")
    sw.add_argument("--retry-failed", action="store_true", help="run the failed runs of an earlier sweep again")
    sw.add_argument("--save-every", type=positive_float, default=None, metavar="SECONDS",
                    help="save the results table at most this often while runs finish, > 0 (default 5)")
    tu = sub.add_parser("tune", help="search gains with Ray Tune for an objective under constraints (TUNE.yaml)")
    tu.add_argument("study", metavar="TUNE.yaml", help="the tuning file (see studies/tune.yaml)")
    tu.add_argument("--out", type=output_dir, default=None, help="results folder (default reports/tune/<name>)")
    for p in (sw, tu):
        p.add_argument("--address", default=None, help=ADDRESS_HELP)
        p.add_argument("--workers", type=int_in(1, 256), default=None,
                       help="CPUs of the embedded Ray, at most this machine's (default: all of them)")
        p.add_argument("--quiet", action="store_true", help="no progress bar")
    sw.set_defaults(func=sweep_main)
    tu.set_defaults(func=tune_main)


def _utf8_arguments(args: argparse.Namespace) -> None:
    """StudyUsageError for a path or address that is not UTF-8 text (a byte of a Latin-1 file name): Ray
    reads this process's command line when it starts and fails on it, Ray Tune on its storage path, and
    pyarrow takes only UTF-8 path names."""
    for name, value in (("the study file", args.study), ("--out", args.out), ("--address", args.address)):
        try:
            str(value).encode("utf-8")
        except UnicodeEncodeError:
            raise StudyUsageError(f"{name} {cut(display_path(value), 100)} is not UTF-8 text, which Ray needs on the "
                                  "command line; rename it or choose another path") from None


def _prepare(args: argparse.Namespace, command: str) -> None:
    from lapwrench.study import setup

    if args.address is not None and args.workers is not None:
        raise StudyUsageError("--workers sizes the embedded Ray; a cluster at --address has its own CPUs")
    from lapwrench.study.runner import available_cpus

    if args.workers is not None and args.workers > (cpus := available_cpus()):
        raise StudyUsageError(f"--workers {args.workers}: this process may use {cpus} CPUs; more workers would only "
                              "take turns on them, each holding a simulation in memory (--address runs on a cluster)")
    if args.address is not None:  # its form, before anything is installed (reachability: when Ray starts)
        from lapwrench.study.runner import ClusterError, parse_address

        try:
            parse_address(args.address)
        except ClusterError as exc:
            raise StudyUsageError(str(exc)) from exc
    try:
        setup.ensure(command)
    except setup.SetupError as exc:
        raise StudyUsageError(str(exc)) from exc


def _out(args: argparse.Namespace, kind: str, name: str) -> Path:
    from lapwrench.config import ensure_writable_dir

    out = Path(args.out) if args.out else Path("reports") / kind / name
    try:
        ensure_writable_dir(out)
        special = next((p for p in out.iterdir() if p.exists() and not (p.is_file() or p.is_dir())), None)
    except OSError as exc:
        raise StudyUsageError(f"--out {cut(str(out), 100)} is not writable: {exc.strerror or exc}") from exc
    if special is not None:  # reading or writing a FIFO there waits for another program, forever
        raise StudyUsageError(f"--out {cut(str(out), 100)} holds {cut(display_path(special.name), 60)}, a pipe, socket "
                              "or device: a results folder holds files; move it away or choose another --out")
    return out


def _same_study(out: Path, name: str) -> None:
    """Refuse a results folder that holds another study (its ``study.yaml`` names another): the rerun of
    the same study resumes there, a different one would replace its study.yaml and mix their rows."""
    from lapwrench.study.spec import StudyError, read_file

    copy = out / "study.yaml"
    if not copy.is_file():
        return
    try:
        data, _ = read_file(copy, "study")
    except StudyError as exc:
        raise StudyUsageError(f"--out {cut(str(out), 100)} holds a study.yaml that cannot be read ({exc}); "
                              "choose another --out") from exc
    other = data.get("name") if isinstance(data, dict) else None
    if isinstance(other, str) and other.strip() != name:
        raise StudyUsageError(f"--out {cut(str(out), 100)} holds the results of study {short(other.strip())}, not "
                              f"{short(name)}; choose another --out")


def _start(args: argparse.Namespace, command: str) -> tuple[Any, Path]:
    """The validated study (``sweep``) or tuning file (``tune``) and its results folder; the study extra
    installed if missing. StudyUsageError on a bad input."""
    from lapwrench.study.spec import StudyError, load_study
    from lapwrench.study.tune_spec import load_tune

    _utf8_arguments(args)
    try:
        spec = load_study(args.study) if command == "sweep" else load_tune(args.study)
    except StudyError as exc:
        raise StudyUsageError(str(exc)) from exc
    _prepare(args, command)
    out = _out(args, "sweeps" if command == "sweep" else "tune", spec.name)
    if command == "sweep":
        _same_study(out, spec.name)
    return spec, out


def _stopped(command: str, exc: KeyboardInterrupt) -> tuple[str, int]:
    """The start of the line for a stop signal (``lapwrench sweep: stopped by SIGTERM``) and the exit code."""
    signum = signal_of(exc)
    return stop_line(command, signum), 128 + signum


def _saved(out: Path | None) -> str:
    """What an interrupted sweep leaves in ``out`` (None: interrupted before its folder was known)."""
    from lapwrench.study.table import FILE

    table = None if out is None else out / FILE
    if table is None or not table.is_file():
        return "no run had finished, nothing was saved"
    return f"the finished runs are saved in {cut(str(table), 200)}; run the same command again to resume"


def sweep_main(args: argparse.Namespace) -> int:
    """Run a study; exit 0 when every job ran (failed runs included, as rows), 128 + n for a stop signal
    (130: Ctrl-C), 1 when the runs are saved but the report (or the study's copy) cannot be written."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    out: Path | None = None
    try:
        spec, out = _start(args, "sweep")
        from lapwrench.study.runner import SAVE_EVERY_S, ClusterError, run_study
        from lapwrench.study.spec import StudyError
        from lapwrench.study.table import TableError

        try:
            outcome, table = run_study(spec, out, address=args.address, workers=args.workers, progress=not args.quiet,
                                       retry_failed=args.retry_failed,
                                       save_every_s=SAVE_EVERY_S if args.save_every is None else args.save_every)
        except (TableError, ClusterError, StudyError) as exc:  # StudyError: a point expand() refuses
            raise StudyUsageError(str(exc)) from exc
    except StudyUsageError as exc:
        print(f"lapwrench sweep: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        line, code = _stopped("sweep", exc)
        print(f"{line}; {_saved(out)}", file=sys.stderr)
        return code
    from lapwrench.study.report import write_report

    notes = [f"This sweep ran {outcome.ran} jobs ({outcome.failed} failed) and skipped {outcome.skipped} already in "
             f"the table, in {outcome.wall_s:.0f} s on {len(outcome.nodes - {'lost'}) or 0} node(s)."]
    if outcome.outside:  # the study file was edited since the last sweep into this folder
        notes.append(f"{outcome.outside} rows of runs this study no longer has (its grid, seeds or scenarios changed) "
                     "are kept in the table with in_study = false and left out of this report.")
    try:
        if Path(args.study).resolve() != (out / "study.yaml").resolve():
            shutil.copyfile(args.study, out / "study.yaml")
        report = write_report(table.frame(), out, spec.report, notes=notes)
    except OSError as exc:  # a full disk, a folder made read-only, a report.md that is a folder
        print(f"lapwrench sweep: the runs are saved in {cut(str(table.path), 200)}, but the report cannot be "
              f"written: {exc.strerror or exc}{'' if exc.filename is None else f' ({cut(str(exc.filename), 200)})'}",
              file=sys.stderr)
        return 1
    for note in notes:
        print(f"lapwrench sweep: {note}")
    print(f"results: {table.path}\nreport: {report}")
    return 0


def tune_main(args: argparse.Namespace) -> int:
    """Search gains; exit 0 with best.yaml written, 1 when no trial met every constraint (or the results
    cannot be written), 128 + n for a stop signal (130: Ctrl-C)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    out: Path | None = None
    try:
        spec, out = _start(args, "tune")
        from lapwrench.study.runner import ClusterError
        from lapwrench.study.tune import run_tune

        try:
            outcome = run_tune(spec, out, address=args.address, workers=args.workers, progress=not args.quiet)
        except ClusterError as exc:
            raise StudyUsageError(str(exc)) from exc
    except StudyUsageError as exc:
        print(f"lapwrench tune: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        line, code = _stopped("tune", exc)
        print(f"{line}; no configuration was written", file=sys.stderr)
        return code
    except OSError as exc:  # trials.parquet or best.yaml: a full disk, a folder made read-only
        print(f"lapwrench tune: cannot write the results in {cut(str(out or args.out), 200)}: {exc.strerror or exc}",
              file=sys.stderr)
        return 1
    try:
        return _finish_tune(spec, out, outcome)
    except KeyboardInterrupt as exc:
        line, code = _stopped("tune", exc)
        unchecked = "best.yaml is written but not checked; " if outcome.best_config is not None else ""
        print(f"{line} after the search; {unchecked}no report was written", file=sys.stderr)
        return code
    except OSError as exc:
        print(f"lapwrench tune: the trials are saved in {cut(str(out), 200)}, but the report cannot be written: "
              f"{exc.strerror or exc}", file=sys.stderr)
        return 1


def _finish_tune(spec: Any, out: Path, outcome: Any) -> int:
    """Load best.yaml back, run the scenario set with it once more, and write the report."""
    from lapwrench import config as config_mod
    from lapwrench.study.tune import evaluate_config
    from lapwrench.study.tune_report import write_tune_report

    check = None
    if outcome.best_config is not None:
        ev, _ = evaluate_config(spec, config_mod.load(outcome.best_config))
        check = (f"{'passed' if ev.feasible else 'FAILED'}: {spec.reduce} {spec.objective[2:]} = {ev.objective:.4g}"
                 + "".join(f", worst {k[2:]} = {v:.4g}" for k, v in ev.worst.items()))
    report = write_tune_report(outcome.trials, spec, out, best_config=outcome.best_config, check=check)
    feasible = sum(1 for t in outcome.trials if t.get("feasible") is True)
    print(f"lapwrench tune: {feasible} of {len(outcome.trials)} trials met every constraint")
    if outcome.best_config is not None:
        print(f"best: {outcome.best_config} (check {check})")
    print(f"report: {report}")
    return 0 if outcome.best_config is not None else 1
