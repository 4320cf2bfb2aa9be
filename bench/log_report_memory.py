"""Benchmark: the memory ``log-report`` needs per logged cycle, holding the cycles or gathering columns.

A log of ``--cycles`` records like the runner's (7 joints, three wrenches, two cues' telemetry: 5 values)
is written once; then, alternately in fresh processes (``--rounds`` times each, interleaved), the log is
read as the report used to read it (``load_log``: every cycle kept as a dict) and as it reads it now
(``read_for_report``: :class:`~lapwrench.hardware.log.columns.CycleColumns`), and each process reports
its peak resident memory (``VmHWM``) over that of a process that only imported the same modules.
The difference divided by the cycles is the memory per cycle. Last line: one JSON object.

    python bench/log_report_memory.py [--cycles N] [--rounds R]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = """
import sys
from lapwrench.hardware.log import load_log
from lapwrench.hardware.log.report import read_for_report

def peak_kb():  # VmHWM: this process's own peak (ru_maxrss keeps the parent's across exec)
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))

before = peak_kb()
how, path = sys.argv[1], sys.argv[2]
if how == "dicts":
    n = len(load_log(path).cycles)
else:
    log, cols = read_for_report(path)
    n = cols.n
print(n, peak_kb() - before)
"""


def write_log(path: Path, cycles: int) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import numpy as np
    from hardware.log.support import record

    from lapwrench.hardware.log import RunLogger

    rng = np.random.default_rng(0)
    layout = {"zoom": ("spread", "in_band", "force"), "keep_out": ("distance", "barrier")}
    with RunLogger(path, {"robot": "bench"}, telemetry=layout, capacity=cycles + 1, start=False) as log:
        for k in range(cycles):
            log.cycle(record(k, q=rng.normal(size=7), q_cmd=rng.normal(size=7), rcm_error=float(rng.random()),
                             telemetry={"zoom": tuple(rng.random(3)), "keep_out": tuple(rng.random(2))}))


def peak_kb(how: str, path: Path) -> tuple[int, int]:
    out = subprocess.run([sys.executable, "-c", CHILD, how, str(path)], capture_output=True, text=True, check=True)
    n, kb = out.stdout.split()
    return int(n), int(kb)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=20_000)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        write_log(path, args.cycles)
        result: dict[str, list[float]] = {"dicts": [], "columns": []}
        for _ in range(args.rounds):
            for how in ("dicts", "columns"):
                n, kb = peak_kb(how, path)
                assert n == args.cycles, (how, n)
                result[how].append(kb * 1024 / n)
                print(f"{how:8s} {kb / 1024:8.1f} MB over the imports, {kb * 1024 / n:7.0f} B per cycle")
    print(json.dumps({"cycles": args.cycles, "bytes_per_cycle": result,
                      "load_average": Path("/proc/loadavg").read_text().split()[:3]}))


if __name__ == "__main__":
    main()
