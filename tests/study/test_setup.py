"""The study extra's set-up (lapwrench.study.setup): requirements from the installed metadata, and ensure()
never running the real pip in a test."""

from __future__ import annotations

import importlib.metadata
import subprocess
from typing import Any

import pytest

from lapwrench.study import setup
from lapwrench.study.setup import FALLBACK, SetupError, ensure, missing, requirements


def _name(req: str) -> str:
    return req.split(">")[0].split("<")[0].split("=")[0].strip()


@pytest.fixture
def no_pip(monkeypatch: pytest.MonkeyPatch) -> list[list[str]]:
    """Any pip call fails the test unless a test installs its own fake."""
    calls: list[list[str]] = []

    def refuse(cmd: list[str], **_: Any) -> subprocess.CompletedProcess:
        calls.append(cmd)
        raise AssertionError(f"the real pip would run: {cmd}")

    monkeypatch.setattr(setup.subprocess, "run", refuse)
    return calls


def test_requirements_are_the_study_extra_from_the_metadata() -> None:
    reqs = requirements()
    assert [_name(r) for r in reqs] == ["ray[tune]", "pyarrow", "pandas"]
    assert all(";" not in r and "extra" not in r for r in reqs)
    assert any("<3" in r for r in reqs if r.startswith("ray"))


def test_requirements_fall_back_without_metadata(monkeypatch: pytest.MonkeyPatch) -> None:
    def not_found(_name: str) -> list[str]:
        raise importlib.metadata.PackageNotFoundError("lapwrench")

    monkeypatch.setattr(setup.importlib.metadata, "requires", not_found)
    assert requirements() == FALLBACK


def test_requirements_fall_back_when_the_metadata_has_no_study_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(setup.importlib.metadata, "requires", lambda _n: ['numpy>=1.26', 'pytest; extra == "dev"'])
    assert requirements() == FALLBACK


def test_requirements_read_only_the_study_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(setup.importlib.metadata, "requires", lambda _n: [
        "numpy>=1.26", 'ruff; extra == "dev"', "ray[tune]<3,>=2.50 ; extra == 'study'", 'pyarrow>=15; extra=="study"',
        'ultralytics; extra == "studyx"'])
    assert requirements() == ("ray[tune]<3,>=2.50", "pyarrow>=15")


def test_nothing_is_missing_here() -> None:
    assert missing() == []


def test_ensure_does_nothing_when_everything_imports(no_pip: list) -> None:
    ensure("sweep")
    ensure("tune", install=False)
    assert no_pip == []


def test_ensure_without_install_raises_with_a_pip_hint(monkeypatch: pytest.MonkeyPatch, no_pip: list) -> None:
    monkeypatch.setattr(setup, "missing", lambda: ["ray", "ray.tune"])
    with pytest.raises(SetupError) as info:
        ensure("sweep", install=False)
    text = str(info.value)
    assert "ray" in text and "pip install" in text and "'ray[tune]" in text and "pyarrow" in text
    assert "\n" not in text
    assert no_pip == []


def test_ensure_reports_a_failed_pip(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    calls: list[list[str]] = []

    def failing_pip(cmd: list[str], **_: Any) -> subprocess.CompletedProcess:
        calls.append(cmd)
        err = "Collecting ray\nERROR: No matching distribution found for ray\n"
        return subprocess.CompletedProcess(cmd, 1, "", err)

    monkeypatch.setattr(setup, "missing", lambda: ["ray"])
    monkeypatch.setattr(setup.subprocess, "run", failing_pip)
    with pytest.raises(SetupError) as info:
        ensure("sweep")
    text = str(info.value)
    assert "No matching distribution found for ray" in text and "pip install" in text and "\n" not in text
    assert len(calls) == 1 and calls[0][1:4] == ["-m", "pip", "install"]
    assert list(requirements()) == calls[0][-len(requirements()):]
    assert "installing the study extra" in capsys.readouterr().err


def test_ensure_fails_when_pip_succeeds_but_modules_still_do_not_import(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(setup, "missing", lambda: ["pyarrow"])
    monkeypatch.setattr(setup.subprocess, "run", lambda cmd, **_: subprocess.CompletedProcess(cmd, 0, "", ""))
    with pytest.raises(SetupError, match="no output"):
        ensure("tune")


def test_ensure_succeeds_when_pip_installs_the_modules(monkeypatch: pytest.MonkeyPatch) -> None:
    state = {"installed": False}

    def pip(cmd: list[str], **_: Any) -> subprocess.CompletedProcess:
        state["installed"] = True
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(setup, "missing", lambda: [] if state["installed"] else ["ray"])
    monkeypatch.setattr(setup.subprocess, "run", pip)
    ensure("sweep")
    assert state["installed"]


def test_ensure_turns_an_unrunnable_pip_into_a_setup_error(monkeypatch: pytest.MonkeyPatch) -> None:
    def cannot_run(cmd: list[str], **_: Any) -> subprocess.CompletedProcess:
        raise FileNotFoundError(2, "No such file or directory", cmd[0])

    monkeypatch.setattr(setup, "missing", lambda: ["ray"])
    monkeypatch.setattr(setup.subprocess, "run", cannot_run)
    with pytest.raises(SetupError, match="pip install"):
        ensure("sweep")
