"""The guide page of a real small round: the canned photo set as a person's photo folder
(``robot: photos``) through the workflow, its ``round_000/guide/index.html`` (the photo-folder
campaign of tests/fixtures/workflow.py, run once per test session; its round 0 copied here,
where the upload writes); then the page in
headless Chromium (Selenium with the system chromedriver, as tests/test_tour_browser.py):
clicking a shot highlights it on the map, and an upload through ``guide serve`` lands in the
inbox, with no console errors. Screenshots go to ``$SCENEBOT_SCREENSHOT_DIR`` when set, else
the test's temporary folder.
"""

from __future__ import annotations

import json
import os
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest

from tests.fixtures.browser import chromium, needs_browser
from tests.fixtures.workflow import CANNED, shared_photo_campaign, why
from tests.fixtures.workflow import GUIDE_SHOTS as K
from tests.test_guide_page import data_uri_image, page_json, shot_cards

pytestmark = [
    pytest.mark.slow,  # the photo-folder campaign of 45 small photos (shared, ~3 min)
    pytest.mark.skipif(not (CANNED / "log.jsonl").exists(), reason="canned photo set missing"),
]


@pytest.fixture(scope="module")
def guided_round(tmp_path_factory):
    """The workdir, its round_000 and the photo folder (with its files' bytes): the
    photo-folder campaign's (sfm on one thread: on all threads it is not repeatable, and one
    of its maps of these photos put a camera kilometres off, which left the person's 3-D free
    space degenerate), its round 0 copied into a folder of this module's own."""
    campaign = shared_photo_campaign(tmp_path_factory)
    assert campaign.final.returncode == 0, why(campaign.final, campaign.workdir)
    workdir = tmp_path_factory.mktemp("guide")
    rnd = workdir / "results" / "office" / "round_000"
    shutil.copytree(campaign.workdir / "results" / "office" / "round_000", rnd)
    return workdir, rnd, campaign.folder, campaign.before


def test_the_page_shows_the_rounds_shots(guided_round):
    from scenebot.artifacts.previews import read_previews

    _, rnd, folder, before = guided_round
    text = (rnd / "guide" / "index.html").read_text(encoding="utf-8")
    data = page_json(text)
    goals = json.loads((rnd / "goals.json").read_text())
    previews = read_previews(rnd / "goals_preview.npz")
    assert 1 <= len(goals["goals"]) <= K
    assert len(data["shots"]) == len(goals["goals"]) == len(previews.ranks)
    assert data["complete"] == goals["complete"] and data["round"] == "round_000"
    cards = shot_cards(text)
    names = {p.name for p in folder.iterdir()}
    for k, (g, shot) in enumerate(zip(goals["goals"], data["shots"], strict=True)):
        for key in ("rank", "x", "y", "z", "theta", "pitch", "score_deg"):
            assert shot[key] == g[key], (k, key)
        assert shot["from_photo"] in names  # a photo of the folder
        card = cards[g["rank"]]
        preview = data_uri_image(card.split('class="preview" src="', 1)[1].split('"', 1)[0])
        assert np.array_equal(preview, previews.images[k])
        assert f"{g['score_deg']:.1f}°" in card
    assert data["inbox"] == "results/office/round_001/capture/inbox/"
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # photos untouched


@pytest.fixture(scope="module")
def driver():
    yield from chromium(1280, 900)


def _errors(driver) -> list[dict]:
    return [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def _screenshot(driver, tmp_path, name: str) -> Path:
    folder = Path(os.environ.get("SCENEBOT_SCREENSHOT_DIR") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    height = driver.execute_script("return document.body.scrollHeight")
    driver.set_window_size(1280, min(int(height) + 100, 4000))
    driver.execute_script("window.scrollTo(0, 0)")
    path = folder / name
    driver.save_screenshot(str(path))
    driver.set_window_size(1280, 900)
    return path


@needs_browser
def test_clicking_a_shot_highlights_it_on_the_map(guided_round, driver, tmp_path):
    _, rnd, _, _ = guided_round
    driver.get((rnd / "guide" / "index.html").as_uri())
    driver.get_log("browser")  # drop what came before
    cards = driver.find_elements("css selector", ".shot-card")
    assert cards
    pick = len(cards) - 1
    cards[pick].click()
    state = driver.execute_script(
        "return Array.from(document.querySelectorAll('svg.map .shot')).map("
        "e => [e.closest('svg').id, Number(e.dataset.rank), e.classList.contains('active')])"
    )
    assert {v for v, _, _ in state} == {"map-top", "map-side"}
    assert all(active == (rank == pick) for _, rank, active in state), state
    assert driver.execute_script("return document.querySelectorAll('.taken.ref').length") == 2
    assert "active" in cards[pick].get_attribute("class")
    # and from the map: a frustum selects its card
    driver.find_element("css selector", "#map-top .shot[data-rank='0'] circle").click()
    assert "active" in cards[0].get_attribute("class")
    assert "active" not in cards[pick].get_attribute("class")
    previews = driver.execute_script(
        "return Array.from(document.querySelectorAll('img.preview')).map(i => i.naturalWidth)"
    )
    assert len(previews) == len(cards) and all(w > 0 for w in previews)
    # "I cannot take this shot" needs guide serve: hidden from a file
    assert not any(b.is_displayed() for b in driver.find_elements("css selector", ".skip"))
    print("screenshot:", _screenshot(driver, tmp_path, "guide_page.png"))
    assert not _errors(driver)


def _answered(driver) -> bool:
    """The upload's answer is on the page."""
    text = driver.find_element("id", "upload-result").text
    return bool(text) and "Uploading" not in text


@needs_browser
def test_an_upload_through_guide_serve_lands_in_the_inbox(guided_round, driver, tmp_path):
    from selenium.webdriver.support.ui import WebDriverWait
    from werkzeug.serving import make_server

    from scenebot.guide.config import GuideConfig
    from scenebot.guide.serve import create_app

    _, rnd, folder, _ = guided_round
    scene = rnd.parent
    server = make_server("127.0.0.1", 0, create_app(GuideConfig(), scene), threaded=True)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        driver.get(f"http://127.0.0.1:{server.socket.getsockname()[1]}/")
        driver.get_log("browser")
        form = driver.find_element("id", "upload")
        WebDriverWait(driver, 10).until(lambda d: form.is_displayed())
        photo = sorted(folder.iterdir())[0]
        driver.find_element("css selector", "#upload input[type=file]").send_keys(str(photo))
        driver.find_element("css selector", "#upload button").click()
        WebDriverWait(driver, 20).until(_answered)
        text = driver.find_element("id", "upload-result").text
        assert f"{photo.name}: saved" in text, text
        saved = scene / "round_001" / "capture" / "inbox" / photo.name
        assert saved.read_bytes() == photo.read_bytes()
        # a shot the person cannot take, marked from its card, lands in the inbox's list
        card = driver.find_element("id", "shot-0")
        card.find_element("css selector", ".skip").click()
        WebDriverWait(driver, 10).until(lambda d: "skipped" in card.get_attribute("class"))
        skipped = json.loads((saved.parent / "skipped.json").read_text())["shots"]
        assert [s["rank"] for s in skipped] == [0]
        print("screenshot:", _screenshot(driver, tmp_path, "guide_upload.png"))
        assert not _errors(driver)
    finally:
        server.shutdown()
        thread.join(5)
