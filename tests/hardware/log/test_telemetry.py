"""lapwrench.hardware.log.telemetry: every cue's telemetry fields in the run log's cycle messages,
named by the configured cues, bounded where the configuration is read (issue 13)."""

from __future__ import annotations

import argparse
import importlib.metadata
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hardware.log.support import record

from lapwrench import plugins
from lapwrench.config import from_dict, to_dict
from lapwrench.config_cues import MAX_CUE_TELEMETRY, MAX_TELEMETRY, parse_cues
from lapwrench.config_ranges import ConfigError
from lapwrench.hardware import cli as hw
from lapwrench.hardware.log import RunLogger, iter_messages, load_log, read_log
from lapwrench.hardware.log.cycle_codec import cycle_descriptor
from lapwrench.hardware.log.telemetry import (
    checked_layout,
    layout_from_meta,
    message_name,
    simulation_layout,
    telemetry_layout,
)
from lapwrench.spatial import Wrench
from lapwrench.wrenches.base import Cue, TickContext

KEEP_OUT = {"keep_out": {"center": [0.9, 0.0, 0.1], "radius": 0.05}}


def _cue(fields: tuple[str, ...]) -> type[Cue]:
    class Chatty(Cue):
        telemetry_fields = fields

        def compute(self, ctx: TickContext) -> Wrench:
            return Wrench.zero(ctx.kin.p_C)

    return Chatty


@pytest.fixture
def chatty(monkeypatch: pytest.MonkeyPatch) -> dict[str, type[Cue]]:
    """Cues registered for this test only: ``wide`` has too many telemetry fields, ``many_a`` ..
    ``many_d`` have the most a cue may have (four of them pass the total)."""
    fake: dict[str, type[Cue]] = {"wide": _cue(tuple(f"v{i}" for i in range(MAX_CUE_TELEMETRY + 1))),
                                  "twice": _cue(("a", "a")), "upper": _cue(("Speed",))}
    for name in "abcd":
        fake[f"many_{name}"] = _cue(tuple(f"v{i}" for i in range(MAX_CUE_TELEMETRY)))
    real = plugins.load
    monkeypatch.setattr(plugins, "load", lambda group, name: fake.get(name) or real(group, name))
    return fake


@pytest.fixture
def registered(chatty: dict[str, type[Cue]], monkeypatch: pytest.MonkeyPatch) -> dict[str, type[Cue]]:
    """The ``chatty`` cues registered as entry points (beside the real ones), and ``broken``, whose
    module does not exist (it fails to load)."""
    real = importlib.metadata.entry_points
    extra = [importlib.metadata.EntryPoint(n, f"lapwrench_no_such_plugin_{n}:Cue", plugins.CUE_GROUP)
             for n in (*chatty, "broken")]

    def entry_points(**params: Any) -> list[importlib.metadata.EntryPoint]:
        return list(real(**params)) + (extra if params.get("group") == plugins.CUE_GROUP else [])

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)
    assert {"broken", "wide", "many_a"} <= set(plugins.names(plugins.CUE_GROUP))
    return chatty


ZOOM = ("zoom", ("spread", "in_band", "force"))
KEEP_OUT_FIELDS = ("distance", "barrier")


def test_live_simulated_runs_log_the_configured_cues_then_every_registered_type_under_its_name(
    registered: dict[str, type[Cue]],
) -> None:
    """The configuration's cues first (in its order, under its names), then each registered type that
    runs in Python and declares telemetry, by name: a name already there, a fused cue (interaction),
    a cue whose fields break the bounds (wide, twice, upper) and one that fails to load are left out."""
    zone = KEEP_OUT["keep_out"]
    cfg = from_dict({"cues": {"zoom": {}, "near": {"type": "keep_out", **zone}}})
    assert telemetry_layout(cfg.cues) == (ZOOM, ("near", KEEP_OUT_FIELDS))
    layout = simulation_layout(cfg.cues)
    assert layout[:3] == (ZOOM, ("near", KEEP_OUT_FIELDS), ("keep_out", KEEP_OUT_FIELDS))
    names = [n for n, _ in layout]
    assert len(set(names)) == len(names) and sum(len(f) for _, f in layout) <= MAX_TELEMETRY
    assert not {"interaction", "broken", "wide", "twice", "upper"} & set(names)
    other = from_dict({"cues": {"far": {"type": "keep_out", **zone}}})  # the demo's second (tracking) config
    assert simulation_layout(cfg.cues, other.cues)[:3] == (ZOOM, ("near", KEEP_OUT_FIELDS), ("far", KEEP_OUT_FIELDS))


def test_without_a_configured_cue_the_shipped_cue_types_are_logged_by_their_names() -> None:
    """What the demo's zoom and keep-out scenarios add (``cues={"zoom": {}}``) is in the layout; a
    disabled configured cue is not, but its type is."""
    layout = simulation_layout()
    assert ZOOM in layout and ("keep_out", KEEP_OUT_FIELDS) in layout
    assert not {"rcm", "interaction", "tracking", "viscous"} & {n for n, _ in layout}  # in the compiled tick
    off = from_dict({"cues": {"zoom": {"enabled": False}}})
    assert telemetry_layout(off.cues) == () and simulation_layout(off.cues) == layout


def test_the_registered_types_stop_before_the_bound_on_the_fields_logged(registered: dict[str, type[Cue]]) -> None:
    """16 fields configured; keep_out's two fit, then many_c's eight would pass 24: nothing more."""
    cfg = from_dict({"cues": {"many_a": {}, "many_b": {}}})
    layout = simulation_layout(cfg.cues)
    assert [n for n, _ in layout] == ["many_a", "many_b", "keep_out"]
    assert sum(len(f) for _, f in layout) == 2 * MAX_CUE_TELEMETRY + 2 <= MAX_TELEMETRY
    full = from_dict({"cues": {f"many_{n}": {} for n in "abc"}})  # 24: the bound itself
    assert [n for n, _ in simulation_layout(full.cues)] == ["many_a", "many_b", "many_c"]


def test_the_layout_names_the_python_cues_that_declare_telemetry() -> None:
    """keep_out (a plugin-style cue) logs its fields; the paper's cues run in the compiled tick and
    carry none here, the interaction cue's included (its δ and n_c are the cycle's own fields)."""
    cfg = from_dict({"cues": KEEP_OUT})
    assert telemetry_layout(cfg.cues) == (("keep_out", ("distance", "barrier")),)
    assert telemetry_layout(from_dict({}).cues) == ()
    assert layout_from_meta({"config": to_dict(cfg)}) == (("keep_out", ("distance", "barrier")),)
    assert layout_from_meta({"robot": "test"}) == () and layout_from_meta(None) == ()
    off = from_dict({"cues": {"keep_out": {**KEEP_OUT["keep_out"], "enabled": False}}})
    assert telemetry_layout(off.cues) == ()


def test_a_layout_given_in_code_is_held_to_the_same_bounds() -> None:
    assert checked_layout({"zoom": ["spread", "force"], "quiet": []}) == (("zoom", ("spread", "force")),)
    with pytest.raises(ValueError, match="at most 8"):
        checked_layout({"zoom": [f"v{i}" for i in range(MAX_CUE_TELEMETRY + 1)]})
    with pytest.raises(ValueError, match="in all"):
        checked_layout({f"c{i}": [f"v{j}" for j in range(MAX_CUE_TELEMETRY)] for i in range(4)})
    with pytest.raises(ValueError, match="lower-case"):
        checked_layout({"zoom": ["in band"]})
    assert message_name("keep_out") == "Keep_out" != message_name("keepout")


@pytest.mark.parametrize(
    ("cues", "words"),
    [
        ({"wide": {}}, ("cues.wide", "declares 9 telemetry fields", "at most 8")),
        ({"twice": {}}, ("cues.twice", "twice")),
        ({"upper": {}}, ("cues.upper", "lower-case")),
        ({f"many_{n}": {} for n in "abcd"}, ("'cues'", "32 telemetry fields", f"at most {MAX_TELEMETRY}")),
    ],
)
def test_a_cue_with_too_many_telemetry_fields_is_refused_in_one_line(
    chatty: dict[str, type[Cue]], cues: dict[str, Any], words: tuple[str, ...]
) -> None:
    with pytest.raises(ConfigError) as err:
        parse_cues(cues)
    message = str(err.value)
    assert "\n" not in message and all(w in message for w in words), message


def test_lapwrench_run_refuses_such_a_config_before_anything_starts(
    chatty: dict[str, type[Cue]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = tmp_path / "wide.yaml"
    cfg.write_text("cues:\n  wide: {}\n")
    p = argparse.ArgumentParser()
    hw.add_run_arguments(p)
    code = hw.run_main(p.parse_args(["--dry-run", "--config", str(cfg), "--duration", "1"]))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("lapwrench run:") and "telemetry" in err[0]


def test_the_log_carries_each_cues_telemetry_by_name(tmp_path: Path) -> None:
    """Written with a layout, read back by name; a cycle without a cue's values leaves it out; the
    file's schema (what Foxglove plots with) names the fields."""
    from google.protobuf import descriptor_pb2

    path = tmp_path / "run.mcap"
    layout = {"zoom": ("spread", "in_band", "force"), "pedal_home": ("pressed", "angle_deg")}
    with RunLogger(path, {"robot": "test"}, telemetry=layout) as log:
        for k in range(50):
            values = {"zoom": (0.1 * k, 1.0, math.nan), "pedal_home": (float(k > 20), 10.0 - k / 10)}
            log.cycle(record(k, telemetry=values if k != 5 else {"zoom": (0.5, 0.0, 0.0)}))
    cycles = read_log(path)[0]
    assert cycles[30]["telemetry"] == {"zoom": {"spread": 3.0, "in_band": 1.0, "force": None},
                                       "pedal_home": {"pressed": 1.0, "angle_deg": 7.0}}
    assert cycles[5]["telemetry"] == {"zoom": {"spread": 0.5, "in_band": 0.0, "force": 0.0}}
    fds = descriptor_pb2.FileDescriptorSet.FromString(cycle_descriptor(tuple(layout.items())))
    telemetry = next(m for m in fds.file[0].message_type if m.name == "Telemetry")
    assert [f.name for f in telemetry.field] == ["zoom", "pedal_home"]
    assert [f.name for f in telemetry.nested_type[0].field] == ["spread", "in_band", "force"]


def test_a_log_takes_its_telemetry_fields_from_the_configuration_in_its_meta(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with RunLogger(path, {"config": to_dict(from_dict({"cues": KEEP_OUT}))}) as log:
        log.cycle(record(0, telemetry={"keep_out": (0.25, 3.0), "not_configured": (1.0,)}))
    (cycle,) = read_log(path)[0]
    assert cycle["telemetry"] == {"keep_out": {"distance": 0.25, "barrier": 3.0}}


def test_a_log_without_telemetry_fields_reads_as_before(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with RunLogger(path, {"robot": "test"}) as log:
        log.cycle(record(0, telemetry={"zoom": (1.0, 2.0, 3.0)}))
    assert [m["telemetry"] for _, m in iter_messages(path, ["/lapwrench/cycle"])] == [{}]


@pytest.mark.parametrize("in_process", [False, True], ids=["rt-process", "in-process"])
def test_lapwrench_run_logs_the_cue_telemetry(in_process: bool, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """``run --dry-run`` (the 1 kHz child: the values cross the real-time bus) and ``--in-process``
    both log the configured keep-out cue's distance and barrier every cycle."""
    cfg, log = tmp_path / "keep_out.yaml", tmp_path / "run.mcap"
    cfg.write_text("cues:\n  keep_out: {center: [0.9, 0.0, 0.1], radius: 0.05}\n")
    # the telemetry is under test, not the machine's timing: no stop on deadline misses in a row
    argv = ["--dry-run", "--duration", "0.3", "--config", str(cfg), "--log", str(log), "--max-misses", "0"]
    p = argparse.ArgumentParser()
    hw.add_run_arguments(p)
    code = hw.run_main(p.parse_args(argv + (["--in-process"] if in_process else [])))
    contents = load_log(log)
    cycles = contents.cycles
    assert code == 0, capsys.readouterr().err
    assert len(cycles) >= 250
    distance = np.array([c["telemetry"]["keep_out"]["distance"] for c in cycles])
    assert np.all(distance > 0.2) and np.all(distance < 0.6)  # the tip is far outside the zone
    assert {c["telemetry"]["keep_out"]["barrier"] for c in cycles} == {0.0}
