"""The page in a real browser: headless Chromium (Debian's ``chromium`` and ``chromium-driver``) driven by
selenium opens ``lapwrench ui``'s page, grips and pushes the handle through the page's own controls,
drags the handle gizmo with real pointer actions on the 3D canvas, plays a paper scenario from its
button, and enters a bad parameter.

The gizmo is found where the page's camera shows it: the test points the page's camera (viser's
``client.camera``) at the handle, reads back the pose and field of view the browser reports, and
projects the gizmo's arrow onto the canvas (pinhole, OpenCV axes as viser reports them).

The server runs in this process (:class:`~lapwrench.ui.app.UiApp` on a free port), so the test reads
the simulated scope's ground truth directly. A screenshot of the page is saved as an artifact:
``reports/test-artifacts/ui_page.png`` (and to the path in ``LAPWRENCH_UI_SCREENSHOT`` if set, which
is how ``docs/ui.png`` is refreshed).
"""

from __future__ import annotations

import math
import os
import shutil
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
from selenium.webdriver.common.actions.action_builder import ActionBuilder  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.common.keys import Keys  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402
from selenium.webdriver.remote.webelement import WebElement  # noqa: E402

from lapwrench import config  # noqa: E402
from lapwrench.robot.description import FRAME_H  # noqa: E402
from lapwrench.sim.scripts import TISSUE_DEPTH  # noqa: E402
from lapwrench.ui.app import UiApp, UiOptions  # noqa: E402
from lapwrench.ui.controls import GIZMO_SCALE  # noqa: E402
from lapwrench.ui.inputs import GIZMO_STIFFNESS  # noqa: E402


@pytest.fixture(scope="module")
def app() -> Iterator[UiApp]:
    os.environ.setdefault("MUJOCO_GL", "egl")
    ui = UiApp(config.load(), UiOptions(port=0))
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
        wait_for(lambda: _button(driver, "high") is not None, 60, "the page's controls")
        yield driver
    finally:
        driver.quit()


def wait_for(condition: Callable[[], object], timeout: float, what: str) -> None:
    print(f"{time.strftime('%X')} waiting for {what}", flush=True)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            if condition():
                return
        except Exception:  # the page is still building: try again
            pass
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {what}")


def wait_sim(app: UiApp, seconds: float, timeout: float = 120.0) -> None:
    """Let ``seconds`` of simulated time pass (the simulation may run slower than real time)."""
    t_end = app.session.time + seconds
    wait_for(lambda: app.session.time >= t_end, timeout, f"{seconds} s of simulated time")


# The elements are looked up in one script call each: a software-rendered page answers every
# WebDriver round trip slowly.
_FIND_BUTTON = """
const b = Array.from(document.querySelectorAll('button')).find(b => b.innerText.trim() === arguments[0]);
if (b) b.scrollIntoView({block: 'center'});  // clear of the panel's edges
return b;
"""
_FIND_NUMBER = """
const label = Array.from(document.querySelectorAll('label')).find(x => x.innerText.trim() === arguments[0]);
if (!label) return null;
const row = label.parentElement.parentElement.parentElement;
return row.querySelector('input.mantine-NumberInput-input');
"""


_OPEN_FOLDER = """
const t = document.evaluate(`//*[normalize-space(text())='${arguments[0]}']`, document, null,
                            XPathResult.FIRST_ORDERED_NODE_TYPE, null).singleNodeValue;
t.scrollIntoView({block: 'center'});
t.click();
"""
_SHOWN = "const r = arguments[0].getBoundingClientRect(); return r.width > 0 && r.height > 0;"


def _button(driver: WebDriver, text: str) -> WebElement | None:
    """The button labelled ``text``, scrolled to the middle of its panel (None if there is none)."""
    return driver.execute_script(_FIND_BUTTON, text)


def _number_input(driver: WebDriver, label: str) -> WebElement:
    """The number box of the control labelled ``label`` (a slider's or a number's)."""
    box = driver.execute_script(_FIND_NUMBER, label)
    if box is None:
        raise LookupError(f"no number input labelled {label!r}")
    return box


def _type_number(driver: WebDriver, label: str, value: str) -> None:
    box = _number_input(driver, label)
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'});", box)
    box.click()
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys(value, Keys.TAB)


_CANVAS_RECT = """
document.querySelectorAll('.mantine-Notification-root button').forEach(b => b.click());
let best = null;
for (const c of document.querySelectorAll('canvas')) {
  const r = c.getBoundingClientRect();
  if (!best || r.width * r.height > best.width * best.height) best = r;
}
return [best.left, best.top, best.width, best.height];
"""
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


def _plot_pixels(driver: WebDriver) -> list[str]:
    return driver.execute_script(
        "return Array.from(document.querySelectorAll('.uplot canvas')).map(c => c.toDataURL());")


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
    plots_before = _plot_pixels(browser)
    assert len(plots_before) >= 5, "the page shows the live plots"
    d0 = _shaft(app)
    app.session.reset_stats()
    _button(browser, "high").click()  # type: ignore[union-attr]
    wait_for(lambda: app.session.hand.grip_force > 0, 10, "the grip from the page")
    _type_number(browser, "push (N)", "15")
    wait_for(lambda: app.session.hand.push_magnitude == 15.0, 10, "the push from the page")
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
    wait_for(lambda: _plot_pixels(browser) != plots_before, 20, "the plots to change")
    wait_for(lambda: app.view.frames > 0, 60, "a laparoscope frame")
    _show_instrument_in_view(app)  # for the picture: an instrument the detector finds
    wait_sim(app, 1.0)
    browser.execute_script(  # close the "software WebGL" notice that covers the scene
        "document.querySelectorAll('.mantine-Notification-root button').forEach(b => b.click())")
    ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
    browser.save_screenshot(str(ARTIFACT))
    extra = os.environ.get("LAPWRENCH_UI_SCREENSHOT")
    if extra:
        shutil.copyfile(ARTIFACT, extra)
    print(f"turned {turned:.2f} deg, max physical RCM error {rcm_mm:.3f} mm, {app.stats()}")
    _button(browser, "Let go").click()  # type: ignore[union-attr]
    wait_for(lambda: app.session.hand.push_magnitude == 0.0, 10, "the hand to let go")


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


def test_dragging_the_handle_gizmo_on_the_canvas_pushes_the_handle_and_releasing_ends_it(
    app: UiApp, browser: WebDriver
) -> None:
    _button(browser, "high").click()  # type: ignore[union-attr]
    wait_for(lambda: app.session.hand.grip_force > 0, 10, "the grip from the page")
    camera = _point_camera_at_the_handle(app)
    rect = browser.execute_script(_CANVAS_RECT)  # also closes the notice covering the scene
    before = np.asarray(app.controls.gizmo.position, float)  # on the handle
    grab = _on_canvas(camera, rect, before + np.array([0.6 * GIZMO_SCALE, 0.0, 0.0]))  # on its x arrow
    to = _on_canvas(camera, rect, before + np.array([0.6 * GIZMO_SCALE - DRAG, 0.0, 0.0]))
    print(f"gizmo at {before} m, canvas {rect}, grab at {grab} px, drag to {to} px")
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
    app.session.hand.release()  # clean-up for the next test (the first test clicks "Let go"; each click costs)


def test_the_needle_search_button_plays_the_scenario(app: UiApp, browser: WebDriver) -> None:
    t = app.session.time
    _button(browser, "Reset").click()  # type: ignore[union-attr]  # the scope back where the paper starts
    wait_for(lambda: app.session.time < t and app.session.snapshot is not None, 60, "the reset")
    _button(browser, "Play Fig. 6-7: needle search (26 s)").click()  # type: ignore[union-attr]
    wait_for(lambda: app.session.snapshot.script_name == "needle-search", 20, "the scenario to start")  # type: ignore[union-attr]
    wait_for(lambda: app.session.snapshot.mode == "tracking", 60, "the camera to track its instrument")  # type: ignore[union-attr]
    app.session.stop_script()  # clean-up (stopping is unit-tested; each click on this page costs)


def test_a_bad_parameter_is_shown_on_the_page_and_the_simulation_keeps_running(
    app: UiApp, browser: WebDriver
) -> None:
    browser.execute_script(_OPEN_FOLDER, "Live parameters")
    wait_for(lambda: browser.execute_script(_SHOWN, _number_input(browser, "ε2 (px)")), 30, "the parameter inputs")
    eps2 = app.session.cfg.tracking.epsilon2
    _type_number(browser, "ε2 (px)", "10")  # below ε1 = 50: the configuration refuses it
    _button(browser, "Apply parameters").click()  # type: ignore[union-attr]
    wait_for(lambda: "Parameter error" in browser.find_element(By.TAG_NAME, "body").text, 20, "the error on the page")
    body = browser.find_element(By.TAG_NAME, "body").text
    assert "epsilon2" in body
    t0 = app.session.time
    wait_sim(app, 0.5, timeout=30)
    assert app.session.time > t0
    assert app.session.cfg.tracking.epsilon2 == eps2
    assert app.runner.error is None
