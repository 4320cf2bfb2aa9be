"""The study's results table: one Parquet file, read at start (to resume) and rewritten atomically.

The file is always whole: rows are written to a temporary file beside it and moved into place, so a
study killed at any moment leaves the rows of every run that finished before, and a rerun skips
them (:attr:`ResultTable.done`).

A study file edited between two sweeps into the same folder (another grid, fewer seeds or scenarios) leaves
rows of runs it no longer has: they are kept (a finished run is never thrown away, and comes back if the
edit is undone) with ``in_study`` false, and left out of the report (:meth:`ResultTable.mark_study`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import pandas as pd

FILE = "runs.parquet"
IN_STUDY = "in_study"  # column: whether the row's run belongs to the study as the folder's last sweep had it
STATUSES = ("ok", "failed")  # a row's status: its run finished, or its job raised


class TableError(ValueError):
    """The results file exists but cannot be read as a study table."""


def to_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """Rows as a table Parquet can store: a column mixing numbers and text (a grid of robot names and
    numbers, say) is stored as text; cells that are missing stay missing."""
    import pandas as pd  # here: a stop signal's message must not need pandas (lapwrench.study.cli)

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
            import pandas as pd

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
        self.rows.extend({**r, IN_STUDY: True} for r in rows)
        self.dirty = True

    def mark_study(self, run_ids: set[str]) -> int:
        """Set every row's ``in_study``: whether its run is one of ``run_ids`` (the study's jobs now); returns
        how many rows are not (kept in the file, left out of :meth:`frame`)."""
        outside = 0
        for r in self.rows:
            inside = r["run_id"] in run_ids
            outside += not inside
            if r.get(IN_STUDY) is not inside:  # also a numpy bool read back from the file: made plain
                r[IN_STUDY] = inside
                self.dirty = True
        return outside

    def frame(self, *, everything: bool = False) -> pd.DataFrame:
        """The rows of the study's runs (all of them, ``in_study`` false too, with ``everything``)."""
        return to_frame(self.rows if everything else [r for r in self.rows if bool(r.get(IN_STUDY, True))])

    def save(self) -> None:
        """Write every row to the file, atomically (temporary file, fsync, rename)."""
        if not self.dirty:
            return
        tmp = self.path.with_suffix(".parquet.tmp")
        # opened here: pyarrow takes only UTF-8 path names (a folder named in Latin-1 lost every row of the
        # sweep at its first save)
        with open(tmp, "wb") as f:
            self.frame(everything=True).to_parquet(f, index=False)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
        self.dirty = False


def _missing(v: object) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))
