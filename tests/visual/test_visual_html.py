"""The HTML view in a real headless Chromium (Debian's chromium and chromium-driver): it opens with no console
errors, the masses are drawn where plotly's own camera puts them, the time slider changes the picture, and
hovering a link shows its number and tension."""
from __future__ import annotations

import io
import shutil
import time

import numpy as np
import pytest
from PIL import Image

from linknet_core import visual

webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (pip install -e '.[test]')")

CHROMIUM, CHROMEDRIVER = shutil.which("chromium"), shutil.which("chromedriver")
WINDOW = (1000, 800)
DARK = 100  # a mass marker (#262626, anchors black) is darker than any link colour, grid line or background

# Where plotly draws a data point: its own projection of 3-D annotations (src/plots/gl3d/project.js and
# annotations3d's convert), data scaled by the scene's dataScale, through model, view and projection matrices,
# into the scene's domain of the plot area. Returns viewport pixels.
PROJECT = """
const gd = document.querySelector('.js-plotly-plot');
const layout = gd._fullLayout, scene = layout.scene._scene, camera = scene.glplot.cameraParams;
const size = layout._size, domain = layout.scene.domain, box = gd.getBoundingClientRect();
const scale = scene.dataScale;
function xform(m, v) {
  const out = [0, 0, 0, 0];
  for (let i = 0; i < 4; ++i) for (let j = 0; j < 4; ++j) out[j] += m[4 * i + j] * v[i];
  return out;
}
return arguments[0].map(p => {
  const v = xform(camera.projection, xform(camera.view, xform(camera.model,
                  [p[0] * scale[0], p[1] * scale[1], p[2] * scale[2], 1])));
  const width = size.w * (domain.x[1] - domain.x[0]), height = size.h * (domain.y[1] - domain.y[0]);
  return [box.left + size.l + domain.x[0] * size.w + 0.5 * (1 + v[0] / v[3]) * width,
          box.top + size.t + (1 - domain.y[1]) * size.h + 0.5 * (1 - v[1] / v[3]) * height];
});
"""

READY = """
const gd = document.querySelector('.js-plotly-plot');
return !!(gd && gd._fullLayout && gd._fullLayout.scene && gd._fullLayout.scene._scene
          && gd._fullLayout.scene._scene.glplot && gd._transitionData && gd._transitionData._frames.length);
"""

NEXT_PAINTS = """
const done = arguments[arguments.length - 1];
requestAnimationFrame(() => requestAnimationFrame(() => requestAnimationFrame(() => done(true))));
"""


@pytest.fixture(scope="module")
def browser():
    if not (CHROMIUM and CHROMEDRIVER):
        pytest.skip("Chromium and its driver are not installed (Debian: apt-get install chromium chromium-driver)")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    # WebGL in a headless browser with no GPU: SwiftShader, Chromium's software renderer
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", f"--window-size={WINDOW[0]},{WINDOW[1]}",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--force-device-scale-factor=1"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    yield driver
    driver.quit()


def open_view(driver, path):
    driver.get_log("browser")  # forget what earlier pages said
    driver.get(path.resolve().as_uri())
    deadline = time.monotonic() + 60
    while not driver.execute_script(READY):
        assert time.monotonic() < deadline, "the plot never finished loading"
        time.sleep(0.05)
    settle(driver)


def settle(driver):
    driver.set_script_timeout(30)
    driver.execute_async_script(NEXT_PAINTS)


def screenshot(driver) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(driver.get_screenshot_as_png())).convert("RGB")).astype(int)


def darkest_near(image, pixel, radius=2) -> int:
    """Max channel of the darkest pixel within radius of a viewport pixel (0 black, 255 white)."""
    column, row = int(round(pixel[0])), int(round(pixel[1]))
    patch = image[row - radius:row + radius + 1, column - radius:column + radius + 1]
    return int(patch.max(axis=2).min())


def severe_console_messages(driver) -> list[str]:
    return [entry["message"] for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]


def mouse(driver, kind, pixel):
    driver.execute_cdp_cmd("Input.dispatchMouseEvent", {"type": kind, "x": float(pixel[0]), "y": float(pixel[1]),
                                                       "button": "left", "clickCount": 1})


@pytest.fixture(scope="module")
def net_view(net_npz, tmp_path_factory):
    motion = visual.Motion.from_npz(net_npz)
    path = tmp_path_factory.mktemp("html") / "net.html"
    visual.write_html(motion, path, max_frames=6)
    _, frames = visual.build_html_figure(motion, max_frames=6)
    return path, motion, frames


@pytest.fixture(scope="module")
def chain_view(chain_npz, tmp_path_factory):
    motion = visual.Motion.from_npz(chain_npz)
    path = tmp_path_factory.mktemp("html") / "chain.html"
    visual.write_html(motion, path, max_frames=6)
    _, frames = visual.build_html_figure(motion, max_frames=6)
    return path, motion, frames


@pytest.mark.parametrize("view", ["net_view", "chain_view"])
def test_opens_without_console_errors_and_draws_every_mass(browser, view, request):
    path, motion, frames = request.getfixturevalue(view)
    open_view(browser, path)
    assert severe_console_messages(browser) == []
    image = screenshot(browser)
    masses = browser.execute_script(PROJECT, motion.X[frames[0]].tolist())
    for k, pixel in enumerate(masses):
        assert darkest_near(image, pixel) < DARK, f"mass {k + 1} is not drawn at {pixel}"
    dark = (image.max(axis=2) < DARK).mean()
    assert 0 < dark < 0.05, "the page is not a network on a light background"


def test_time_slider_changes_the_picture_and_hover_shows_a_links_tension(browser, net_view):
    path, motion, frames = net_view
    open_view(browser, path)
    before = screenshot(browser)
    rail = browser.execute_script("""
        const r = document.querySelector('.slider-rail-touch-rect').getBoundingClientRect();
        return [r.left, r.top, r.width, r.height];""")
    end_of_rail = (rail[0] + rail[2] - 3, rail[1] + rail[3] / 2)
    mouse(browser, "mousePressed", end_of_rail)
    mouse(browser, "mouseReleased", end_of_rail)
    last = frames[-1]
    deadline = time.monotonic() + 30
    while browser.execute_script("return document.querySelector('.js-plotly-plot')._fullLayout.sliders[0].active")\
            != len(frames) - 1:
        assert time.monotonic() < deadline, "the slider did not move to its last step"
        time.sleep(0.05)
    settle(browser)
    after = screenshot(browser)
    label = browser.execute_script("""return Array.from(document.querySelectorAll('.slider-container text'))
        .map(e => e.textContent).find(text => text.startsWith('t = '))""")  # the slider's current value
    assert label == f"t = {visual._time_format(motion.t[frames]).format(motion.t[last])} s"
    assert (np.abs(after - before).max(axis=2) > 60).sum() > 200, "the picture did not change"
    now = browser.execute_script(PROJECT, motion.X[last].tolist())
    then = browser.execute_script(PROJECT, motion.X[frames[0]].tolist())
    for k, pixel in enumerate(now):
        assert darkest_near(after, pixel) < DARK, f"mass {k + 1} is not drawn at its new place {pixel}"
    moved_away = [p for p in then if min(np.hypot(*np.subtract(p, q)) for q in now) > 20]
    assert moved_away and all(darkest_near(after, p) >= DARK for p in moved_away), "masses left behind"
    assert severe_console_messages(browser) == []

    # hover the link whose midpoint lies farthest from every mass on the screen
    middles = browser.execute_script(PROJECT, (0.5 * (motion.X[last, motion.k1] + motion.X[last, motion.k2])).tolist())
    clearance = [min(np.hypot(*np.subtract(m, q)) for q in now) for m in middles]
    link = int(np.argmax(clearance))
    mouse(browser, "mouseMoved", middles[link])
    deadline = time.monotonic() + 30
    text = ""
    while "link" not in text:
        assert time.monotonic() < deadline, "no hover label on the link"
        settle(browser)
        text = browser.execute_script("const h = document.querySelector('.hovertext'); return h ? h.textContent : ''")
    expected = f"link {link + 1} (masses {motion.k1[link] + 1}-{motion.k2[link] + 1})T = "
    assert text.startswith(expected), text
    shown = float(text[len(expected):].split()[0].replace("\u2212", "-"))
    assert shown == pytest.approx(motion.T[last, link], rel=1e-4, abs=1e-6)
