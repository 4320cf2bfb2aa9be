"""The page in a real browser: headless Chromium (Debian's ``chromium`` and ``chromium-driver``) driven by
selenium opens ``lapwrench ui``'s page, grips and pushes the handle through the page's own controls,
drags the handle gizmo with real pointer actions on the 3D canvas, plays a paper scenario from its
button, and enters a bad parameter.

The gizmo is found where the page's camera shows it: the test points the page's camera (viser's
``client.camera``) at the handle, reads back the pose and field of view the browser reports, and
projects the gizmo's arrow onto the canvas (pinhole, OpenCV axes as viser reports them).

The server runs in this process (:class:`~lapwrench.ui.app.UiApp` on a free port), so the test reads
the simulated scope's ground truth directly.

A software-rendered page answers each WebDriver round trip slowly (seconds while it is busy), so the
tests make few: each step's lookups and clicks go in one script call, and what the server knows is
read from the server. The laparoscope view streams at :data:`VIEW_FPS` (no test looks at its frame
rate, and its frames are rendered on the cores the browser needs).

A screenshot of the page is saved as an artifact: ``reports/test-artifacts/ui_page.png`` (and to the
path in ``LAPWRENCH_UI_SCREENSHOT`` if set, which is how ``docs/ui.png`` is refreshed).
"""

from __future__ import annotations

import math
import os
import shutil
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytestmark = pytest.mark.slow

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
ARTIFACT = Path(__file__).resolve().parents[2] / "reports" / "test-artifacts" / "ui_page.png"
VIEW_FPS = 2.0  # laparoscope frames per second on the page: enough for the screenshot


def _missing() -> str | None:
    if CHROMIUM is None or CHROMEDRIVER is None:
        return "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
    for module in ("selenium", "viser"):
        try:
            __import__(module)
        except ImportError:
            return f"needs the {module} package"
    return None


if (_reason := _missing()) is not None:
    pytest.skip(_reason, allow_module_level=True)

import viser.transforms as tf  # noqa: E402
from selenium import webdriver  # noqa: E402 - after the skip
from selenium.webdriver.chrome.options import Options  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.actions.action_builder import ActionBuilder  # noqa: E402
from selenium.webdriver.common.keys import Keys  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402

from lapwrench import config  # noqa: E402
from lapwrench.robot.description import FRAME_H  # noqa: E402
from lapwrench.sim.scripts import TISSUE_DEPTH  # noqa: E402
from lapwrench.ui.app import UiApp, UiOptions  # noqa: E402
from lapwrench.ui.controls import GIZMO_SCALE  # noqa: E402
from lapwrench.ui.inputs import GIZMO_STIFFNESS  # noqa: E402


@pytest.fixture(scope="module")
def app() -> Iterator[UiApp]:
    os.environ.setdefault("MUJOCO_GL", "egl")
    ui = UiApp(config.load(), UiOptions(port=0, view_fps=VIEW_FPS))
    ui.start()
    try:
        yield ui
    finally:
        ui.stop()


@pytest.fixture(scope="module")
def browser(app: UiApp) -> Iterator[WebDriver]:
    opts = Options()
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1280,900"):
        opts.add_argument(arg)
    opts.binary_location = CHROMIUM
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.set_page_load_timeout(60)
    driver.set_script_timeout(120)  # a software-rendered page under load answers slowly
    try:
        driver.get(app.url)
        wait_for(lambda: _page(driver, "return findButton('high') !== null;"), 60, "the page's controls")
        yield driver
    finally:
        driver.quit()


@pytest.fixture(autouse=True)
def hand_off(app: UiApp) -> Iterator[None]:
    """Each test leaves the hand off the handle, also when it fails (a grip left on would keep the next
    test's camera from tracking); from the server: each round trip to the page costs."""
    yield
    app.session.hand.release()
    app.controls.magnitude.value = 0.0


def wait_for(condition: Callable[[], object], timeout: float, what: str, every: float = 0.05) -> None:
    """Poll ``condition`` every ``every`` s until it holds (a condition that asks the browser is a
    round trip of its own: give it a longer ``every``)."""
    print(f"{time.strftime('%X')} waiting for {what}", flush=True)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            if condition():
                return
        except Exception:  # the page is still building: try again
            pass
        time.sleep(every)
    raise AssertionError(f"timed out waiting for {what}")


def wait_sim(app: UiApp, seconds: float, timeout: float = 120.0) -> None:
    """Let ``seconds`` of simulated time pass (the simulation may run slower than real time)."""
    t_end = app.session.time + seconds
    wait_for(lambda: app.session.time >= t_end, timeout, f"{seconds} s of simulated time")


# The page's own controls, from scripts run in the page: each call of _page is one round trip. A button
# is clicked by its own click event (React's handler sends it to the server, as a pointer's click does);
# numbers are typed with real key presses and the gizmo is dragged with real pointer input.
_PAGE_JS = """
function closeNotices() {  // the "software WebGL" notice covers the scene
  document.querySelectorAll('.mantine-Notification-root button').forEach(b => b.click());
}
function findButton(text) {
  return Array.from(document.querySelectorAll('button')).find(b => b.innerText.trim() === text) || null;
}
function clickButtons(texts) {
  const found = texts.map(findButton);
  if (found.includes(null)) throw new Error('no button ' + texts[found.indexOf(null)]);
  for (const b of found) { b.scrollIntoView({block: 'center'}); b.click(); }
  closeNotices();
}
function focusNumber(label) {  // the number box of a slider or a number, its text selected; false if not shown
  const l = Array.from(document.querySelectorAll('label')).find(x => x.innerText.trim() === label);
  const box = l && l.parentElement.parentElement.parentElement.querySelector('input.mantine-NumberInput-input');
  if (!box) return false;
  box.scrollIntoView({block: 'center'});
  const r = box.getBoundingClientRect();
  if (!(r.width > 0 && r.height > 0)) return false;  // in a folder still opening
  box.focus();
  box.select();
  return document.activeElement === box;
}
function openFolder(title) {
  const t = document.evaluate(`//*[normalize-space(text())='${title}']`, document, null,
                              XPathResult.FIRST_ORDERED_NODE_TYPE, null).singleNodeValue;
  t.scrollIntoView({block: 'center'});
  t.click();
}
function plotPixels() {
  return Array.from(document.querySelectorAll('.uplot canvas')).map(c => c.toDataURL());
}
function canvasRect() {  // the 3D scene's canvas (the largest), CSS px
  let best = null;
  for (const c of document.querySelectorAll('canvas')) {
    const r = c.getBoundingClientRect();
    if (!best || r.width * r.height > best.width * best.height) best = r;
  }
  return [best.left, best.top, best.width, best.height];
}
"""


def _page(driver: WebDriver, code: str, *args: object) -> Any:
    """Run ``code`` in the page with the functions of :data:`_PAGE_JS` (one round trip)."""
    return driver.execute_script(_PAGE_JS + code, *args)


def _type_keys(driver: WebDriver, value: str) -> None:
    """Type ``value`` into the focused box with real key presses, then leave it (Tab), which sends it."""
    ActionChains(driver).send_keys(value, Keys.TAB).perform()


DRAG = 0.05  # m, how far the test drags the gizmo (15 N at 300 N/m)


def _point_camera_at_the_handle(app: UiApp) -> Any:
    """Point the page's camera at the handle from 45 cm in front (-y) and return the camera."""
    clients = app.server.get_clients()
    assert len(clients) == 1, "one browser on the page"
    camera = next(iter(clients.values())).camera
    snap = app.session.snapshot
    assert snap is not None
    eye, target = snap.hand_point + np.array([0.0, -0.45, 0.12]), snap.hand_point + np.array([0.1, 0.0, 0.0])
    camera.position = eye  # position first: it moves look_at along
    camera.look_at = target
    wait_for(lambda: np.allclose(camera.position, eye, atol=1e-4) and np.allclose(camera.look_at, target, atol=1e-4),
             30, "the page's camera")
    return camera


def _on_canvas(camera: Any, rect: list[float], x: np.ndarray) -> tuple[int, int]:
    """Where world point ``x`` (m, {B}) shows on the page (CSS px): viser's camera pose is
    P_world = R p_camera + t with +z forward and +y down; ``fov`` is vertical."""
    R = tf.SO3(np.asarray(camera.wxyz)).as_matrix()
    p = R.T @ (np.asarray(x, float) - np.asarray(camera.position))
    assert p[2] > 0, "the point is in front of the camera"
    tan_half = math.tan(camera.fov / 2.0)
    left, top, width, height = rect
    u = p[0] / p[2] / (tan_half * width / height)
    v = p[1] / p[2] / tan_half
    return round(left + (1.0 + u) / 2.0 * width), round(top + (1.0 + v) / 2.0 * height)


def _show_instrument_in_view(app: UiApp) -> None:
    """The left instrument's tip 1 cm beside where the scope's axis meets the tissue."""
    with app.session.lock:
        world = app.session.closed.world
        p_E, d = world.shaft_axis()
        base = world.incision_rest_position() + np.array([0.0, 0.0, -TISSUE_DEPTH])
    hit = p_E + (base[2] - p_E[2]) / d[2] * d
    app.session.set_instrument(0, True, hit[0] - base[0] + 0.01, hit[1] - base[1])


def _shaft(app: UiApp) -> np.ndarray:
    with app.session.lock:
        return app.session.closed.world.shaft_axis()[1]


def _turned_deg(d0: np.ndarray, d1: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(d0 @ d1, -1.0, 1.0))))


def test_grip_and_push_from_the_page_turn_the_scope_about_the_incision(app: UiApp, browser: WebDriver) -> None:
    wait_sim(app, 0.5)
    d0 = _shaft(app)
    app.session.reset_stats()
    # one round trip: the grip pressed, the push's box focused for the keys, the plots as they are
    focused, plots_before = _page(browser, "clickButtons(['high']); return [focusNumber('push (N)'), plotPixels()];")
    assert focused, "the push's number box"
    assert len(plots_before) >= 5, "the page shows the live plots"
    _type_keys(browser, "15")
    wait_for(lambda: app.session.hand.grip_force > 0 and app.session.hand.push_magnitude == 15.0, 10,
             "the grip and the push from the page")
    t_push = app.session.time
    wait_for(lambda: _turned_deg(d0, _shaft(app)) > 2.5 or app.session.time > t_push + 3.0, 120,
             "the scope to turn (at most 3 s of simulated time)")
    d1 = _shaft(app)
    turned = _turned_deg(d0, d1)
    rcm_mm = app.session.max_rcm_error * 1e3
    snap = app.session.snapshot
    assert snap is not None and snap.held is None, f"no hold: {snap and snap.held}"
    assert turned > 2.0, f"the scope turned only {turned:.2f} deg"
    assert rcm_mm <= 2.0, f"physical RCM error reached {rcm_mm:.2f} mm"
    assert app.session.history.names(), "the plots have signals"
    wait_for(lambda: _page(browser, "return plotPixels();") != plots_before, 20, "the plots to change", every=0.5)
    wait_for(lambda: app.view.frames > 0, 60, "a laparoscope frame")
    _show_instrument_in_view(app)  # for the picture: an instrument the detector finds
    wait_sim(app, 1.0)
    ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
    browser.save_screenshot(str(ARTIFACT))
    extra = os.environ.get("LAPWRENCH_UI_SCREENSHOT")
    if extra:
        shutil.copyfile(ARTIFACT, extra)
    print(f"turned {turned:.2f} deg, max physical RCM error {rcm_mm:.3f} mm, {app.stats()}")
    _page(browser, "clickButtons(['Let go']);")
    wait_for(lambda: app.session.hand.push_magnitude == 0.0 and app.session.hand.grip_force == 0.0, 10,
             "the hand to let go")


def _drag(browser: WebDriver, grab: tuple[int, int], to: tuple[int, int], steps: int = 5) -> None:
    """Press the left button at ``grab`` (CSS px) and move to ``to`` in ``steps`` pointer moves, as a
    hand would; the button stays down."""
    actions = ActionBuilder(browser, duration=50)
    actions.pointer_action.move_to_location(*grab).pause(0.2).pointer_down().pause(0.2)
    for k in range(1, steps + 1):
        actions.pointer_action.move_to_location(round(grab[0] + (to[0] - grab[0]) * k / steps),
                                                round(grab[1] + (to[1] - grab[1]) * k / steps)).pause(0.05)
    actions.perform()


def _release(browser: WebDriver) -> None:
    actions = ActionBuilder(browser)
    actions.pointer_action.pointer_up()
    actions.perform()


def _rcm_state(app: UiApp) -> tuple[float, float]:
    """The physical RCM error (mm) and the trocar's load across the shaft (N) now."""
    with app.session.lock:
        closed = app.session.closed
        f, d = closed.world.contact_force(), closed.world.shaft_axis()[1]
        return closed.physical_rcm_error() * 1e3, float(np.linalg.norm(f - (f @ d) * d))


def test_dragging_the_handle_gizmo_on_the_canvas_pushes_the_handle_and_releasing_ends_it(
    app: UiApp, browser: WebDriver
) -> None:
    # From where the paper starts (the page's Reset), not from wherever the test before left the scope: a
    # long push tilts it by tens of degrees, where it rests with a trocar load below the adaptive RCM's
    # dead zone (adaptive_rcm.gamma1) and so with about a millimetre of RCM error before any drag.
    t = app.session.time
    rect = _page(browser, "clickButtons(['Reset', 'high']); return canvasRect();")  # the hand is kept over a reset
    wait_for(lambda: app.session.time < t and app.session.snapshot is not None, 60, "the reset")
    wait_for(lambda: app.session.hand.grip_force > 0, 10, "the grip from the page")
    wait_for(lambda: np.allclose(app.controls.gizmo.position, app.session.snapshot.hand_point, atol=2e-4),  # type: ignore[union-attr]
             10, "the gizmo on the handle")
    camera = _point_camera_at_the_handle(app)
    before = np.asarray(app.controls.gizmo.position, float)  # on the handle
    grab = _on_canvas(camera, rect, before + np.array([0.6 * GIZMO_SCALE, 0.0, 0.0]))  # on its x arrow
    to = _on_canvas(camera, rect, before + np.array([0.6 * GIZMO_SCALE - DRAG, 0.0, 0.0]))
    rest_mm, rest_n = _rcm_state(app)
    print(f"gizmo at {before} m, canvas {rect}, grab at {grab} px, drag to {to} px; before the drag: physical"
          f" RCM error {rest_mm:.3f} mm, trocar load across the shaft {rest_n:.2f} N")
    d0 = _shaft(app)
    app.session.reset_stats()
    try:
        _drag(browser, grab, to)
        wait_for(lambda: np.linalg.norm(app.session.hand.gizmo) > 1.0, 30, "the gizmo's pull")
        t_drag = app.session.time
        wait_sim(app, 2.0)
        with app.session.lock:
            dragged = np.asarray(app.controls.gizmo.position, float) - before
            hand_point = app.session.closed.world.frame_pose(FRAME_H)[0]
            pull, still_dragging = app.session.hand.gizmo.copy(), app.controls.dragging
            spring = np.asarray(app.controls.gizmo.position, float) - hand_point
            held_s = app.session.time - t_drag
        snap = app.session.snapshot
    finally:
        _release(browser)
    wait_for(lambda: not app.controls.dragging and not np.any(app.session.hand.gizmo), 30, "the gizmo's release")
    wait_sim(app, 0.1)
    after = app.session.snapshot
    t, values = app.session.history.window(["|F| interaction"])
    w_h = values["|F| interaction"][t > t_drag]
    turned = _turned_deg(d0, _shaft(app))
    rcm_mm = app.session.max_rcm_error * 1e3
    print(f"dragged {dragged} m, pull {pull} N after {held_s:.2f} s, |W_h| max {w_h.max():.2f} N,"
          f" turned {turned:.2f} deg, max physical RCM error {rcm_mm:.3f} mm")
    assert still_dragging
    assert dragged[0] == pytest.approx(-DRAG, rel=0.3) and np.all(np.abs(dragged[1:]) < 0.005), dragged
    # a spring between the handle and the gizmo: the handle follows the pull, which then eases off
    assert pull == pytest.approx(GIZMO_STIFFNESS * spring, abs=1.5)
    assert snap is not None and np.linalg.norm(snap.hand_force) > 1.0
    assert w_h.max() > 1.0, "the interaction wrench answered the pull"
    assert turned > 1.0, f"the scope turned only {turned:.2f} deg"
    assert rcm_mm <= 2.0 and snap.held is None
    assert after is not None and np.linalg.norm(after.hand_force) == 0.0, "releasing ends the push"


def test_the_needle_search_button_plays_the_scenario(app: UiApp, browser: WebDriver) -> None:
    t = app.session.time
    _page(browser, "clickButtons(['Reset']);")  # the scope back where the paper starts
    wait_for(lambda: app.session.time < t and app.session.snapshot is not None, 60, "the reset")
    _page(browser, "clickButtons(['Play Fig. 6-7: needle search (26 s)']);")
    wait_for(lambda: app.session.snapshot.script_name == "needle-search", 20, "the scenario to start")  # type: ignore[union-attr]
    wait_for(lambda: app.session.snapshot.mode == "tracking", 60, "the camera to track its instrument")  # type: ignore[union-attr]
    app.session.stop_script()  # clean-up (stopping is unit-tested; each click on this page costs)


def test_a_bad_parameter_is_shown_on_the_page_and_the_simulation_keeps_running(
    app: UiApp, browser: WebDriver
) -> None:
    eps2 = app.session.cfg.tracking.epsilon2
    _page(browser, "openFolder('Live parameters');")
    wait_for(lambda: _page(browser, "return focusNumber('ε2 (px)');"), 30, "the parameter inputs", every=0.5)
    _type_keys(browser, "10")  # below ε1 = 50: the configuration refuses it
    _page(browser, "clickButtons(['Apply parameters']);")
    body = ""

    def shown() -> bool:
        nonlocal body
        body = _page(browser, "return document.body.innerText;")
        return "Parameter error" in body

    wait_for(shown, 20, "the error on the page", every=0.5)
    assert "epsilon2" in body
    t0 = app.session.time
    wait_sim(app, 0.5, timeout=30)
    assert app.session.time > t0
    assert app.session.cfg.tracking.epsilon2 == eps2
    assert app.runner.error is None


def test_a_failed_start_stops_the_server_and_takes_its_client_guard_off(monkeypatch: pytest.MonkeyPatch) -> None:
    """A page that fails while its panels are built (after the server and the session started) leaves no
    server running and no filter on websockets' logger (they outlived the failed start before)."""
    import logging

    from lapwrench.ui import app as app_module

    def broken(*args: Any, **kwargs: Any) -> None:
        raise RuntimeError("broken panel")

    monkeypatch.setattr(app_module, "LivePlots", broken)
    guards_before = list(logging.getLogger("websockets.server").filters)
    started: list[Any] = []
    real_init = app_module.PageServer.__init__

    def recording_init(self: Any, *args: Any, **kwargs: Any) -> None:
        real_init(self, *args, **kwargs)
        started.append(self)

    monkeypatch.setattr(app_module.PageServer, "__init__", recording_init)
    with pytest.raises(RuntimeError, match="broken panel"):
        UiApp(config.load(), UiOptions(port=0, view_fps=VIEW_FPS))
    assert logging.getLogger("websockets.server").filters == guards_before
    port = int(started[0].get_port())
    with socket.socket() as s:  # the port is free again: the server stopped
        s.bind(("127.0.0.1", port))
