"""Benchmark: does ``lapwrench ui`` run the simulation at real time with the 25 fps laparoscope stream?

Same-run reference first: the bare closed loop (``ClosedLoop.step`` of the page's loop, no UI, no
threads) and the page's own tick alone (``Session.step``), each stepped flat out for
``--ref-seconds`` wall seconds: simulated seconds per wall second, i.e. the most the machine could
give the page. Then :class:`lapwrench.ui.app.UiApp` (port 0, headless) runs for ``--warmup`` +
``--seconds`` wall seconds, once with no browser and, with ``--browser``, once more with headless
Chromium (Debian's /usr/bin/chromium and chromedriver, driven by selenium as tests/ui/test_app.py
does) showing the page. Over the ``--seconds`` window after the warm-up it reports:

* ``rtf``: simulated seconds per wall second (the runner paces to the wall clock, so 1.0 is the most
  it can show; it falls below 1 when the sim thread cannot keep up);
* ``tick_ms``: wall time of one tick in the UI's sim thread, sleeps excluded (the runner's
  busy time per tick, averaged over its windows) (vs the session's tick alone: the
  threads' and the other processes' toll on the control loop); ``headroom_x`` = 1 ms / tick_ms;
* ``view_fps``: laparoscope frames the view produced per second; ``sent_fps``: view images sent to
  the page per second; with a browser also ``shown_fps``: new view images the page displayed per
  second (counted in the page by a MutationObserver on the image's ``src``);
* ``page_hz``: page updates (scene poses) per second;
* per-thread CPU (% of one core) of this process's threads, the render child's and Chromium's, and
  the share of the wall time the sim thread was ready to run but waited for a core (run queue).

Usage (from the repository root):

    MUJOCO_GL=egl .venv/bin/python bench/ui.py [--seconds 20] [--warmup 5] [--browser]

Against another tree (A/B): ``PYTHONPATH=/path/to/tree/src .venv/bin/python bench/ui.py ...``.
The last line printed is one JSON object with unit-suffixed keys.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import threading
import time
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")

import lapwrench
from lapwrench import config
from lapwrench.cli_types import float_in
from lapwrench.sim.world import CONTROL_DT
from lapwrench.ui.playback import PLAYABLE

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
TICK = os.sysconf("SC_CLK_TCK")

# Counts the view image's new pictures in the page: viser shows each as an <img> with a new blob URL.
_COUNT_IMAGES = """
window.__lw_shown = 0;
const srcs = new Set();
const seen = new WeakSet();
const count = (img) => { const s = img.getAttribute('src') || '';
  if (s.startsWith('blob:') && !srcs.has(s)) { srcs.add(s); window.__lw_shown += 1; } };
const watch = (img) => { if (seen.has(img)) return; seen.add(img);
  new MutationObserver(() => count(img)).observe(img, {attributes: true, attributeFilter: ['src']}); };
document.querySelectorAll('img').forEach(watch);
new MutationObserver(() => document.querySelectorAll('img').forEach(watch))
  .observe(document.body, {childList: true, subtree: true});
return true;
"""


def cpu_seconds(pid: int, tid: int | None = None) -> float:
    """User + system CPU seconds of a process (all its threads) or of one of its threads."""
    path = f"/proc/{pid}/stat" if tid is None else f"/proc/{pid}/task/{tid}/stat"
    try:
        with open(path) as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / TICK


def children(pid: int) -> list[int]:
    """All descendants of ``pid``."""
    out: list[int] = []
    kids: list[int] = []
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):  # a child belongs to the thread that started it
            with open(f"/proc/{pid}/task/{tid}/children") as f:
                kids.extend(int(x) for x in f.read().split())
    except OSError:
        return out
    for k in kids:
        out.append(k)
        out.extend(children(k))
    return out


def process_name(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/comm") as f:
            return f.read().strip()
    except OSError:
        return "?"


def cpu_snapshot() -> dict[str, float]:
    """CPU seconds by thread of this process (by Python thread name) and by child process kind."""
    me = os.getpid()
    out: dict[str, float] = {}
    for t in threading.enumerate():
        if t.native_id is not None:
            name = t.name if t.name.startswith(("lapwrench", "Main")) else "viser/other threads"
            out[name] = out.get(name, 0.0) + cpu_seconds(me, t.native_id)
            if t.name == "lapwrench-ui-sim":  # seconds it was ready to run but waited for a core
                with open(f"/proc/{me}/task/{t.native_id}/schedstat") as f:
                    out["sim thread waiting for a core"] = int(f.read().split()[1]) / 1e9
    out["process total"] = cpu_seconds(me)
    for pid in children(me):
        comm = process_name(pid)
        kind = "chromium" if "chrom" in comm else ("render child" if "python" in comm else comm)
        out[kind] = out.get(kind, 0.0) + cpu_seconds(pid)
    return out


def reference(cfg: config.Config, seconds: float) -> dict[str, float]:
    """Simulated seconds per wall second of the bare closed loop and of the page's tick alone."""
    from lapwrench.ui.session import Session, build_loop

    closed = build_loop(cfg, 0, "projected")
    session = Session(cfg)
    out = {}
    for name, step in (("closed_loop", lambda: closed.step(0.0)), ("session", session.step)):
        for _ in range(200):
            step()
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            for _ in range(50):
                step()
            n += 50
        wall = time.perf_counter() - t0
        out[f"{name}_rtf_x"] = n * CONTROL_DT / wall
        out[f"{name}_tick_ms"] = wall / n * 1e3
    closed.world.close()
    session.closed.world.close()
    return out


class SentCounter:
    """Counts the images the page is sent: wraps the app's image handle (its ``image`` setter)."""

    def __init__(self, handle: Any) -> None:
        self._handle = handle
        self.count = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self._handle, name)

    def __setattr__(self, name: str, value: Any) -> None:
        if name in ("_handle", "count"):
            object.__setattr__(self, name, value)
            return
        if name == "image":
            self.count += 1
        setattr(self._handle, name, value)


def images_sent(app: Any) -> int:
    n = getattr(app, "images_sent", None)
    return int(n) if n is not None else app.image.count


def start_browser(url: str, preload: str | None = None) -> Any:
    """Headless Chromium on ``url``, once the page is built; ``preload`` is a script the page runs before
    its own (Chrome DevTools' ``Page.addScriptToEvaluateOnNewDocument``)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1280,900"):
        opts.add_argument(arg)
    opts.binary_location = CHROMIUM
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.set_page_load_timeout(60)
    driver.set_script_timeout(120)
    if preload is not None:
        driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": preload})
    driver.get(url)
    end = time.monotonic() + 90
    while time.monotonic() < end:  # the page is built when its buttons are
        try:
            if driver.execute_script("return document.querySelectorAll('button').length > 5 "
                                     "&& document.querySelectorAll('img').length > 0"):
                break
        except Exception:
            pass
        time.sleep(0.5)
    else:
        raise RuntimeError("the page did not come up in 90 s")
    return driver


def ui_run(cfg: config.Config, seconds: float, warmup: float, browser: bool, scenario: str) -> dict[str, float]:
    """One UiApp run: figures over ``seconds`` after ``warmup`` (see the module docstring)."""
    from lapwrench.ui.app import UiApp, UiOptions

    app = UiApp(cfg, UiOptions(port=0))
    if getattr(app, "images_sent", None) is None:
        app.image = SentCounter(app.image)
    driver = None
    app.start()
    try:
        if browser:
            driver = start_browser(app.url)
        end = time.monotonic() + 120
        while app.view.frames == 0 and time.monotonic() < end:  # the render child is up
            time.sleep(0.1)
        if scenario != "none":
            app.session.play(scenario)
        time.sleep(warmup)
        if driver is not None:
            driver.execute_script(_COUNT_IMAGES)
        s0 = (time.perf_counter(), app.session.time, app.view.frames, images_sent(app), app.page_frames,
              app.runner.ticks, cpu_snapshot(), getattr(app.runner, "dropped", float("nan")))
        busy: list[float] = []  # the runner's busy time per tick, one sample per window
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            time.sleep(min(app.runner.window, max(0.0, end - time.monotonic())))
            busy.append(app.runner.step_seconds)
        s1 = (time.perf_counter(), app.session.time, app.view.frames, images_sent(app), app.page_frames,
              app.runner.ticks, cpu_snapshot(), getattr(app.runner, "dropped", float("nan")))
        shown = driver.execute_script("return window.__lw_shown") if driver is not None else None
    finally:
        if driver is not None:
            driver.quit()
        app.stop()
    wall = s1[0] - s0[0]
    out = {"rtf_x": (s1[1] - s0[1]) / wall, "tick_ms": 1e3 * sum(busy) / max(len(busy), 1),
           "view_fps": (s1[2] - s0[2]) / wall, "sent_fps": (s1[3] - s0[3]) / wall,
           "page_hz": (s1[4] - s0[4]) / wall, "dropped_pct": 100 * (s1[7] - s0[7]) / wall,
           "sim_nice": getattr(app.runner, "nice", None) or 0,
           "sim_realtime": int(getattr(app.runner, "realtime", False))}
    if shown is not None:
        out["shown_fps"] = shown / wall
    for k in sorted(set(s0[6]) | set(s1[6])):
        out[f"cpu_{k.replace(' ', '_').replace('/', '_')}_pct"] = 100 * (s1[6].get(k, 0.0) - s0[6].get(k, 0.0)) / wall
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float_in(1.0, 3600.0), default=20.0,
                   help="measured window of each UI run (wall s)")
    p.add_argument("--warmup", type=float_in(0.0, 600.0), default=5.0,
                   help="wall s before the window (after the first frame)")
    p.add_argument("--ref-seconds", type=float_in(0.5, 600.0), default=3.0, help="wall s of each reference run")
    p.add_argument("--browser", action="store_true", help="also a run with headless Chromium on the page")
    p.add_argument("--browser-only", action="store_true", help="only the run with Chromium")
    p.add_argument("--scenario", default="workflow", choices=["none", *PLAYABLE],
                   help="paper scenario played from the warm-up on, so the scene moves ('none': the scope at rest)")
    args = p.parse_args(argv)
    cfg = config.load()
    print(f"lapwrench from {os.path.dirname(lapwrench.__file__)}; load {os.getloadavg()}", flush=True)
    result: dict[str, float] = {}
    ref = reference(cfg, args.ref_seconds)
    result.update(ref)
    print(f"reference: closed loop {ref['closed_loop_rtf_x']:.2f}x real time"
          f" ({ref['closed_loop_tick_ms']:.3f} ms/tick), session alone {ref['session_rtf_x']:.2f}x"
          f" ({ref['session_tick_ms']:.3f} ms/tick)", flush=True)
    runs = [] if args.browser_only else [("nobrowser", False)]
    if args.browser or args.browser_only:
        runs.append(("browser", True))
    for name, browser in runs:
        r = ui_run(cfg, args.seconds, args.warmup, browser, args.scenario)
        line = (f"{name}: rtf {r['rtf_x']:.3f}x, tick {r['tick_ms']:.3f} ms"
                f" ({r['tick_ms'] / ref['session_tick_ms']:.2f}x the session's alone), view {r['view_fps']:.1f} fps,"
                f" sent {r['sent_fps']:.1f} fps, page {r['page_hz']:.1f} Hz")
        if "shown_fps" in r:
            line += f", shown in the page {r['shown_fps']:.1f} fps"
        print(line + f", dropped {r['dropped_pct']:.1f} % of the wall time, sim thread nice {r['sim_nice']}"
                   f"{' SCHED_RR' if r['sim_realtime'] else ''}",
              flush=True)
        print("  cpu % of a core: " + ", ".join(f"{k[4:-4]} {v:.0f}" for k, v in r.items() if k.startswith("cpu_")),
              flush=True)
        result.update({f"{k.rsplit('_', 1)[0]}_{name}_{k.rsplit('_', 1)[1]}": v for k, v in r.items()})
        result[f"rtf_{name}_over_session_alone_x"] = r["rtf_x"] / min(1.0, ref["session_rtf_x"])
    result["load_1min"] = os.getloadavg()[0]
    print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in result.items()}))
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:  # the page, its render process and the browser were stopped on the way out
        print("bench/ui.py: interrupted; no figures", file=sys.stderr)
        sys.exit(130)
