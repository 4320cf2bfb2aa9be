"""The study's results table: one Parquet file, read at start (to resume) and rewritten atomically.

The file is always whole: rows are written to a temporary file beside it and moved into place, so a
study killed at any moment leaves the rows of every run that finished before, and a rerun skips
them (:attr:`ResultTable.done`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import pandas as pd

FILE = "runs.parquet"
STATUSES = ("ok", "failed")  # a row's status: its run finished, or its job raised


class TableError(ValueError):
    """The results file exists but cannot be read as a study table."""


def to_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """Rows as a table Parquet can store: a column mixing numbers and text (a grid of robot names and
    numbers, say) is stored as text; cells that are missing stay missing."""
    frame = pd.DataFrame(rows)
    for col in frame.columns:
        kinds = {type(v) for v in frame[col] if not _missing(v)}
        if str in kinds and len(kinds) > 1:
            frame[col] = [None if _missing(v) else str(v) for v in frame[col]]
    return frame


class ResultTable:
    """The rows of ``<out>/runs.parquet``; ``done`` holds the run ids already there."""

    def __init__(self, out: Path) -> None:
        self.path = out / FILE
        self.rows: list[dict[str, Any]] = []
        if self.path.exists():
            try:
                with open(self.path, "rb") as f:  # opened here: pyarrow takes only UTF-8 path names
                    old = pd.read_parquet(f)
            except Exception as exc:
                raise TableError(f"{self.path} is not a readable results table ({type(exc).__name__}); "
                                 "move it away to start over, or choose another --out") from exc
            if "run_id" not in old.columns or "status" not in old.columns:
                raise TableError(f"{self.path} has no run_id/status columns: not a lapwrench study table")
            self.rows = [{k: v for k, v in r.items() if not _missing(v)} for r in old.to_dict("records")]
            for i, r in enumerate(self.rows):
                if not isinstance(r.get("run_id"), str) or r.get("status") not in STATUSES:
                    raise TableError(f"{self.path} row {i} has run_id {str(r.get('run_id'))[:40]!r} and status "
                                     f"{str(r.get('status'))[:40]!r} (text and one of {', '.join(STATUSES)}): "
                                     "not a lapwrench study table; move it away or choose another --out")
        self.dirty = False

    @property
    def done(self) -> set[str]:
        return {r["run_id"] for r in self.rows}

    def failed_ids(self) -> set[str]:
        return {r["run_id"] for r in self.rows if r.get("status") == "failed"}

    def drop(self, run_ids: set[str]) -> None:
        """Forget the rows of ``run_ids`` (failed runs to try again)."""
        self.rows = [r for r in self.rows if r["run_id"] not in run_ids]
        self.dirty = True

    def add(self, rows: list[dict[str, Any]]) -> None:
        self.rows.extend(rows)
        self.dirty = True

    def frame(self) -> pd.DataFrame:
        return to_frame(self.rows)

    def save(self) -> None:
        """Write every row to the file, atomically (temporary file, fsync, rename)."""
        if not self.dirty:
            return
        tmp = self.path.with_suffix(".parquet.tmp")
        with open(tmp, "wb") as f:  # opened here: pyarrow takes only UTF-8 path names (a folder named in
            self.frame().to_parquet(f, index=False)  # Latin-1 lost every row of the sweep at its first save)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
        self.dirty = False


def _missing(v: object) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))
