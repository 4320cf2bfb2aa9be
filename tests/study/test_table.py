"""The results table (lapwrench.study.table): mixed columns, the atomic round trip a resumed study relies
on, and refusing a file that is not a study table."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest

from lapwrench.study.table import FILE, ResultTable, TableError, to_frame


def _row(run_id: str, status: str = "ok", **cols: object) -> dict[str, object]:
    return {"run_id": run_id, "study": "t", "scenario": "grip", "label": "high", "seed": 0, "status": status,
            "error": None if status == "ok" else "RuntimeError: boom", **cols}


# --------------------------------------------------------------------------- to_frame


def test_column_mixing_text_and_numbers_becomes_text_keeping_missing_cells() -> None:
    frame = to_frame([{"p.robot": "panda"}, {"p.robot": 3}, {"p.robot": 2.5}, {"p.robot": None},
                      {"p.robot": math.nan}, {}])
    assert list(frame["p.robot"][:3]) == ["panda", "3", "2.5"]
    assert frame["p.robot"][3:].isna().all()  # None, NaN and an absent cell stay missing, not "None"/"nan"


def test_numeric_and_text_only_columns_keep_their_type() -> None:
    frame = to_frame([{"a": 1, "b": "x", "c": 1.5}, {"a": 2, "b": "y", "c": math.nan}])
    assert pd.api.types.is_integer_dtype(frame["a"])
    assert list(frame["b"]) == ["x", "y"]
    assert pd.api.types.is_float_dtype(frame["c"]) and math.isnan(frame["c"][1])


def test_mixed_frame_writes_to_parquet(tmp_path: Path) -> None:
    rows = [_row("a", **{"p.robot": "panda", "m.x": 1.0}), _row("b", **{"p.robot": 0.5, "m.x": math.nan}),
            _row("c", "failed", **{"p.robot": None})]
    to_frame(rows).to_parquet(tmp_path / "x.parquet", index=False)
    back = pd.read_parquet(tmp_path / "x.parquet")
    assert list(back["p.robot"][:2]) == ["panda", "0.5"] and back["p.robot"].isna()[2]


def test_empty_rows_give_an_empty_frame() -> None:
    assert len(to_frame([])) == 0


# --------------------------------------------------------------------------- ResultTable


def test_new_table_is_empty_and_saving_nothing_writes_nothing(tmp_path: Path) -> None:
    table = ResultTable(tmp_path)
    assert table.done == set() and table.failed_ids() == set()
    table.save()
    assert not (tmp_path / FILE).exists()


def test_round_trip_keeps_rows_and_done_ids(tmp_path: Path) -> None:
    table = ResultTable(tmp_path)
    table.add([_row("aaaa", **{"m.rcm_error_max_mm": 0.4, "p.robot": "fr3"}),
               _row("aaaa", label="low", **{"m.rcm_error_max_mm": 0.6, "p.robot": "fr3"}),
               _row("bbbb", "failed", label=None, **{"p.robot": 7})])
    table.save()
    assert (tmp_path / FILE).is_file()
    assert [p.name for p in tmp_path.iterdir()] == [FILE]  # no temporary file left beside it

    again = ResultTable(tmp_path)
    assert again.done == {"aaaa", "bbbb"}
    assert again.failed_ids() == {"bbbb"}
    assert len(again.rows) == 3
    failed = next(r for r in again.rows if r["run_id"] == "bbbb")
    assert failed["error"] == "RuntimeError: boom"
    assert "m.rcm_error_max_mm" not in failed and "label" not in failed  # missing cells are dropped on reading
    ok = [r for r in again.rows if r["run_id"] == "aaaa"]
    assert sorted(r["m.rcm_error_max_mm"] for r in ok) == [0.4, 0.6]


def test_adding_to_a_reopened_table_keeps_the_old_rows(tmp_path: Path) -> None:
    first = ResultTable(tmp_path)
    first.add([_row("a1")])
    first.save()
    second = ResultTable(tmp_path)
    second.add([_row("b2", **{"m.new": 1.0})])
    second.save()
    third = ResultTable(tmp_path)
    assert third.done == {"a1", "b2"}
    assert len(pd.read_parquet(tmp_path / FILE)) == 2


def test_drop_forgets_failed_runs_for_a_retry(tmp_path: Path) -> None:
    table = ResultTable(tmp_path)
    table.add([_row("ok1"), _row("bad1", "failed"), _row("bad2", "failed")])
    table.save()
    again = ResultTable(tmp_path)
    again.drop(again.failed_ids())
    assert again.done == {"ok1"} and again.failed_ids() == set()
    again.save()
    assert ResultTable(tmp_path).done == {"ok1"}


def test_drop_of_nothing_keeps_every_row(tmp_path: Path) -> None:
    table = ResultTable(tmp_path)
    table.add([_row("x"), _row("y", "failed")])
    table.drop(set())
    table.drop({"not-there"})
    assert table.done == {"x", "y"}


def test_save_replaces_a_stale_temporary_file(tmp_path: Path) -> None:
    (tmp_path / (FILE + ".tmp")).write_bytes(b"half a file from a killed run")
    table = ResultTable(tmp_path)
    table.add([_row("z")])
    table.save()
    assert not (tmp_path / (FILE + ".tmp")).exists()
    assert ResultTable(tmp_path).done == {"z"}


@pytest.mark.parametrize("content", [b"", b"garbage, not parquet", b"PAR1" + b"\0" * 64])
def test_unreadable_file_is_a_table_error_naming_it(tmp_path: Path, content: bytes) -> None:
    (tmp_path / FILE).write_bytes(content)
    with pytest.raises(TableError) as info:
        ResultTable(tmp_path)
    assert str(tmp_path / FILE) in str(info.value)


def test_truncated_table_is_a_table_error(tmp_path: Path) -> None:
    table = ResultTable(tmp_path)
    table.add([_row(f"{i:04d}", **{"m.x": float(i)}) for i in range(50)])
    table.save()
    data = (tmp_path / FILE).read_bytes()
    (tmp_path / FILE).write_bytes(data[: len(data) // 2])
    with pytest.raises(TableError, match=FILE):
        ResultTable(tmp_path)


@pytest.mark.parametrize("columns", [{"id": ["a"], "status": ["ok"]}, {"run_id": ["a"]}, {"x": [1.0]}])
def test_parquet_that_is_not_a_study_table_is_refused(tmp_path: Path, columns: dict) -> None:
    pd.DataFrame(columns).to_parquet(tmp_path / FILE)
    with pytest.raises(TableError) as info:
        ResultTable(tmp_path)
    assert str(tmp_path / FILE) in str(info.value) and "run_id" in str(info.value)


def test_a_directory_named_like_the_table_is_refused(tmp_path: Path) -> None:
    (tmp_path / FILE).mkdir()
    with pytest.raises(TableError, match=FILE):
        ResultTable(tmp_path)


@pytest.mark.parametrize("columns", [
    {"run_id": [None, "b"], "status": ["ok", "ok"]},  # a missing run id: KeyError from ResultTable.done
    {"run_id": [[1], [2]], "status": ["ok", "ok"]},  # a list: TypeError (unhashable) from ResultTable.done
    {"run_id": [1, 2], "status": ["ok", "failed"]},
    {"run_id": ["a", "b"], "status": ["ok", "finished"]},
    {"run_id": ["a", "b"], "status": ["ok", None]},
])
def test_rows_without_a_text_run_id_and_a_known_status_are_refused(tmp_path: Path, columns: dict) -> None:
    """A table with the right columns but other values is not a study's table: a TableError naming the
    file (one line of lapwrench sweep), not a KeyError or TypeError traceback when the done ids are read."""
    pd.DataFrame(columns).to_parquet(tmp_path / FILE)
    with pytest.raises(TableError) as info:
        ResultTable(tmp_path).done  # noqa: B018 (what a sweep reads first)
    assert str(tmp_path / FILE) in str(info.value) and "not a lapwrench study table" in str(info.value)


def test_a_folder_name_that_is_not_utf8_holds_the_table(tmp_path: Path) -> None:
    """pyarrow takes only UTF-8 path names: --out with a Latin-1 name ran every job, then failed to save
    their rows (a UnicodeEncodeError traceback, nothing kept)."""
    import os

    out = tmp_path / os.fsdecode(b"r\xe9sultats")
    out.mkdir()
    table = ResultTable(out)
    table.add([_row("a"), _row("b", "failed")])
    table.save()
    again = ResultTable(out)
    assert again.done == {"a", "b"} and again.failed_ids() == {"b"}


def test_rows_of_runs_outside_the_study_are_kept_marked_and_left_out_of_the_frame(tmp_path: Path) -> None:
    """A study edited between two sweeps: its old runs' rows stay in the file (in_study false), not in the frame
    the report is drawn from; marking them again as they were changes nothing."""
    table = ResultTable(tmp_path)
    table.add([{"run_id": "a", "status": "ok"}, {"run_id": "b", "status": "failed"}])
    table.save()
    edited = ResultTable(tmp_path)
    assert edited.mark_study({"a", "c"}) == 1
    edited.save()
    again = ResultTable(tmp_path)
    assert list(again.frame().run_id) == ["a"] and list(again.frame(everything=True).in_study) == [True, False]
    assert again.done == {"a", "b"}  # a finished run is never run again, even outside the study
    assert again.mark_study({"a", "c"}) == 1 and not again.dirty
    assert again.mark_study({"a", "b"}) == 0 and len(again.frame()) == 2
