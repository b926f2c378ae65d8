"""Guided rounds (``robot: guided``, ``person-sim``): a round's inbox taken in as its capture
(scenebot/capture/person.py) and the shots each photo fulfilled (scenebot/guide/fulfil.py);
bad input named: an empty inbox, a photo that is not one, the same photo twice, a photo
that fulfils no shot, one that does not register."""

from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pycolmap
import pytest
from PIL import Image

from scenebot.capture.person import InboxError, run_folder_round, run_inbox_round
from scenebot.capturelog import photo_records, read_log
from scenebot.config import Config
from scenebot.guide.config import GuideConfig
from scenebot.guide.fulfil import FulfilInputs, FulfilOutputs, compare, fulfils, run


def jpeg(path, seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    Image.fromarray(rng.integers(0, 255, (24, 32, 3), dtype=np.uint8)).save(path, "JPEG")
    return path.read_bytes()


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@pytest.fixture
def scene(tmp_path):
    """results/office with round 0 taken (one photo, its hash logged) and round 1's inbox."""
    scene = tmp_path / "results" / "office"
    cap0 = scene / "round_000" / "capture"
    (cap0 / "images").mkdir(parents=True)
    old = jpeg(cap0 / "images" / "r000_0000.jpg", 99)
    (cap0 / "log.jsonl").write_text(
        json.dumps({"type": "photo", "index": 0, "image": "images/r000_0000.jpg",
                    "sha256": sha(old)}) + "\n"
    )  # fmt: skip
    inbox = scene / "round_001" / "capture" / "inbox"
    inbox.mkdir(parents=True)
    return scene, inbox, old


def cfg(tmp_path) -> Config:
    folder = tmp_path / "my photos"
    folder.mkdir(exist_ok=True)
    return Config(robot="guided", photos={"folder": str(folder)})


def test_an_empty_inbox_says_where_to_put_the_photos(scene, tmp_path):
    _, inbox, _ = scene
    (inbox / "notes.txt").write_text("not a photo")
    with pytest.raises(InboxError) as err:
        run_inbox_round(cfg(tmp_path), inbox.parent, 1)
    msg = str(err.value)
    assert f"{inbox}/" in msg
    assert "round_000/guide/index.html" in msg and "guide serve" in msg
    assert "max_rounds=1" in msg
    assert not (inbox.parent / "log.jsonl").exists()
    assert not (inbox.parent / "images").exists()  # nothing started


def test_the_inbox_photos_become_the_rounds_capture_and_stay_in_the_inbox(scene, tmp_path):
    _, inbox, old = scene
    data = {n: jpeg(inbox / n, k) for k, n in enumerate(["IMG_2.JPG", "IMG_10.jpg"])}
    (inbox / "same.jpg").write_bytes(data["IMG_2.JPG"])  # the same photo twice
    (inbox / "again.jpg").write_bytes(old)  # a photo of round 0 again
    (inbox / "broken.jpg").write_bytes(b"\xff\xd8 not a jpeg")
    before = {p.name: p.read_bytes() for p in inbox.iterdir()}
    summary = run_inbox_round(cfg(tmp_path), inbox.parent, 1)
    assert summary["photos"] == 2
    cap = inbox.parent
    recs = photo_records(cap / "log.jsonl")
    assert [r["image"] for r in recs] == ["images/r001_0000.jpg", "images/r001_0001.jpg"]
    assert [r["source"] for r in recs] == ["inbox/IMG_2.JPG", "inbox/IMG_10.jpg"]
    for r in recs:
        got = (cap / r["image"]).read_bytes()
        assert got == before[r["source"].rsplit("/", 1)[1]] and sha(got) == r["sha256"]
        assert not (cap / r["image"]).stat().st_mode & 0o222  # read-only
    left = {e["source"].rsplit("/", 1)[1]: e["reason"] for e in read_log(cap / "log.jsonl")
            if e.get("event") == "photo_left_out"}  # fmt: skip
    assert set(left) == {"same.jpg", "again.jpg", "broken.jpg"}
    assert "IMG_2.JPG" in left["same.jpg"] and "r000_0000.jpg" in left["again.jpg"]
    assert "not an image" in left["broken.jpg"]
    assert (cap / "trajectory.png").is_file()
    assert {p.name: p.read_bytes() for p in inbox.iterdir()} == before  # never modified

    # a photo added later: the round is taken in again, the earlier attempt archived
    jpeg(inbox / "IMG_11.jpg", 5)
    run_inbox_round(cfg(tmp_path), cap, 1)
    assert len(photo_records(cap / "log.jsonl")) == 3
    archived = list((cap / "superseded").glob("*/images/r001_0001.jpg"))
    assert len(archived) == 1 and (inbox / "IMG_11.jpg").is_file()
    assert not list((cap / "superseded").glob("*/inbox"))  # the inbox stays in place


def test_only_bad_photos_is_an_error_naming_each(scene, tmp_path):
    _, inbox, old = scene
    (inbox / "again.jpg").write_bytes(old)
    (inbox / "empty.png").write_bytes(b"")
    with pytest.raises(InboxError) as err:
        run_inbox_round(cfg(tmp_path), inbox.parent, 1)
    msg = str(err.value)
    assert "again.jpg" in msg and "empty.png" in msg and "empty file" in msg


def test_the_simulated_persons_truth_goes_into_the_log(scene, tmp_path):
    _, inbox, _ = scene
    jpeg(inbox / "person_r001_000.jpg", 1)
    truth = {"center": [1, 2, 1.5], "R_cam_from_world": np.eye(3).tolist()}
    (inbox / "person-sim.jsonl").write_text(
        json.dumps({"type": "shot", "aimed_shot": 2, "image": "person_r001_000.jpg",
                    "truth": truth}) + "\n"
        + json.dumps({"type": "shot", "aimed_shot": 3, "skipped": "inside furniture"}) + "\n"
    )  # fmt: skip
    run_inbox_round(cfg(tmp_path), inbox.parent, 1)
    (rec,) = photo_records(inbox.parent / "log.jsonl")
    assert rec["aimed_shot"] == 2 and rec["truth"] == truth


def test_round_zero_is_the_folder_taken_in(tmp_path):
    c = cfg(tmp_path)
    data = [jpeg(c.photos.folder / f"DSC{k}.jpg", k) for k in range(3)]
    cap = tmp_path / "results" / "office" / "round_000" / "capture"
    assert run_folder_round(c, cap)["photos"] == 3
    recs = photo_records(cap / "log.jsonl")
    assert [(cap / r["image"]).read_bytes() for r in recs] == data
    empty = Config(robot="guided", photos={"folder": str(tmp_path / "none")})
    with pytest.raises(InboxError, match="holds no photo"):
        run_folder_round(empty, tmp_path / "other" / "round_000" / "capture")


# ------------------------------------------------------------------------------ fulfilment


def test_a_photo_fulfils_a_shot_within_every_tolerance():
    cfg = GuideConfig(fulfil_distance_m=0.3, fulfil_heading_deg=20, fulfil_pitch_deg=15)
    shot = {"rank": 0, "center": np.zeros(3), "heading": 0.0, "pitch": 0.0}

    def axis(h, p):
        h, p = math.radians(h), math.radians(p)
        return np.array([math.cos(p) * math.cos(h), math.cos(p) * math.sin(h), math.sin(p)])

    d = compare(np.array([0.2, 0.1, 0.0]), axis(350, 10), shot)
    assert d["distance"] == pytest.approx(math.hypot(0.2, 0.1))
    assert d["heading_deg"] == pytest.approx(10) and d["pitch_deg"] == pytest.approx(10)
    assert fulfils(d, cfg)
    assert not fulfils(compare(np.array([0.35, 0, 0]), axis(0, 0), shot), cfg)
    assert not fulfils(compare(np.zeros(3), axis(25, 0), shot), cfg)
    assert not fulfils(compare(np.zeros(3), axis(0, -20), shot), cfg)


def _sim3(scale: float, angle: float, t) -> pycolmap.Sim3d:
    q = np.array([0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)])  # x, y, z, w
    return pycolmap.Sim3d(scale, pycolmap.Rotation3d(q), np.asarray(t, float))


def test_the_shots_each_photo_fulfilled_in_a_frame_fixed_anew(tmp_path):
    """Round 1's map holds round 0's photos and three new ones in a frame scaled, turned and
    moved from round 0's: the first new photo stands on shot 0, the second 1 m from any
    shot, the third did not register."""
    opts = pycolmap.SyntheticDatasetOptions()
    opts.num_points3D = 200
    rec = pycolmap.synthesize_dataset(opts)
    ids = sorted(rec.reg_image_ids())
    n0 = len(ids) - 2
    scene = tmp_path / "results" / "office"
    names = [f"round_000/capture/images/r000_{k:04d}.jpg" for k in range(n0)]
    names += [f"round_001/capture/images/r001_{k:04d}.jpg" for k in range(2)]
    for i, n in zip(ids, names, strict=True):
        rec.image(i).name = n
    cur = pycolmap.Reconstruction(rec)
    cur.transform(_sim3(2.0, 0.8, [1.0, -3.0, 0.5]))  # round 1's frame
    (scene / "round_001" / "sfm").mkdir(parents=True)
    cur.write(str(scene / "round_001" / "sfm"))
    prev = pycolmap.Reconstruction(rec)
    for i in ids[n0:]:
        prev.deregister_frame(prev.image(i).frame_id)
    (scene / "round_000" / "sfm").mkdir(parents=True)
    prev.write(str(scene / "round_000" / "sfm"))

    def pose(rc, i):  # x, y, z, heading, pitch of a photo in a model
        im = rc.image(i)
        v = im.cam_from_world().rotation.matrix()[2]
        c = im.projection_center()
        return [*c, math.atan2(v[1], v[0]), math.asin(v[2])]

    x, y, z, th, p = pose(rec, ids[n0])  # round 0's frame: the shot the new photo stands on
    far = pose(rec, ids[n0 + 1])
    goals = [
        {"rank": 0, "x": x + 0.05, "y": y, "z": z, "theta": th + 0.1, "pitch": p},
        {"rank": 1, "x": far[0] + 1.0, "y": far[1], "z": far[2], "theta": far[3], "pitch": far[4]},
    ]  # fmt: skip
    (scene / "round_000" / "goals.json").write_text(json.dumps({"goals": goals}))
    # an earlier round's unfulfilled shot, in round 0's frame: carried into round 1's
    earlier = {"round": "round_xxx", "rank": 3, "x": 1.0, "y": 2.0, "z": 0.5, "reason": "r"}
    (scene / "round_000" / "fulfilment.json").write_text(json.dumps({"unfulfilled": [earlier]}))
    cap = scene / "round_001" / "capture"
    cap.mkdir()
    recs = [{"type": "photo", "index": k, "image": f"images/r001_{k:04d}.jpg",
             "source": f"{cap}/inbox/IMG_{k}.jpg"} for k in range(3)]  # fmt: skip
    # the person said it could not take shot 1 (the inbox's skipped.json, in the log)
    recs.append({"type": "event", "event": "shots_skipped",
                 "shots": [{"rank": 1, "reason": "behind a wall"}]})  # fmt: skip
    (cap / "log.jsonl").write_text("".join(json.dumps(r) + "\n" for r in recs))
    report = scene / "round_001" / "sfm" / "report.json"
    report.write_text(json.dumps({"dropped": {
        "round_001/capture/images/r001_0002.jpg": "no verified matches with a registered photo"
    }}))  # fmt: skip
    out = scene / "round_001" / "fulfilment.json"
    # tolerances in map units: round 0's frame is half the size of round 1's
    g = GuideConfig(fulfil_distance_m=0.3, fulfil_heading_deg=10, fulfil_pitch_deg=10)
    doc = run(g, FulfilInputs(scene / "round_001" / "sfm", scene / "round_000" / "sfm",
                              scene / "round_000" / "goals.json", cap / "log.jsonl", report,
                              scene / "round_000" / "fulfilment.json"),
              FulfilOutputs(out))  # fmt: skip
    assert json.loads(out.read_text()) == json.loads(json.dumps(doc))
    assert doc["frame"]["scale"] == pytest.approx(2.0)
    on, off, lost = doc["photos"]
    assert on["fulfils"] == [0] and on["nearest_shot"]["distance"] == pytest.approx(0.1)
    assert off["fulfils"] == [] and off["registered"]
    assert off["nearest_shot"]["rank"] == 1
    assert off["nearest_shot"]["distance"] == pytest.approx(2.0)  # 1 unit of round 0 x 2
    assert "IMG_1.jpg (images/r001_0001.jpg) fulfils no shot" in off["message"]
    assert "nearest, shot 1, is 2.00 away" in off["message"]  # numbered as on the guide page
    assert "It is kept" in off["message"]
    assert not lost["registered"]
    assert "IMG_2.jpg (images/r001_0002.jpg) did not register" in lost["message"]
    assert "no verified matches" in lost["message"]
    assert [(s["rank"], s["fulfilled_by"]) for s in doc["shots"]] == [
        (0, ["round_001/capture/images/r001_0000.jpg"]), (1, [])]  # fmt: skip

    def moved(p):  # round 0's frame -> round 1's
        c, s_ = math.cos(0.8), math.sin(0.8)
        return 2.0 * np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]]) @ np.asarray(p) + [1, -3, 0.5]

    shot1 = doc["shots"][1]
    assert [shot1[k] for k in "xyz"] == pytest.approx(moved([far[0] + 1.0, far[1], far[2]]))
    # the shots no photo fulfilled, every round's so far, in round 1's frame
    carried, unfulfilled = doc["unfulfilled"]
    assert carried["round"] == "round_xxx" and carried["rank"] == 3
    assert [carried[k] for k in "xyz"] == pytest.approx(moved([1.0, 2.0, 0.5]))
    assert unfulfilled["round"] == "round_000" and unfulfilled["rank"] == 1
    assert [unfulfilled[k] for k in "xyz"] == pytest.approx([shot1[k] for k in "xyz"])
    assert shot1["skipped"] == "behind a wall" and "skipped" not in doc["shots"][0]
    assert unfulfilled["reason"] == "skipped: the person could not take shot 1 (behind a wall)"
    assert doc["summary"] == {"shots": 2, "fulfilled": 1, "skipped": 1, "photos": 3,
                              "registered": 2, "fulfilling_none": 1, "not_registered": 1,
                              "unfulfilled_so_far": 2}  # fmt: skip
    assert doc["messages"] == [off["message"], lost["message"]]


def test_a_guided_campaign_matches_all_pairs_unless_told_otherwise():
    from scenebot.config import GUIDED_EXHAUSTIVE_MAX_IMAGES

    assert Config(robot="person-sim").sfm.exhaustive_max_images == GUIDED_EXHAUSTIVE_MAX_IMAGES
    assert Config().sfm.exhaustive_max_images == 40  # the robot pairs by its positions
    told = Config(robot="person-sim", sfm={"exhaustive_max_images": 60})
    assert told.sfm.exhaustive_max_images == 60


def test_settings_name_a_guided_photo_as_the_person_named_it():
    """sfm.known_distance and sfm.up_photo name the folder's files (IMG_0003.jpg); a guided
    campaign's round 0 holds them as round_000/capture/images/r000_NNNN.jpg."""
    from types import SimpleNamespace

    from scenebot.sfm.photos import Photo
    from scenebot.sfm.stage import _person_known_distance, _person_photo_name

    photos = [
        Photo(f"round_000/capture/images/r000_000{k}.jpg", None, source=f"/x/IMG_000{k + 3}.jpg")
        for k in range(3)
    ]
    s = SimpleNamespace(photos=photos, names=[p.name for p in photos], capture_dirs=[])
    assert _person_photo_name(s, "IMG_0004.jpg") == "round_000/capture/images/r000_0001.jpg"
    assert _person_photo_name(s, photos[2].name) == photos[2].name
    assert _person_known_distance(s, ("IMG_0003.jpg", "IMG_0005.jpg", 2.5)) == (
        photos[0].name, photos[2].name, 2.5,
    )  # fmt: skip
    assert _person_known_distance(s, None) is None


# ------------------------------------------------------------------------- skipped shots


def test_shots_the_person_cannot_take_make_a_round_without_photos(scene, tmp_path, capsys):
    """`scenebot guide skip` marks shots of the current guide as not taken; an inbox with
    no photo but skipped shots is a round without photos (not an error), the skips in its
    log; the sfm stage keeps the previous map for it."""
    from scenebot import cli
    from scenebot.capturelog import skipped_shots
    from scenebot.sfm.config import SfmConfig
    from scenebot.sfm.stage import SfmInputs, SfmOutputs
    from scenebot.sfm.stage import run as run_sfm

    scene_dir, inbox, _ = scene
    goals = {"goals": [{"rank": k, "x": 0, "y": 0, "theta": 0} for k in range(4)]}
    (scene_dir / "round_000" / "goals.json").write_text(json.dumps(goals))
    (scene_dir / "round_000" / "guide").mkdir()
    (scene_dir / "round_000" / "guide" / "index.html").write_text("<p>guide</p>")
    conf = tmp_path / "c.yaml"
    conf.write_text(json.dumps({"scene": "office"}))
    base = ["guide", "skip", "--config", str(conf), "--scene-dir", str(scene_dir)]
    assert cli.main([*base, "1", "3", "--reason", "behind a wall"]) == 0
    assert cli.main([*base, "3", "2"]) == 0  # shot 3 keeps its first reason
    assert cli.main([*base, "7"]) == 1
    err = capsys.readouterr().err
    assert "has no shot 7: its shots are 0, 1, 2, 3 (the numbers on its guide page)" in err
    doc = json.loads((inbox / "skipped.json").read_text())
    assert doc["shots"] == [{"rank": 1, "reason": "behind a wall"},
                            {"rank": 2, "reason": "the person could not take it"},
                            {"rank": 3, "reason": "behind a wall"}]  # fmt: skip

    summary = run_inbox_round(cfg(tmp_path), inbox.parent, 1)
    assert summary["photos"] == 0 and summary["skipped_shots"] == 3
    log = inbox.parent / "log.jsonl"
    assert photo_records(log) == []
    assert skipped_shots(log) == {1: "behind a wall", 2: "the person could not take it",
                                  3: "behind a wall"}  # fmt: skip
    assert next(r for r in read_log(log) if r["type"] == "end")["photos"] == 0

    # the round's map is the previous one, unchanged, without mapping
    rec = pycolmap.synthesize_dataset(pycolmap.SyntheticDatasetOptions())
    prev = scene_dir / "round_000" / "sfm"
    prev.mkdir()
    rec.write(str(prev))
    (prev / "report.json").write_text(json.dumps({"registered": rec.num_reg_images()}))
    (prev / "map.png").write_bytes(b"png")
    out = scene_dir / "round_001" / "sfm"
    report = run_sfm(SfmConfig(), SfmInputs(tmp_path / "db.db", [scene_dir / "round_000" /
                                            "capture", inbox.parent], previous_model=prev),
                     SfmOutputs(out))  # fmt: skip
    assert report["unchanged_from"] == "round_000"
    assert report["registered"] == rec.num_reg_images()
    assert json.loads((out / "report.json").read_text()) == report
    for f in ("cameras.bin", "images.bin", "points3D.bin", "map.png"):
        assert (out / f).read_bytes() == (prev / f).read_bytes()
    assert not (tmp_path / "db.db").exists()  # nothing matched, nothing mapped


def test_a_broken_skip_list_is_an_error_naming_it(scene, tmp_path):
    _, inbox, _ = scene
    (inbox / "skipped.json").write_text("[1, 2]")
    with pytest.raises(InboxError, match=r"skipped\.json is not a list of skipped shots"):
        run_inbox_round(cfg(tmp_path), inbox.parent, 1)


def test_a_tape_between_photos_not_in_the_map_leaves_the_scale_unknown(tmp_path, caplog):
    """The person's tape (the capture log's known_distance) between a photo that registered
    and one that did not: the map is mapped without a metric scale, with a warning, instead
    of the stage failing; between two registered photos it gives the scale."""
    from types import SimpleNamespace

    from scenebot.sfm.config import SfmConfig
    from scenebot.sfm.photos import Photo
    from scenebot.sfm.stage import _person_alignment

    rec = pycolmap.synthesize_dataset(pycolmap.SyntheticDatasetOptions())
    ids = sorted(rec.reg_image_ids())
    for k, i in enumerate(ids):
        rec.image(i).name = f"round_000/capture/images/r000_{k:04d}.jpg"
    cap = tmp_path / "round_000" / "capture"
    cap.mkdir(parents=True)
    photos = [Photo(rec.image(i).name, None) for i in ids]

    def align(other: str):
        tape = {"type": "event", "event": "known_distance", "image_a": "images/r000_0000.jpg",
                "image_b": other, "distance_m": 2.0}  # fmt: skip
        (cap / "log.jsonl").write_text(json.dumps(tape) + "\n")
        s = SimpleNamespace(cfg=SfmConfig(), photos=photos, names=[p.name for p in photos],
                            capture_dirs=[cap])  # fmt: skip
        return _person_alignment(s, SimpleNamespace(reconstruction=rec))

    with caplog.at_level("WARNING"):
        unknown = align("images/r000_0099.jpg")  # not in the map
    assert "not both in the map: the map's scale is unknown" in caplog.text
    metric = align("images/r000_0001.jpg")
    c0, c1 = (rec.image(ids[k]).projection_center() for k in (0, 1))
    assert metric.scale == pytest.approx(2.0 / np.linalg.norm(c1 - c0), rel=1e-6)
    assert unknown.scale != pytest.approx(metric.scale)


def test_a_capture_apps_record_beside_the_photos_goes_into_the_log(scene, tmp_path):
    """phone.jsonl beside the photos (photos.folder or an inbox): each photo's orientation and
    tracked motion go into its log record, other fields and other files' lines are ignored; a
    broken line stops the round naming the file and the line."""
    _, inbox, _ = scene
    jpeg(inbox / "IMG_1.jpg", 1)
    motion = {"session": "s1", "center": [0.1, 0.2, 1.5], "R_cam_from_session": np.eye(3).tolist(),
              "walked_m": 3.2}  # fmt: skip
    orientation = {"heading_deg": 90.0, "pitch_deg": 5.0, "roll_deg": 0.0}
    (inbox / "phone.jsonl").write_text(
        json.dumps({"image": "IMG_1.jpg", "motion": motion, "orientation": orientation,
                    "exposure": 0.01}) + "\n\n"
        + json.dumps({"image": "IMG_9.jpg", "motion": motion}) + "\n"
    )  # fmt: skip
    run_inbox_round(cfg(tmp_path), inbox.parent, 1)
    (rec,) = photo_records(inbox.parent / "log.jsonl")
    assert rec["motion"] == motion and rec["orientation"] == orientation
    assert "exposure" not in rec
    c = cfg(tmp_path)
    jpeg(c.photos.folder / "DSC0.jpg", 3)
    (c.photos.folder / "phone.jsonl").write_text(json.dumps({"image": "DSC0.jpg",
                                                             "motion": motion}) + "\n")  # fmt: skip
    cap = tmp_path / "results" / "office" / "round_000" / "capture"
    run_folder_round(c, cap)
    assert photo_records(cap / "log.jsonl")[0]["motion"] == motion
    (inbox / "phone.jsonl").write_text('{"image": "IMG_1.jpg"}\n{"motion": {}}\n')
    with pytest.raises(InboxError, match=r"phone\.jsonl, line 2: no \"image\""):
        run_inbox_round(cfg(tmp_path), inbox.parent, 1)
    (inbox / "phone.jsonl").write_text("IMG_1.jpg 0 0 0\n")
    with pytest.raises(InboxError, match=r"phone\.jsonl, line 1: not JSON"):
        run_inbox_round(cfg(tmp_path), inbox.parent, 1)
