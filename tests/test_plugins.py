"""lapwrench.plugins: finding cues and inputs by name through entry points."""

from __future__ import annotations

import importlib.metadata
from collections.abc import Callable
from pathlib import Path

import pytest

from lapwrench import plugins
from lapwrench.wrenches.tracking import TrackingCue


def test_the_paper_cues_are_found_by_name() -> None:
    assert {"rcm", "interaction", "tracking", "viscous"} <= set(plugins.names(plugins.CUE_GROUP))
    assert plugins.load(plugins.CUE_GROUP, "tracking") is TrackingCue


def test_an_unknown_name_is_one_line_naming_what_is_installed() -> None:
    with pytest.raises(plugins.PluginError) as err:
        plugins.load(plugins.CUE_GROUP, "warp_drive")
    msg = str(err.value)
    assert "warp_drive" in msg and "tracking" in msg and "\n" not in msg


def _fake_entry_points(*eps: importlib.metadata.EntryPoint) -> Callable[..., list[importlib.metadata.EntryPoint]]:
    return lambda group: [ep for ep in eps if ep.group == group]


def test_a_plugin_that_fails_to_import_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    ep = importlib.metadata.EntryPoint("broken", "no_such_module_xyz:Cue", plugins.CUE_GROUP)
    monkeypatch.setattr(importlib.metadata, "entry_points", _fake_entry_points(ep))
    with pytest.raises(plugins.PluginError, match=r"broken.*failed to load: ModuleNotFoundError"):
        plugins.load(plugins.CUE_GROUP, "broken")


def test_a_name_registered_twice_by_different_packages_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    a = importlib.metadata.EntryPoint("twin", "pkg_a:Cue", plugins.CUE_GROUP)
    b = importlib.metadata.EntryPoint("twin", "pkg_b:Cue", plugins.CUE_GROUP)
    monkeypatch.setattr(importlib.metadata, "entry_points", _fake_entry_points(a, b))
    with pytest.raises(plugins.PluginError, match="more than one package"):
        plugins.load(plugins.CUE_GROUP, "twin")


@pytest.mark.parametrize("name", ["tracking", "zoom_2", "a"])
def test_names_are_lower_case_identifiers(name: str) -> None:
    assert plugins.NAME.match(name)


@pytest.mark.parametrize("name", ["Tracking", "2zoom", "a-b", "", "x" * 41, "a b", "a\n"])
def test_other_names_are_not(name: str) -> None:
    assert not plugins.NAME.match(name)


def test_a_plugin_that_exits_while_it_imports_is_one_line_not_an_exit(monkeypatch: pytest.MonkeyPatch,
                                                                       tmp_path: Path) -> None:
    (tmp_path / "exits_on_import_xyz.py").write_text("import sys\nsys.exit(3)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    ep = importlib.metadata.EntryPoint("exits", "exits_on_import_xyz:Cue", plugins.CUE_GROUP)
    monkeypatch.setattr(importlib.metadata, "entry_points", _fake_entry_points(ep))
    with pytest.raises(plugins.PluginError, match=r"exits_on_import_xyz:Cue\) failed to load: SystemExit"):
        plugins.load(plugins.CUE_GROUP, "exits")


def test_a_plugin_import_error_of_many_lines_is_one_short_line(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    (tmp_path / "chatty_on_import_xyz.py").write_text("raise ImportError('first\\nsecond\\n' + 'x' * 5000)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    ep = importlib.metadata.EntryPoint("chatty", "chatty_on_import_xyz:Cue", plugins.CUE_GROUP)
    monkeypatch.setattr(importlib.metadata, "entry_points", _fake_entry_points(ep))
    with pytest.raises(plugins.PluginError, match="ImportError: first second x") as err:
        plugins.load(plugins.CUE_GROUP, "chatty")
    assert "\n" not in str(err.value) and len(str(err.value)) < 400
