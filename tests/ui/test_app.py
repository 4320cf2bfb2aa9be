"""The page in a real browser: headless Chromium (Debian's ``chromium`` and ``chromium-driver``) driven by
selenium opens ``lapwrench ui``'s page, grips and pushes the handle through the page's own controls,
and enters a bad parameter.

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

from selenium import webdriver  # noqa: E402 - after the skip
from selenium.webdriver.chrome.options import Options  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.common.keys import Keys  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402
from selenium.webdriver.remote.webelement import WebElement  # noqa: E402

from lapwrench import config  # noqa: E402
from lapwrench.sim.scenarios import TISSUE_DEPTH  # noqa: E402
from lapwrench.ui.app import UiApp, UiOptions  # noqa: E402


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
_FIND_BUTTON = "return Array.from(document.querySelectorAll('button')).find(b => b.innerText.trim() === arguments[0])"
_FIND_NUMBER = """
const label = Array.from(document.querySelectorAll('label')).find(x => x.innerText.trim() === arguments[0]);
if (!label) return null;
const row = label.parentElement.parentElement.parentElement;
return row.querySelector('input.mantine-NumberInput-input');
"""


def _button(driver: WebDriver, text: str) -> WebElement | None:
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
    wait_sim(app, 3.0)
    d1 = _shaft(app)
    turned = math.degrees(math.acos(float(np.clip(d0 @ d1, -1.0, 1.0))))
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


def test_a_bad_parameter_is_shown_on_the_page_and_the_simulation_keeps_running(
    app: UiApp, browser: WebDriver
) -> None:
    folder = browser.find_element(By.XPATH, "//*[normalize-space(text())='Live parameters']")
    browser.execute_script("arguments[0].scrollIntoView({block: 'center'});", folder)
    folder.click()
    wait_for(lambda: _number_input(browser, "ε2 (px)").is_displayed(), 10, "the parameter inputs")
    eps2 = app.session.cfg.tracking.epsilon2
    _type_number(browser, "ε2 (px)", "10")  # below ε1 = 50: the configuration refuses it
    apply = _button(browser, "Apply parameters")
    assert apply is not None
    browser.execute_script("arguments[0].scrollIntoView({block: 'center'});", apply)
    apply.click()
    wait_for(lambda: "Parameter error" in browser.find_element(By.TAG_NAME, "body").text, 20, "the error on the page")
    body = browser.find_element(By.TAG_NAME, "body").text
    assert "epsilon2" in body
    t0 = app.session.time
    wait_sim(app, 0.5, timeout=30)
    assert app.session.time > t0
    assert app.session.cfg.tracking.epsilon2 == eps2
    assert app.runner.error is None
