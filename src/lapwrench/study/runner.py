"""Run a study's jobs on Ray: embedded and local by default, or on a cluster given its address.

Each job is one Ray task of one CPU (:func:`lapwrench.study.execute.run_job`), so a machine runs as many
jobs at once as it has cores, and a cluster as many as all its nodes. The driver keeps a few tasks
per CPU in flight, saves the table as results come back (:class:`~lapwrench.study.table.ResultTable`),
at most every ``save_every_s`` seconds, and shows a progress bar. A Ray this process already started is
used as it is and left running. A task lost with its worker (killed, out of memory) is a failed row like
any other failure; the study goes on.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lapwrench.config_yaml import short
from lapwrench.study.execute import job_rows, one_line, run_job
from lapwrench.study.spec import Job, StudyError, StudySpec
from lapwrench.study.table import ResultTable

SAVE_EVERY_S = 5.0  # default: the table is rewritten at most this often while results arrive (and at the end)
IN_FLIGHT_PER_CPU = 2
# Every worker process: one thread per maths library (a job is one CPU), headless rendering.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "NUMBA_NUM_THREADS": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


class ClusterError(RuntimeError):
    """Ray could not be started here, or the cluster at ``--address`` could not be reached."""


@dataclass
class SweepOutcome:
    """What a sweep did: jobs run now, skipped (already in the table), failed now, nodes used."""

    ran: int = 0
    skipped: int = 0
    failed: int = 0
    wall_s: float = 0.0
    nodes: set[str] = field(default_factory=set)
    interrupted: bool = False
    outside: int = 0  # rows of runs the study no longer has (kept with in_study false, out of the report)


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity: ``taskset`` or a container's cpuset count, unlike
    ``os.cpu_count()``): what the embedded Ray gets by default, and the most ``--workers`` may ask."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not on Linux
        return os.cpu_count() or 1


def parse_address(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of a Ray head node's ``HOST:PORT`` (``ray://`` allowed), None for ``auto``;
    ClusterError naming the argument otherwise."""
    if address == "auto":
        return None
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ClusterError(f"--address {address[:80]!r} is not HOST:PORT of a Ray head node")
    return host.strip("[]"), int(port)


def _auto_address() -> str:
    """The ``HOST:PORT`` Ray's ``auto`` means here: ``RAY_ADDRESS``, else the cluster ``ray start`` last
    wrote in Ray's temporary folder (which ``ray stop`` leaves behind), else a running one; ClusterError
    when there is none."""
    from ray._private.services import get_ray_address_from_environment  # Ray's own resolution of "auto"

    try:
        return str(get_ray_address_from_environment("auto", None))
    except ConnectionError as exc:
        raise ClusterError(f"--address auto: {one_line(exc)}") from exc


def check_reachable(address: str, timeout_s: float = 3.0) -> None:
    """ClusterError unless ``HOST:PORT`` accepts a TCP connection within ``timeout_s`` (Ray itself
    retries an unreachable address for minutes). ``auto`` is resolved as Ray does (:func:`_auto_address`)
    and checked the same way: a cluster stopped since is refused at once."""
    target = parse_address(address)
    if target is None:
        resolved = _auto_address()
        if resolved == "auto" or (target := parse_address(resolved)) is None:
            return  # a running instance found by its processes: Ray connects to it
        address = f"auto ({resolved})"
    try:
        socket.create_connection(target, timeout=timeout_s).close()
    except OSError as exc:
        raise ClusterError(f"cannot reach the Ray cluster at {address[:80]}: {exc.strerror or exc}") from exc
    except UnicodeError as exc:  # a host name the IDNA codec refuses (a label over 63 characters)
        raise ClusterError(f"cannot reach the Ray cluster at {address[:80]}: not a valid host name ({exc})") from exc


def _signal_handlers() -> dict[int, Any]:
    """The current SIGINT/SIGTERM/SIGHUP handlers (none off the main thread, where they cannot be set)."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}


def start_ray(address: str | None, workers: int | None) -> int:
    """Connect to the cluster at ``address``, or start Ray here with ``workers`` CPUs (default: all);
    returns the CPUs the cluster offers."""
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    import ray

    # Ray's notice that token authentication is on (it is, and should be) on every start
    logging.getLogger("ray._private.authentication.authentication_token_setup").setLevel(logging.ERROR)

    kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "logging_level": logging.WARNING,
                              "runtime_env": {"env_vars": WORKER_ENV}}
    if address:
        check_reachable(address)
    with _held_signals() as held:
        try:
            if address:
                ray.init(address=address, **kwargs)
            else:
                # "local": a new instance of our own, even when another cluster runs on this machine
                ray.init(address="local", num_cpus=workers or available_cpus(), **kwargs)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = f"the Ray cluster at {address}" if address else "a local Ray instance"
            raise ClusterError(f"cannot start or reach {where}: {one_line(exc)}") from exc
    try:
        for sig in held:  # now, with the caller's handlers back: Ctrl-C during the start raises here
            signal.raise_signal(sig)
    except BaseException:
        ray.shutdown()  # Ray has started whole: its shutdown stops every process it started
        raise
    return _cluster_cpus()


@contextlib.contextmanager
def _held_signals() -> Iterator[list[int]]:
    """SIGINT, SIGTERM and SIGHUP noted, not acted on, while the block runs (ray.init): a start cut
    halfway leaves Ray's agents running with no raylet, long after this process. The caller's handlers
    come back at the end (ray.init installs its own SIGTERM handler: the caller's wins); the signals
    noted are the caller's to deliver."""
    handlers = _signal_handlers()
    held: list[int] = []
    for sig in handlers:
        signal.signal(sig, lambda signum, _frame: held.append(signum))
    try:
        yield held
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)


def _cluster_cpus() -> int:
    """The CPUs of the Ray cluster this process runs or joined (at least 1)."""
    import ray

    return max(1, int(ray.cluster_resources().get("CPU", 1)))


def _ray_running() -> bool:
    """Whether this process has started or joined Ray already (without importing Ray when it has not)."""
    ray = sys.modules.get("ray")
    return ray is not None and bool(ray.is_initialized())


def _remote() -> Any:
    import ray

    @ray.remote(num_cpus=1, max_retries=0)
    def study_task(job: Job, study: str) -> list[dict]:
        rows = run_job(job, study)
        node = ray.get_runtime_context().get_node_id()[:8]
        for r in rows:
            r["node"] = node
        return rows

    return study_task


def run_study(
    spec: StudySpec,
    out: Path,
    *,
    address: str | None = None,
    workers: int | None = None,
    retry_failed: bool = False,
    progress: bool = True,
    on_rows: Callable[[list[dict]], None] | None = None,
    save_every_s: float = SAVE_EVERY_S,
) -> tuple[SweepOutcome, ResultTable]:
    """Run every job of ``spec`` not yet in ``<out>/runs.parquet``; returns what happened and the table.
    The table is saved at most every ``save_every_s`` seconds while results arrive, and at the end.
    When this process has started Ray already (``ray.is_initialized()``), that Ray runs the jobs and
    stays up; ``address`` and ``workers`` must then be None. Otherwise Ray is started here (see
    :func:`start_ray`) and shut down at the end.

    Raises:
        ValueError: ``save_every_s`` is not a finite number > 0, or ``address``/``workers`` are given
            while Ray already runs in this process.
        TableError: the table exists but is damaged (before anything runs).
        StudyError: the table holds another study's rows, or a point of the study is refused (before
            anything runs).
        ClusterError: Ray could not start or connect.
        KeyboardInterrupt: after the finished rows were saved and the running tasks cancelled.
    """
    from tqdm import tqdm

    from lapwrench.study.spec import expand

    if isinstance(save_every_s, bool) or not (isinstance(save_every_s, int | float) and math.isfinite(save_every_s)
                                              and save_every_s > 0):
        raise ValueError(f"save_every_s must be a finite number > 0, got {save_every_s!r}")
    own_ray = not _ray_running()
    if not own_ray and (address is not None or workers is not None):
        raise ValueError("Ray already runs in this process: address and workers must be None")
    out.mkdir(parents=True, exist_ok=True)
    table = ResultTable(out)
    others = sorted({str(r["study"]) for r in table.rows if r.get("study") not in (None, spec.name)})
    if others:  # their rows would mix with this study's in the report
        raise StudyError(f"{table.path} holds rows of study {short(others[0])}, not {short(spec.name)}; "
                         "choose another --out")
    jobs = expand(spec)
    ids = {j.run_id for j in jobs}
    if retry_failed:
        table.drop(table.failed_ids() & ids)
    outcome = SweepOutcome(outside=table.mark_study(ids))
    done = table.done
    todo = [j for j in jobs if j.run_id not in done]
    outcome.skipped = len(jobs) - len(todo)
    if not todo:
        table.save()
        return outcome, table
    t0 = time.perf_counter()
    import ray

    cpus = start_ray(address, workers) if own_ray else _cluster_cpus()
    task = _remote()
    pending: dict[Any, Job] = {}
    queue = list(reversed(todo))
    bar = tqdm(total=len(todo), desc=f"sweep {spec.name}", unit="run", disable=not progress, mininterval=1.0)
    last_save = time.monotonic()
    try:
        while queue or pending:
            while queue and len(pending) < cpus * IN_FLIGHT_PER_CPU:
                job = queue.pop()
                pending[task.remote(job, spec.name)] = job
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
            for ref in ready:
                job = pending.pop(ref)
                try:
                    rows = ray.get(ref)
                except Exception as exc:
                    rows = job_rows(job, spec.name, None, one_line(exc), 0.0)
                    for r in rows:
                        r["node"] = "lost"
                table.add(rows)
                outcome.ran += 1
                outcome.failed += any(r["status"] == "failed" for r in rows)
                outcome.nodes.update(r.get("node", "") for r in rows)
                if on_rows is not None:
                    on_rows(rows)
                bar.update(1)
                bar.set_postfix(failed=outcome.failed, refresh=False)
            if time.monotonic() - last_save > save_every_s:
                table.save()
                last_save = time.monotonic()
    except KeyboardInterrupt:
        outcome.interrupted = True
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
    finally:
        bar.close()
        table.save()
        outcome.wall_s = time.perf_counter() - t0
        if own_ray:
            ray.shutdown()
    return outcome, table
