"""``scenebot guide serve`` (scenebot/guide/serve.py) through Flask's test client: the current
round's page, photos into the next round's inbox, each refusal naming the photo, nothing
overwritten."""

from __future__ import annotations

import io
import json

import cv2
import numpy as np
import pytest

from scenebot.guide.config import GuideConfig
from scenebot.guide.serve import create_app, current_round, save_photo

PAGE = "<!DOCTYPE html><title>guide of round 1</title>"


def jpeg(seed: int = 0, size: tuple[int, int] = (48, 64)) -> bytes:
    img = np.random.default_rng(seed).integers(0, 255, (*size, 3), dtype=np.uint8)
    return cv2.imencode(".jpg", img)[1].tobytes()


def png(seed: int = 0) -> bytes:
    img = np.random.default_rng(seed).integers(0, 255, (20, 30, 3), dtype=np.uint8)
    return cv2.imencode(".png", img)[1].tobytes()


@pytest.fixture
def scene(tmp_path):
    """results/<scene> with guides of rounds 0 and 1 (round 1 is current)."""
    scene = tmp_path / "results" / "demo"
    for r, text in ((0, "<p>old</p>"), (1, PAGE)):
        page = scene / f"round_{r:03d}" / "guide" / "index.html"
        page.parent.mkdir(parents=True)
        page.write_text(text)
    return scene


@pytest.fixture
def client(scene):
    app = create_app(GuideConfig(max_upload_mb=0.05), scene)  # 50 kB
    app.testing = True
    return app.test_client()


def upload(client, *files: tuple[bytes, str], accept: str = "application/json"):
    data = {"photos": [(io.BytesIO(b), name) for b, name in files]}
    return client.post("/upload", data=data, content_type="multipart/form-data",
                       headers={"Accept": accept})  # fmt: skip


def inbox(scene):
    return scene / "round_002" / "capture" / "inbox"


def test_the_current_rounds_page_is_served(client, scene):
    res = client.get("/")
    assert res.status_code == 200 and res.mimetype == "text/html"
    assert res.get_data(as_text=True) == PAGE
    status = client.get("/api/status").get_json()
    assert status["round"] == "round_001"
    assert status["inbox"] == inbox(scene).as_posix() + "/"
    assert status["max_upload_mb"] == 0.05 and status["photos_in_inbox"] == []


def test_a_jpeg_lands_in_the_inbox_unchanged(client, scene):
    photo = jpeg()
    res = upload(client, (photo, "IMG_0001.jpg"))
    assert res.status_code == 200, res.get_json()
    body = res.get_json()
    assert [a["saved_as"] for a in body["accepted"]] == ["IMG_0001.jpg"] and not body["rejected"]
    assert "IMG_0001.jpg" in body["accepted"][0]["message"]
    assert (inbox(scene) / "IMG_0001.jpg").read_bytes() == photo
    assert client.get("/api/status").get_json()["photos_in_inbox"] == ["IMG_0001.jpg"]


def test_a_png_is_taken_and_named_as_one(client, scene):
    res = upload(client, (png(), "screen.png"), (png(1), "sent_as.jpg"))
    assert res.status_code == 200, res.get_json()
    assert sorted(p.name for p in inbox(scene).iterdir()) == ["screen.png", "sent_as.png"]


def test_a_file_that_is_not_an_image_is_refused_by_name(client, scene):
    res = upload(client, (b"%PDF-1.4 not a photo", "notes.jpg"),
                 (b"\xff\xd8\xff\xe0 truncated", "broken.jpg"))  # fmt: skip
    assert res.status_code == 422
    messages = [r["message"] for r in res.get_json()["rejected"]]
    assert len(messages) == 2
    assert messages[0].startswith("notes.jpg: refused: not a JPEG or PNG")
    assert messages[1].startswith("broken.jpg: refused: not a JPEG or PNG")
    assert not inbox(scene).exists() or not any(inbox(scene).iterdir())


def test_an_oversized_photo_is_refused_by_name(client, scene):
    big = jpeg(size=(600, 800))
    assert len(big) > 50_000
    res = upload(client, (big, "huge.jpg"), (jpeg(2), "small.jpg"))
    assert res.status_code == 422
    body = res.get_json()
    assert [r["name"] for r in body["rejected"]] == ["huge.jpg"]
    assert "huge.jpg" in body["rejected"][0]["message"]
    assert "guide.max_upload_mb" in body["rejected"][0]["message"]
    assert [p.name for p in inbox(scene).iterdir()] == ["small.jpg"]  # the other one is kept


@pytest.mark.parametrize("name", ["../evil.jpg", "sub/dir.jpg", "..\\win.jpg", "/abs.jpg",
                                  ".hidden.jpg", ""])  # fmt: skip
def test_a_name_with_a_path_is_refused(client, scene, name):
    res = upload(client, (jpeg(), name))
    assert res.status_code in (400, 422)
    body = res.get_json()
    if res.status_code == 422:  # named as received (a quoted name's backslashes are escapes)
        got = body["rejected"][0]
        assert got["message"].startswith(f"{got['name']!r}: refused")
    assert not list(scene.parent.rglob("evil.jpg")) and not list(scene.rglob("*.jpg"))


def test_an_existing_photo_is_never_overwritten(client, scene):
    box = inbox(scene)
    box.mkdir(parents=True)
    (box / "IMG_1.jpg").write_bytes(b"first")
    images = box.parent / "images"  # a photo of the round already registered
    images.mkdir()
    (images / "IMG_1-1.jpg").write_bytes(b"registered")
    again = jpeg(5)
    res = upload(client, (again, "IMG_1.jpg"), (jpeg(6), "IMG_1.jpg"))
    assert res.status_code == 200
    saved = [a["saved_as"] for a in res.get_json()["accepted"]]
    assert saved == ["IMG_1-2.jpg", "IMG_1-3.jpg"]
    assert "IMG_1.jpg is there already" in res.get_json()["accepted"][0]["message"]
    assert (box / "IMG_1.jpg").read_bytes() == b"first"
    assert (images / "IMG_1-1.jpg").read_bytes() == b"registered"
    assert (box / "IMG_1-2.jpg").read_bytes() == again


def test_a_plain_form_post_gets_a_page(client, scene):
    res = upload(client, (b"nope", "a.txt"), accept="text/html")
    assert res.status_code == 422 and res.mimetype == "text/html"
    assert "a.txt: refused" in res.get_data(as_text=True)


def test_an_upload_without_photos_and_a_request_too_large(scene):
    app = create_app(GuideConfig(max_upload_mb=0.01, max_request_photos=1), scene)
    c = app.test_client()
    res = c.post("/upload", data={}, headers={"Accept": "application/json"})
    assert res.status_code == 400 and "no photo" in res.get_json()["error"]
    res = upload(c, (jpeg(size=(900, 1200)), "big.jpg"))
    assert res.status_code == 413 and "send fewer photos" in res.get_json()["error"]


def test_no_guide_yet_says_what_to_run(tmp_path):
    app = create_app(GuideConfig(), tmp_path / "results" / "none")
    res = app.test_client().get("/", headers={"Accept": "application/json"})
    assert res.status_code == 404 and "run snakemake" in res.get_json()["error"]


def test_a_fixed_round_and_the_latest(scene):
    assert current_round(scene) == 1 and current_round(scene, 0) == 0
    app = create_app(GuideConfig(), scene, round_=0)
    assert app.test_client().get("/").get_data(as_text=True) == "<p>old</p>"
    status = app.test_client().get("/api/status").get_json()
    assert status["inbox"].endswith("round_001/capture/inbox/")


def test_save_photo_writes_nothing_for_a_refusal(tmp_path):
    box = tmp_path / "inbox"
    u = save_photo(box, "x.jpg", io.BytesIO(b"GIF89a"), 1000)
    assert not u.ok and u.message.startswith("x.jpg: refused") and not box.exists()


def test_serve_binds_to_localhost_unless_told(monkeypatch, scene, capsys):
    from scenebot import cli

    seen = {}

    def fake_serve(cfg, scene_dir, round_=None):
        seen.update(host=cfg.host, port=cfg.port, scene_dir=scene_dir, round=round_)

    monkeypatch.setattr("scenebot.guide.serve.serve", fake_serve)
    cfg = scene.parent.parent / "c.yaml"
    cfg.write_text(json.dumps({"scene": "demo"}))
    assert cli.main(["guide", "serve", "--config", str(cfg), "--scene-dir", str(scene)]) == 0
    assert seen["host"] == "127.0.0.1" and seen["port"] == GuideConfig().port
    cli.main(["guide", "serve", "--config", str(cfg), "--scene-dir", str(scene), "--host",
              "0.0.0.0", "--port", "0", "--round", "0"])  # fmt: skip
    assert (seen["host"], seen["port"], seen["round"]) == ("0.0.0.0", 0, 0)


def test_a_shot_the_person_cannot_take_is_marked_in_the_inbox(client, scene):
    """The page's "I cannot take this shot": POST /skip writes the inbox's skipped.json
    (the next round plans others); a shot the guide does not have is refused, naming its
    shots; /api/status lists the marked shots."""
    goals = {"goals": [{"rank": k, "x": 0.0, "y": 0.0, "theta": 0.0} for k in range(3)]}
    (scene / "round_001" / "goals.json").write_text(json.dumps(goals))
    r = client.post("/skip", json={"shot": 2})
    assert r.status_code == 200 and r.get_json()["skipped"] == [2]
    assert "shot 2 marked as not taken" in r.get_json()["message"]
    r = client.post("/skip", data={"shot": "0", "reason": "behind the sofa"})
    assert r.status_code == 200 and r.get_json()["skipped"] == [0, 2]
    box = scene / "round_002" / "capture" / "inbox"
    assert json.loads((box / "skipped.json").read_text())["shots"] == [
        {"rank": 0, "reason": "behind the sofa"},
        {"rank": 2, "reason": "marked on the guide page"},
    ]
    for bad in ({"shot": 7}, {"shot": "x"}, {}):
        r = client.post("/skip", json=bad)
        assert r.status_code == 400
        assert "round_001's guide has no shot" in r.get_json()["error"]
        assert "its shots are 0, 1, 2" in r.get_json()["error"]
    assert client.get("/api/status").get_json()["skipped"] == [0, 2]
