"""The guide page of a person's round (scenebot/guide/page.py) on a small synthetic round: a
pycolmap synthetic map, photos written under its image names, goals near the cameras,
previews and a coverage picture; and the step from a photo to a shot (guide/advice.py).

The real round (the canned photo set through the workflow) is in test_guide_workflow.py.
"""

from __future__ import annotations

import base64
import json
import re

import cv2
import numpy as np
import pycolmap
import pytest

from scenebot.artifacts.previews import read_previews, write_previews
from scenebot.geometry import read_sparse_map
from scenebot.guide.advice import describe, nearest_photo, photo_poses, step_from
from scenebot.guide.config import GuideConfig
from scenebot.guide.page import GuideInputError, GuideInputs, GuideOutputs, run


def page_json(text: str) -> dict:
    """The data a guide page embeds (``<script id="guide-data">``)."""
    m = re.search(r'<script id="guide-data" type="application/json">(.*?)</script>', text, re.S)
    assert m, "no guide-data script"
    return json.loads(m.group(1).replace("<\\/", "</"))


def data_uri_image(uri: str) -> np.ndarray:
    """An RGB image from a data URI."""
    head, b64 = uri.split(",", 1)
    assert head in ("data:image/png;base64", "data:image/jpeg;base64"), head
    img = cv2.imdecode(np.frombuffer(base64.b64decode(b64), np.uint8), cv2.IMREAD_COLOR)
    assert img is not None
    return img[..., ::-1]


def shot_cards(text: str) -> dict[int, str]:
    """Each shot card's HTML by rank."""
    parts = re.findall(r'(<article class="shot-card"[^>]*data-rank="(\d+)".*?</article>)', text,
                       re.S)  # fmt: skip
    return {int(r): html for html, r in parts}


@pytest.fixture
def round_dir(tmp_path):
    """results/<scene>/round_000 of a small synthetic round: sfm/, photos, goals.json,
    goals_preview.npz, goals.png."""
    scene = tmp_path / "results" / "demo"
    rnd = scene / "round_000"
    sfm = rnd / "sfm"
    sfm.mkdir(parents=True)
    opts = pycolmap.SyntheticDatasetOptions()
    opts.num_points3D = 300
    rec = pycolmap.synthesize_dataset(opts)
    rec.write(str(sfm))
    smap = read_sparse_map(sfm)
    photos = tmp_path / "photos"
    photos.mkdir()
    rng = np.random.default_rng(3)
    for name in smap.names:
        img = rng.integers(0, 255, (60, 80, 3), dtype=np.uint8)
        cv2.imwrite(str(photos / name), img)
    taken = photo_poses(smap.R, smap.centres)
    goals = []
    for rank, i in enumerate((0, 3, 5)):
        x, y, z, t, p = taken[i] + np.array([0.3, -0.2, 0.1, 0.4, 0.2])
        goals.append({"rank": rank, "candidate": 10 + rank, "x": round(x, 4), "y": round(y, 4),
                      "z": round(z, 4), "theta": round(t, 5), "pitch": round(p, 5),
                      "score_deg": 30.0 - rank})  # fmt: skip
    (rnd / "goals.json").write_text(json.dumps({"round": "round_000", "complete": False,
                                                "goals": goals}))  # fmt: skip
    tiles = [rng.integers(0, 255, (30, 40, 3), dtype=np.uint8) for _ in goals]
    missing = [rng.random((30, 40)) < 0.3 for _ in goals]
    write_previews(rnd / "goals_preview.npz", [g["rank"] for g in goals], tiles, missing)
    cv2.imwrite(str(rnd / "goals.png"), np.full((50, 70, 3), 200, np.uint8))
    return rnd, photos


def inputs(rnd, photos) -> GuideInputs:
    return GuideInputs(rnd / "sfm", photos, rnd / "goals.json", rnd / "goals_preview.npz",
                       rnd / "goals.png")  # fmt: skip


def test_the_page_lists_each_shot_of_goals_json_with_its_preview(round_dir):
    rnd, photos = round_dir
    out = rnd / "guide" / "index.html"
    summary = run(GuideConfig(photo_width=64), inputs(rnd, photos), GuideOutputs(out))
    text = out.read_text(encoding="utf-8")
    data = page_json(text)
    goals = json.loads((rnd / "goals.json").read_text())["goals"]
    previews = read_previews(rnd / "goals_preview.npz")
    assert len(data["shots"]) == len(goals) == len(summary["shots"]) == 3
    cards = shot_cards(text)
    assert sorted(cards) == [0, 1, 2]
    for k, (g, shot) in enumerate(zip(goals, data["shots"], strict=True)):
        for key in ("rank", "x", "y", "z", "theta", "pitch", "score_deg"):
            assert shot[key] == g[key], (k, key)
        card = cards[g["rank"]]
        assert f"{g['score_deg']:.1f}°" in card  # the predicted gain
        srcs = re.findall(r'src="(data:[^"]+)"', card)
        assert len(srcs) == 2  # the preview and the photo to start from
        assert np.array_equal(data_uri_image(srcs[0]), previews.images[k])  # PNG: lossless
        assert data_uri_image(srcs[1]).shape[1] == 64  # guide.photo_width
        assert shot["from_photo"] in card and shot["advice"] in card.replace("&#x27;", "'")
        assert shot["missing_fraction"] == pytest.approx(previews.missing[k].mean(), abs=1e-4)
    # each shot's frustum on both views
    for view in ("top", "side"):
        svg = re.search(rf'<svg class="map" id="map-{view}".*?</svg>', text, re.S).group(0)
        assert sorted(map(int, re.findall(r'class="shot" data-rank="(\d+)"', svg))) == [0, 1, 2]
        assert len(re.findall(r'class="taken"', svg)) == data["photos_mapped"]
    assert data["inbox"].endswith("results/demo/round_001/capture/inbox/")
    assert data["units"] == "units"  # no sfm report with a metric scale


def test_the_step_leads_from_the_nearest_photo_to_the_shot(round_dir):
    rnd, photos = round_dir
    out = rnd / "guide" / "index.html"
    run(GuideConfig(), inputs(rnd, photos), GuideOutputs(out))
    data = page_json(out.read_text(encoding="utf-8"))
    smap = read_sparse_map(rnd / "sfm")
    taken = photo_poses(smap.R, smap.centres)
    for shot in data["shots"]:
        i = smap.names.index(shot["from_photo"])
        assert i == shot["from_index"]
        pose = np.array([shot[c] for c in ("x", "y", "z", "theta", "pitch")])
        d = np.linalg.norm(taken[:, :3] - pose[:3], axis=1)
        assert d[i] <= d.min() * 1.1 + 1e-9  # the nearest (ties: the one facing alike)
        st, th = shot["step"], taken[i, 3]
        fwd, right = np.array([np.cos(th), np.sin(th), 0]), np.array([np.sin(th), -np.cos(th), 0])
        there = taken[i, :3] + st["forward"] * fwd + st["right"] * right + [0, 0, st["up"]]
        np.testing.assert_allclose(there, pose[:3], atol=2e-3)


def test_the_page_needs_no_network(round_dir):
    rnd, photos = round_dir
    out = rnd / "guide" / "index.html"
    run(GuideConfig(), inputs(rnd, photos), GuideOutputs(out))
    text = out.read_text(encoding="utf-8")
    assert not re.search(r"<link[^>]+stylesheet", text)
    assert not re.search(r"<script[^>]+src=", text)
    urls = re.findall(r'(?:src|href)="([^"]+)"', text)
    assert urls and all(u.startswith("data:") for u in urls), urls
    assert "http://www.w3.org/2000/svg" in text  # the SVG namespace is the only URL
    assert not re.search(r"https?://(?!www\.w3\.org/2000/svg)", text)


def test_previews_of_other_shots_are_refused(round_dir):
    rnd, photos = round_dir
    prev = read_previews(rnd / "goals_preview.npz")
    write_previews(rnd / "goals_preview.npz", [0, 1], list(prev.images[:2]),
                   list(prev.missing[:2]))  # fmt: skip
    with pytest.raises(GuideInputError, match="re-run the goals_preview rule"):
        run(GuideConfig(), inputs(rnd, photos), GuideOutputs(rnd / "guide" / "index.html"))


def test_a_robots_goals_are_refused(round_dir):
    rnd, photos = round_dir
    (rnd / "goals.json").write_text(json.dumps({"goals": [{"rank": 0, "x": 0, "y": 0,
                                                           "theta": 0}]}))  # fmt: skip
    with pytest.raises(GuideInputError, match="person's photos"):
        run(GuideConfig(), inputs(rnd, photos), GuideOutputs(rnd / "guide" / "index.html"))


def test_a_complete_map_says_so_and_shows_no_card(round_dir):
    rnd, photos = round_dir
    (rnd / "goals.json").write_text(
        json.dumps(
            {"round": "round_000", "complete": True, "complete_because": "best 3 < 10", "goals": []}
        )
    )
    write_previews(rnd / "goals_preview.npz", [], [], [])
    out = rnd / "guide" / "index.html"
    run(GuideConfig(), inputs(rnd, photos), GuideOutputs(out))
    text = out.read_text(encoding="utf-8")
    assert "<b>complete</b>" in text and "No shot advised" in text and not shot_cards(text)


def test_step_from_a_photo_in_its_own_terms():
    photo = np.array([1.0, 2.0, 0.0, 0.0, 0.0])  # facing +x
    shot = np.array([2.0, 1.0, 0.5, np.pi / 2, np.radians(20)])  # 1 ahead, 1 right, up
    st = step_from(photo, shot)
    assert (st.forward, st.right, st.up) == pytest.approx((1.0, 1.0, 0.5))
    assert st.distance == pytest.approx(1.5)
    assert st.turn_deg == pytest.approx(90.0) and st.pitch_deg == pytest.approx(20.0)
    text = describe(st, "IMG_7.jpg", "m")
    for part in ("IMG_7.jpg", "1.00 m forward", "1.00 m right", "0.50 m higher",
                 "turn 90° left", "aim 20° above level"):  # fmt: skip
        assert part in text, (part, text)
    back = describe(step_from(shot, photo), "x.jpg", "units")
    assert "units" in back and "turn 90° right" in back and "hold the camera level" in back


def test_nearest_photo_breaks_ties_by_direction():
    taken = np.array([[0, 0, 0, 0.0, 0], [0.01, 0, 0, np.pi, 0], [5, 0, 0, np.pi, 0]])
    shot = np.array([0.5, 0, 0, np.pi - 0.1, 0])
    assert nearest_photo(shot, taken) == 1  # as near as photo 0, and facing the same way
    assert nearest_photo(np.array([4.0, 0, 0, 0, 0]), taken) == 2
