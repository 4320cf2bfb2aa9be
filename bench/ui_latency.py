"""Benchmark: from a push on ``lapwrench ui``'s page to a visible motion in its 3D scene (target <= 100 ms).

Headless Chromium (Debian's, driven by selenium as in ``bench/ui.py``) shows the page with the grip set
to "high" from the page. Each of ``--pushes`` pushes starts with the scope at rest and is one key typed
into the page's own "push (N)" box (``9``: a 9 N push across the shaft, one change of the control).
It is timed on the wall clock that the page and the server share (the page's
``performance.timeOrigin + performance.now()``, the server's ``time.time()``):

* ``key``: the keydown in the page (the push);
* ``received``: the server's control callback sets the hand's push;
* ``sent``: the page thread sends the handle body's pose first moved by at least one pixel of the
  page's view from where it was when the push reached the server (one pixel: the handle's distance
  from the page's camera, the camera's vertical field of view and the canvas height in CSS px);
* ``arrived``: viser's websocket worker hands the page a pose of the handle at least one pixel from
  where the page showed it at the keydown (a hook on the page's Worker);
* ``shown``: the end of the first animation frame that starts after it arrived (viser applies the
  queued messages at the start of a frame and three.js draws it in the same frame; the compositor
  puts it on screen after that, so this is a lower bound of the photon time by one compositor frame).

``latency_ms`` = shown - key. Same-run references: the page's own frame interval (rAF to rAF) and the
page thread's update period (:data:`lapwrench.ui.app.PAGE_HZ`), the two waits every push must sit
through. The browser renders WebGL in software here (no GPU), so its frame interval is far above a
desktop's 16.7 ms. Each push starts with the handle at rest (gripped, it still creeps by a fraction of
a millimetre per second, so positions are taken at the push, not before it).

Usage (from the repository root):

    MUJOCO_GL=egl .venv/bin/python bench/ui_latency.py [--pushes 8] [--push-n 9]

The last line printed is one JSON object with unit-suffixed keys.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from typing import Any

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import mujoco
from ui import start_browser

from lapwrench import config
from lapwrench.cli_types import float_in, int_in
from lapwrench.ui.app import PAGE_HZ, UiApp, UiOptions

WATCHED_BODY = "lap_handle"  # the scope's handle: of the scope's bodies it moves the most about the incision

# Runs in the page before viser's scripts. From the push's keydown on it keeps the raw events, for
# Python to read: the arrival of each message about the watched handle body or the force arrows, and the
# start and end of each animation frame. Before the keydown it keeps where the page shows every body (the last
# pose it was sent: a body at rest is not sent again, so this cannot wait for the watched one to move).
PRELOAD = """
(() => {
  const clock = () => performance.timeOrigin + performance.now();
  const lw = window.__lw = {watch: null, key: null, p0: null, last: {}, msgs: [], frames: [], ts: []};
  const W = window.Worker;
  window.Worker = class extends W {
    constructor(...args) {
      super(...args);
      this.addEventListener('message', (e) => {
        const d = e.data;
        if (!d || d.type !== 'message_batch') return;
        const t = clock(), w = lw.watch;
        for (const m of d.messages) {
          const pose = m.type === 'SetPositionMessage';
          if (pose) lw.last[m.name] = Array.from(m.position);  // p0 is taken from here at the keydown
          if (!w || lw.key === null) continue;
          if (pose && m.name === w.name) lw.msgs.push([t, 'pose', Array.from(m.position)]);
          else if (m.name === w.arrows) lw.msgs.push([t, 'arrows', null]);
        }
      });
    }
  };
  const raf = window.requestAnimationFrame.bind(window);
  window.requestAnimationFrame = (cb) => raf((ts) => {
    const start = clock();
    const f = lw.frames;
    if (lw.ts.length === 0 || lw.ts[lw.ts.length - 1] !== ts) {
      lw.ts.push(ts);
      if (lw.ts.length > 4000) lw.ts.splice(0, 2000);
      if (lw.key !== null) f.push([start, start]);
    }
    cb(ts);
    if (lw.key !== null && f.length) f[f.length - 1][1] = clock();  // the frame's last callback so far ended
  });
  document.addEventListener('keydown', (e) => {
    if (lw.watch && lw.key === null && e.key === lw.watch.key) {
      lw.key = clock();
      lw.p0 = lw.last[lw.watch.name] || null;
    }
  }, true);
})();
"""

_FIND_BUTTON = """
const b = Array.from(document.querySelectorAll('button')).find(b => b.innerText.trim() === arguments[0]);
if (b) b.scrollIntoView({block: 'center'});
return b;
"""
_FIND_NUMBER = """
const label = Array.from(document.querySelectorAll('label')).find(x => x.innerText.trim() === arguments[0]);
if (!label) return null;
const box = label.parentElement.parentElement.parentElement.querySelector('input.mantine-NumberInput-input');
if (box) { box.scrollIntoView({block: 'center'}); box.focus(); box.select(); }  // as a click and Ctrl+A would
return box;
"""
_CANVAS_HEIGHT = """
let best = null;
for (const c of document.querySelectorAll('canvas')) {
  const r = c.getBoundingClientRect();
  if (!best || r.width * r.height > best.width * best.height) best = r;
}
return best.height;
"""


class Probe:
    """Server-side timestamps (s, wall clock): when the push reached the hand (``received``), when the
    page thread first sent the scene with the hand's force drawn (``response_sent``) and with the handle
    moved one pixel (``motion_sent``)."""

    def __init__(self, app: UiApp, body: int) -> None:
        self.body = body
        self.p0 = np.zeros(3)  # where the handle was when the push came
        self.armed = False
        self.threshold = math.inf
        self.received: float | None = None
        self.response_sent: float | None = None
        self.motion_sent: float | None = None
        hand, scene = app.session.hand, app.scene
        set_push, update = hand.set_push, scene.update

        def on_push(azimuth: object, magnitude: object) -> None:
            set_push(azimuth, magnitude)
            snap = app.session.snapshot
            if self.armed and self.received is None and hand.push_magnitude > 0.0 and snap is not None:
                self.received, self.p0 = time.time(), snap.body_pos[self.body].copy()

        def on_update(snapshot: Any, colors: Any) -> int:
            n = update(snapshot, colors)
            if self.received is None:
                return n
            now = time.time()
            if self.response_sent is None and np.any(snapshot.hand_force != 0.0):
                self.response_sent = now
            moved = float(np.linalg.norm(snapshot.body_pos[self.body] - self.p0))
            if self.motion_sent is None and moved >= self.threshold:
                self.motion_sent = now
            return n

        hand.set_push = on_push  # type: ignore[method-assign]
        scene.update = on_update  # type: ignore[method-assign]

    def arm(self, threshold: float) -> None:
        self.armed, self.threshold = True, threshold
        self.received = self.response_sent = self.motion_sent = None


def wait_for(condition: Any, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return
        time.sleep(0.02)
    raise RuntimeError(f"timed out ({timeout:.0f} s) waiting for {what}")


def handle_at_rest(app: UiApp, body: int, seconds: float = 0.3, tol: float = 2e-5) -> np.ndarray:
    """Wait until the handle moved less than ``tol`` m over ``seconds`` of simulated time; its position."""
    end = time.monotonic() + 30.0
    while time.monotonic() < end:
        snap = app.session.snapshot
        assert snap is not None
        p, t = snap.body_pos[body].copy(), snap.t
        wait_for(lambda t=t: app.session.time >= t + seconds, 30.0, "simulated time")
        snap = app.session.snapshot
        assert snap is not None
        if float(np.linalg.norm(snap.body_pos[body] - p)) < tol:
            return snap.body_pos[body].copy()
    raise RuntimeError("the handle did not come to rest in 30 s")


def pixel_m(app: UiApp, driver: Any, point: np.ndarray) -> float:
    """Metres one CSS pixel of the page's view spans at ``point``."""
    clients = app.server.get_clients()
    camera = next(iter(clients.values())).camera
    height = float(driver.execute_script(_CANVAS_HEIGHT))
    distance = float(np.linalg.norm(point - np.asarray(camera.position)))
    return 2.0 * distance * math.tan(camera.fov / 2.0) / height


def type_into(driver: Any, label: str, text: str) -> Any:
    """Focus the number box of the control labelled ``label`` with its text selected (one script call:
    each WebDriver round trip to this software-rendered page takes seconds) and type ``text``; the box."""
    from selenium.webdriver.common.keys import Keys

    box = driver.execute_script(_FIND_NUMBER, label)
    if box is None:
        raise RuntimeError(f"the page has no number box labelled {label!r}")
    if text:
        box.send_keys(text, Keys.TAB)
    return box


def one_push(app: UiApp, driver: Any, probe: Probe, body: int, digit: str, azimuth: int) -> dict[str, float]:
    """One push from rest across the shaft towards ``azimuth`` (deg); the timestamps (ms, wall clock) of
    its stages."""
    type_into(driver, "push direction (deg)", str(azimuth))
    wait_for(lambda: app.session.hand.push_azimuth_deg == azimuth, 10, "the push direction")
    driver.execute_script(_FIND_BUTTON, "high").click()
    wait_for(lambda: app.session.hand.grip_force > 0, 10, "the grip")
    p0 = handle_at_rest(app, body)
    px = pixel_m(app, driver, p0)
    box = type_into(driver, "push (N)", "")
    probe.arm(px)
    driver.execute_script("const lw = window.__lw; lw.key = null; lw.msgs = []; lw.frames = [];"
                          " lw.watch = {name: arguments[0], arrows: '/forces', key: arguments[1]};",
                          f"/sim/b{body}", digit)
    box.send_keys(digit)
    wait_for(lambda: probe.motion_sent is not None, 20, "the handle to move one pixel")
    time.sleep(2.0)  # the moved pose reaches the page and is drawn
    lw = driver.execute_script("return window.__lw")
    driver.execute_script(_FIND_BUTTON, "Let go").click()
    wait_for(lambda: app.session.hand.push_magnitude == 0.0, 10, "the hand to let go")
    if lw["key"] is None or lw["p0"] is None or probe.received is None or probe.response_sent is None:
        raise RuntimeError("the page saw no keydown or no handle pose, or the server no push")
    assert probe.motion_sent is not None
    p0 = np.asarray(lw["p0"])
    moved = next((t for t, kind, pos in lw["msgs"] if kind == "pose" and np.linalg.norm(np.asarray(pos) - p0) >= px),
                 None)
    response = next((t for t, kind, _ in lw["msgs"] if kind == "arrows" and t >= probe.response_sent * 1e3), None)
    if moved is None or response is None:
        raise RuntimeError("the moved pose or the force arrows never reached the page")
    return {"key": lw["key"], "received": probe.received * 1e3,
            "response_sent": probe.response_sent * 1e3, "response_arrived": response,
            "response_shown": shown_after(lw["frames"], response),
            "motion_sent": probe.motion_sent * 1e3, "motion_arrived": moved,
            "motion_shown": shown_after(lw["frames"], moved), "pixel_mm": px * 1e3}


def shown_after(frames: list[list[float]], t: float) -> float:
    """The end of the first animation frame that starts at or after ``t`` (viser applies the messages
    queued by then at the start of a frame, and three.js draws them in it); NaN if none did."""
    return next((end for start, end in frames if start >= t), math.nan)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pushes", type=int_in(1, 100), default=8,
                   help="pushes timed (default 8)")
    p.add_argument("--push-n", type=int_in(1, 9), default=9,
                   help="the push in N (one digit typed into the page's push box; default 9)")
    p.add_argument("--view-fps", type=float_in(1.0, 60.0), default=UiOptions.view_fps,
                   help=f"the laparoscope view's frame rate on the page (default {UiOptions.view_fps:g})")
    args = p.parse_args(argv)
    print(f"load {os.getloadavg()}", flush=True)
    app = UiApp(config.load(), UiOptions(port=0, view_fps=args.view_fps))
    body = mujoco.mj_name2id(app.session.closed.world.model, mujoco.mjtObj.mjOBJ_BODY, WATCHED_BODY)
    probe = Probe(app, body)
    driver = None
    app.start()
    try:
        driver = start_browser(app.url, PRELOAD)
        wait_for(lambda: app.session.time > 1.0, 120, "1 s of simulated time")
        rows = []
        for k in range(args.pushes):
            r = one_push(app, driver, probe, body, str(args.push_n), 0 if k % 2 == 0 else 180)  # to and fro
            rows.append(r)
            key, got = r["key"], r["received"]
            print(f"push {k + 1}: the force drawn {r['response_shown'] - key:6.1f} ms after the key (to the server"
                  f" {got - key:5.1f}, sent {r['response_sent'] - got:5.1f}, in the page"
                  f" {r['response_arrived'] - r['response_sent']:5.1f}, drawn"
                  f" {r['response_shown'] - r['response_arrived']:5.1f}); the handle moved 1 px"
                  f" ({r['pixel_mm']:.2f} mm) {r['motion_shown'] - key:6.1f} ms after"
                  f" (sent {r['motion_sent'] - got:5.1f} after the server had the push)", flush=True)
        ts = driver.execute_script("return window.__lw.ts")
        frame_ms = statistics.median(np.diff(ts)) if len(ts) > 2 else math.nan
        rtf = app.runner.rtf
    finally:
        if driver is not None:
            driver.quit()
        app.stop()

    def med(a: str, b: str) -> float:
        return statistics.median(r[b] - r[a] for r in rows)

    response = [r["response_shown"] - r["key"] for r in rows]
    motion = [r["motion_shown"] - r["key"] for r in rows]
    out = {
        "pushes": len(rows), "push_n": args.push_n,
        "response_median_ms": statistics.median(response), "response_max_ms": max(response),
        "motion_median_ms": statistics.median(motion), "motion_max_ms": max(motion),
        "key_to_server_median_ms": med("key", "received"),
        "server_to_response_sent_median_ms": med("received", "response_sent"),
        "response_sent_to_page_median_ms": med("response_sent", "response_arrived"),
        "response_page_to_drawn_median_ms": med("response_arrived", "response_shown"),
        "server_to_motion_sent_median_ms": med("received", "motion_sent"),
        "browser_frame_median_ms": frame_ms, "page_update_period_ms": 1e3 / PAGE_HZ,
        "response_over_browser_frame_x": statistics.median(response) / frame_ms, "sim_rtf_x": rtf,
        "pixel_mm": statistics.median(r["pixel_mm"] for r in rows), "load_1min": os.getloadavg()[0],
    }
    print(f"push to the scene's response (the hand's force drawn): median {out['response_median_ms']:.1f} ms,"
          f" max {out['response_max_ms']:.1f} ms; to the handle moved one pixel: median {out['motion_median_ms']:.1f}"
          f" ms, max {out['motion_max_ms']:.1f} ms, over {len(rows)} pushes of {args.push_n} N (target <= 100 ms)."
          f" Same run: the page's frame {frame_ms:.1f} ms, page updates every {1e3 / PAGE_HZ:.0f} ms", flush=True)
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in out.items()}))
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        print("bench/ui_latency.py: interrupted; no figures", file=sys.stderr)
        sys.exit(130)
