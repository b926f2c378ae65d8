"""The tour viewer in headless Chromium (Selenium with the system chromedriver).

Opens index.html from file://, clicks a viewpoint on the overview, checks that the shown frame
changed and loaded, and that the page logged no errors; saves a screenshot (into
``$SCENEBOT_SCREENSHOT_DIR`` when set, else the test's temporary folder).

Needs Debian's ``chromium`` and ``chromium-driver`` packages and the ``selenium`` package;
skipped with the reason when one is missing.
"""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import pytest

from tests.fixtures.browser import chromium, needs_browser

pytestmark = [pytest.mark.slow, needs_browser]


@pytest.fixture(scope="module")
def tour_dir(tmp_path_factory):
    from scenebot.tour.config import TourConfig
    from scenebot.tour.stage import TourInputs, TourOutputs, run
    from tests.fixtures.tour import make_tour_dataset

    root = tmp_path_factory.mktemp("tour_browser")
    ds = make_tour_dataset(root / "capture", width=128, height=96, per_stop=10)
    cfg = TourConfig.model_validate(
        {
            "width": 160,
            "height": 120,
            "taichi_arch": "cpu",
            "eval_holdout": 0,
            "path": {"frames": 30},
            "viewer": {"viewpoints": 6},
        }
    )
    run(cfg, TourInputs(ds.sparse_dir, ds.root, ds.dense_ply), TourOutputs(root / "tour"), False)
    return root / "tour"


@pytest.fixture(scope="module")
def driver():
    yield from chromium(1280, 800)


def _shown_frame(driver) -> tuple[str, str, int]:
    return driver.execute_script(
        "const f = document.getElementById('frame');"
        "return [f.getAttribute('data-frame'), f.getAttribute('src'),"
        " f.complete ? f.naturalWidth : 0];"
    )


def test_viewer_click_jumps_to_viewpoint(driver, tour_dir, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get((tour_dir / "index.html").resolve().as_uri() + "?autoplay=0")
    WebDriverWait(driver, 20).until(lambda d: _shown_frame(d)[2] > 0)
    before = _shown_frame(driver)
    assert before[0] == "0"
    dots = driver.find_elements(By.CSS_SELECTOR, "#map-overlay circle.viewpoint")
    assert len(dots) >= 3
    target = dots[3]
    frame = target.get_attribute("data-frame")
    assert frame != "0"
    target.click()
    WebDriverWait(driver, 20).until(lambda d: _shown_frame(d)[0] == frame)
    WebDriverWait(driver, 20).until(lambda d: _shown_frame(d)[2] > 0)
    after = _shown_frame(driver)
    assert after[1] != before[1]  # another image is shown
    assert after[2] == 160  # and it loaded (width of the tour frames)
    assert "active" in target.get_attribute("class")
    shot_dir = Path(os.environ.get("SCENEBOT_SCREENSHOT_DIR", tmp_path))
    shot_dir.mkdir(parents=True, exist_ok=True)
    assert driver.save_screenshot(str(shot_dir / "tour_viewer.png"))
    errors = [e for e in driver.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert not errors, errors


def test_viewer_plays(driver, tour_dir):
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get((tour_dir / "index.html").resolve().as_uri())
    WebDriverWait(driver, 20).until(lambda d: int(_shown_frame(d)[0] or 0) >= 3)
    errors = [e for e in driver.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert not errors, errors
