"""A person's capture rounds (``robot: guided`` and ``robot: person-sim``).

A person's photos become a round's capture exactly as a robot's do (:mod:`scenebot.capture.session`:
the lock, the archive of an earlier attempt, ``images/``, ``log.jsonl``, ``trajectory.png``):

* round 0 of ``guided``: the photos of ``photos.folder`` (:func:`run_folder_round`);
* round 0 of ``person-sim``: the simulated person's walk along the walls
  (:func:`run_perimeter_round`);
* every later round: the photos in the round's inbox, ``round_XXX/capture/inbox/``
  (:func:`run_inbox_round`), put there by the person (by hand or through ``scenebot guide
  serve``) or by the simulated person (:func:`run_person_sim_shots`, which writes
  ``inbox/person-sim.jsonl`` beside its photos: the truth of each, for the evaluation).

The person's photos are only read: each is copied to ``images/rXXX_NNNN.<jpg|png>`` (the
capture's naming; read-only), and its record in the log names where it came from
(``source``) and its SHA-256 (``sha256``). A photo that does not decode, or whose bytes are a
photo already taken, is left out with a message naming it (an ``event`` record too); the
inbox keeps it. An empty inbox stops the round with a message saying where to put photos.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import math
import os
import shutil
import stat
from pathlib import Path

import numpy as np

from scenebot.artifacts.skipped import SKIPPED, read_skipped, write_skipped
from scenebot.capture.session import (
    SESSION_LOG,
    SUPERSEDED,
    capture_lock,
    finish_capture,
    start_capture,
)
from scenebot.capturelog import CaptureLog, photo_records, read_log
from scenebot.config import Config
from scenebot.jpeg import publish
from scenebot.sfm.photofiles import photo_files, sha256_of

log = logging.getLogger("scenebot.capture")

INBOX = "inbox"
PERSON_SIM_LOG = "person-sim.jsonl"
"""The simulated person's record of its shots, beside its photos in the inbox."""


PHONE_LOG = "phone.jsonl"
"""A capture app's record of each photo, beside the photos (``photos.folder`` or a round's
inbox): one JSON object per line, the photo's file name (``image``) and what the phone knew
when it took it: ``orientation`` (``heading_deg``, ``pitch_deg``, ``roll_deg``: compass and
accelerometer) and ``motion`` (its tracked pose: ``session``, ``center``,
``R_cam_from_session``, ``walked_m``; see :class:`scenebot.sfm.photos.Motion`). Other fields
are ignored."""
PHONE_FIELDS = ("orientation", "motion")


class InboxError(RuntimeError):
    """The round's inbox holds no photo that can be used (the message says where to put
    photos, and names every photo left out)."""


# ----------------------------------------------------------------------------- intake


def _read_skipped(inbox: Path) -> dict[int, str]:
    try:
        return read_skipped(inbox)
    except ValueError as exc:
        raise InboxError(str(exc)) from exc


def phone_records(folder: Path, files: list[Path]) -> dict[str, dict]:
    """The fields of :data:`PHONE_LOG` in ``folder`` per photo file name (``files``: the
    folder's photos; a record of another file is logged and ignored); empty without one.

    Raises:
        InboxError: a line that is not a JSON object with an ``image`` (names the file and
            the line).
    """
    path = Path(folder) / PHONE_LOG
    if not path.is_file():
        return {}
    names = {f.name for f in files}
    out: dict[str, dict] = {}
    for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as exc:
            raise InboxError(f"{path}, line {k}: not JSON ({exc.msg}); one object per line, "
                             'e.g. {"image": "IMG_1.jpg", "motion": {...}}') from None  # fmt: skip
        if not isinstance(rec, dict) or not isinstance(rec.get("image"), str):
            raise InboxError(f'{path}, line {k}: no "image" (the photo\'s file name) in it')
        name = Path(rec["image"]).name
        if name not in names:
            log.warning("%s, line %d: no photo %s beside it: ignored", path, k, name)
            continue
        out[name] = {f: rec[f] for f in PHONE_FIELDS if f in rec}
    return out


def photo_problem(path: Path) -> str | None:
    """Why ``path`` cannot be a photo of the map (empty, not a JPEG or PNG, corrupt or
    truncated, 16-bit), or None when it decodes."""
    from PIL import Image, UnidentifiedImageError

    if path.stat().st_size == 0:
        return "an empty file (0 bytes)"
    try:
        with Image.open(path) as img:
            img.verify()
        with Image.open(path) as img:
            img.load()
            fmt, mode = img.format, img.mode
    except (OSError, UnidentifiedImageError, SyntaxError, ValueError) as exc:
        return f"not an image, or corrupt or truncated ({exc})"
    if fmt not in ("JPEG", "PNG"):
        return f"a {fmt} file; photos must be JPEG or PNG"
    if mode in ("I", "I;16", "I;16B", "I;16L", "I;16N", "F"):
        return f"16 bits or floats per pixel (mode {mode}); save it with 8 bits per channel"
    return None


def earlier_hashes(scene_dir: Path, round_index: int) -> dict[str, str]:
    """SHA-256 -> photo name of the photos of rounds before ``round_index`` (their logs'
    ``sha256``; photos without one are hashed)."""
    out: dict[str, str] = {}
    for k in range(round_index):
        cap = Path(scene_dir) / f"round_{k:03d}" / "capture"
        path = cap / "log.jsonl"
        if not path.is_file():
            continue
        for rec in photo_records(path):
            digest = rec.get("sha256")
            if digest is None and (cap / rec["image"]).is_file():
                digest = sha256_of(cap / rec["image"])
            if digest:
                out[digest] = _label(f"round_{k:03d}/capture/{rec['image']}", rec.get("source"))
    return out


def _source(src: Path, capture_dir: Path) -> str:
    """Where a photo came from, for its record: relative to the capture folder for the
    round's inbox (``inbox/IMG_0042.jpg``, as ``image`` is), else the path as given."""
    try:
        return Path(src).resolve().relative_to(Path(capture_dir).resolve()).as_posix()
    except ValueError:
        return str(src)


def _label(name: str, source: str | None) -> str:
    """A photo as the person knows it (its file name) and as the map names it."""
    return f"{Path(source).name} ({name})" if source else name


def _copy_photo(src: Path, dest: Path) -> None:
    """Copy ``src`` to ``dest`` complete or not at all, never over a file; read-only."""
    tmp = dest.with_name(f".{dest.name}.{os.getpid()}.part")
    try:
        shutil.copyfile(src, tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        publish(tmp, dest)
    finally:
        tmp.unlink(missing_ok=True)
    dest.chmod(stat.S_IRUSR | stat.S_IRGRP | stat.S_IROTH)


def _session(cfg: Config, round_index: int, source: Path, **extra) -> dict:
    cam = cfg.sim.camera
    return {
        "type": "session",
        "t": 0.0,
        "robot": cfg.robot,
        "scene": cfg.scene,
        "round": round_index,
        "started": dt.datetime.now().isoformat(timespec="seconds"),
        "source": str(source),
        **extra,
        "camera": {
            "model": "PINHOLE",
            "width": cam.width,
            "height": cam.height,
            "focal_px": None,
        },
        "config": cfg.model_dump(mode="json", include={"photos", "person_sim", "guide"}),
    }


def intake(
    clog: CaptureLog,
    capture_dir: Path,
    round_index: int,
    files: list[Path],
    seen: dict[str, str],
    extra: dict[str, dict] | None = None,
) -> tuple[int, list[str]]:
    """Copy ``files`` into ``capture_dir/images/`` as the round's photos and log each.

    Args:
        clog: the round's log.
        capture_dir: ``round_XXX/capture``.
        round_index: the round (the photos' names: ``rXXX_NNNN``).
        files: the person's photos, in order.
        seen: SHA-256 -> name of the photos taken before (updated).
        extra: per file name, fields to add to its record (the simulated person's truth).

    Returns:
        The photos taken in, and a line per photo left out (named, with the reason).
    """
    left_out: list[str] = []
    n = 0
    for src in files:
        problem = photo_problem(src)
        digest = sha256_of(src) if problem is None else None
        if problem is None and digest in seen:
            problem = f"the same bytes as {seen[digest]} (the same photo twice)"
        if problem is not None:
            left_out.append(f"{src}: {problem}")
            log.warning("%s: %s; left out of round %d (the file stays where it is)",
                        src, problem, round_index)  # fmt: skip
            clog.write({"type": "event", "t": float(n), "event": "photo_left_out",
                        "source": _source(src, capture_dir), "reason": problem})  # fmt: skip
            continue
        source = _source(src, capture_dir)
        suffix = ".png" if src.suffix.lower() == ".png" else ".jpg"
        image = f"images/r{round_index:03d}_{n:04d}{suffix}"
        _copy_photo(src, capture_dir / image)
        seen[digest] = _label(f"round_{round_index:03d}/capture/{image}", source)
        record = {"type": "photo", "t": float(n), "index": n, "image": image,
                  "source": source, "sha256": digest}  # fmt: skip
        record.update((extra or {}).get(src.name, {}))
        clog.write(record)
        n += 1
    return n, left_out


def _no_photos(where: Path, round_index: int, left_out: list[str], guide: Path | None) -> str:
    shots = f"the shots of {guide}" if guide is not None else "photos of the scene"
    msg = (
        f"round {round_index}: no photo in {where}/ to take in. Take {shots} and put them in "
        f"{where}/ (or upload them from a phone: python -m scenebot guide serve), then run "
        "snakemake again"
    )
    if round_index > 0:
        msg += (
            f"; shots you cannot take (behind a wall, out of reach): python -m scenebot guide "
            f"skip SHOT ... (the numbers on the guide page; a round of only skipped shots plans "
            "others); "
            f"to end the campaign with round {round_index - 1} instead: snakemake "
            f"--config max_rounds={round_index}"
        )
    if left_out:
        msg += ". Left out:\n  " + "\n  ".join(left_out)
    return msg


def run_folder_round(cfg: Config, capture_dir: Path) -> dict:
    """Round 0 of ``robot: guided``: the photos of ``photos.folder`` as the round's capture.

    Raises:
        InboxError: the folder holds no usable photo.
    """
    folder = Path(cfg.photos.folder)
    files = photo_files(folder)
    if not folder.is_dir() or not files:
        raise InboxError(
            f"photos.folder {folder} holds no photo (.jpg, .jpeg or .png): put the round-0 "
            "photos there, or point photos.folder at them"
        )
    return _take_in(cfg, Path(capture_dir), 0, files, folder, phone_records(folder, files))


def run_inbox_round(cfg: Config, capture_dir: Path, round_index: int) -> dict:
    """Round ``round_index`` >= 1 of a guided campaign: the photos in its inbox.

    The simulated person's record (``inbox/person-sim.jsonl``) adds each photo's truth and
    the shot it aimed at to its log record.

    Raises:
        InboxError: the inbox holds no usable photo (says where to put them).
    """
    capture_dir = Path(capture_dir)
    inbox = capture_dir / INBOX
    guide = capture_dir.parent.parent / f"round_{round_index - 1:03d}" / "guide" / "index.html"
    files = photo_files(inbox)
    skipped = _read_skipped(inbox)
    if not files and skipped:
        return _skipped_round(cfg, capture_dir, round_index, inbox, skipped)
    if not files:
        raise InboxError(_no_photos(inbox, round_index, [], guide))
    extra = phone_records(inbox, files)
    sim_log = inbox / PERSON_SIM_LOG
    if sim_log.is_file():
        for rec in read_log(sim_log):
            if rec.get("image"):
                extra[rec["image"]] = {
                    k: rec[k] for k in ("orientation", "motion", "truth", "aimed_shot") if k in rec
                }
    events = [_skipped_event(skipped)] if skipped else []
    return _take_in(cfg, capture_dir, round_index, files, inbox, extra, guide, events)


def _skipped_event(skipped: dict[int, str]) -> dict:
    """The capture log's record of the shots the person could not take."""
    return {"type": "event", "t": 0.0, "event": "shots_skipped",
            "shots": [{"rank": k, "reason": v} for k, v in sorted(skipped.items())]}  # fmt: skip


def _skipped_round(cfg: Config, capture_dir: Path, round_index: int, inbox: Path,
                   skipped: dict[int, str]) -> dict:  # fmt: skip
    """A round in which the person took none of the shots and said why (``skipped.json``):
    a capture without photos. The map stays as it was, the shots count as not fulfilled
    (the next guide asks for others), and the round counts as idle (``goals.patience`` such
    rounds in a row stop the campaign as stuck)."""
    with capture_lock(capture_dir):
        start_capture(capture_dir, keep=(INBOX,))
        with CaptureLog(capture_dir / SESSION_LOG) as clog:
            clog.write(_session(cfg, round_index, inbox))
            clog.write(_skipped_event(skipped))
            clog.write({"type": "end", "t": 0.0, "photos": 0, "left_out": 0,
                        "reason": f"the person took none of the shots ({len(skipped)} skipped: "
                        f"{inbox / SKIPPED})"})  # fmt: skip
        finish_capture(capture_dir, plot_person_capture, photo_dirs=())
    log.warning("round %d: no photo; the person could not take %d shots (%s): the next guide "
                "asks for others", round_index, len(skipped), inbox / SKIPPED)  # fmt: skip
    return {"photos": 0, "left_out": [], "skipped_shots": len(skipped), "source": str(inbox)}


def _take_in(cfg, capture_dir, round_index, files, source, extra=None, guide=None,
             events=()) -> dict:  # fmt: skip
    seen = earlier_hashes(capture_dir.parent.parent, round_index)
    with capture_lock(capture_dir):
        start_capture(capture_dir, keep=(INBOX,))
        with CaptureLog(capture_dir / SESSION_LOG) as clog:
            clog.write(_session(cfg, round_index, source))
            for ev in events:
                clog.write(ev)
            n, left_out = intake(clog, capture_dir, round_index, files, seen, extra)
            if n == 0:
                raise InboxError(_no_photos(source, round_index, left_out, guide))
            clog.write({"type": "end", "t": float(n), "photos": n, "left_out": len(left_out),
                        "reason": f"the photos of {source}"})  # fmt: skip
        finish_capture(capture_dir, plot_person_capture, photo_dirs=())
    return {"photos": n, "left_out": left_out, "source": str(source)}


# -------------------------------------------------------------------- the simulated person


def _person(cfg: Config, round_index: int):
    from scenebot.robot.person_sim import SimPerson
    from scenebot.scene.loader import load_world_scene

    scene = load_world_scene(cfg.world)
    return SimPerson(scene, cfg.person_sim, cfg.sim.camera, [cfg.seed, round_index], cfg.seed)


def run_perimeter_round(cfg: Config, capture_dir: Path) -> dict:
    """Round 0 of ``robot: person-sim``: the walk along the walls
    (:func:`~scenebot.robot.person_sim.perimeter_walk`), each photo taken with the person's
    error, logged with its truth; the session record holds the tape measurement between
    ``person_sim.tape_photos`` (``known_distance``: the map's metric scale)."""
    from scenebot.robot.person_sim import orientation_record, perimeter_walk, phone_motion

    capture_dir = Path(capture_dir)
    ps = cfg.person_sim
    person = _person(cfg, 0)
    walk = perimeter_walk(person, ps.perimeter_photos, ps.perimeter_inset_m)
    motion = phone_motion(person, "round_000")
    with capture_lock(capture_dir):
        start_capture(capture_dir)
        taken = []
        with CaptureLog(capture_dir / SESSION_LOG) as clog:
            clog.write(_session(cfg, 0, "perimeter walk", eye_height_m=person.eye_height_m))
            for i, aimed in enumerate(walk):
                shot = person.shoot(aimed)
                pose = shot.taken or aimed
                image = f"images/r000_{i:04d}.jpg"
                truth = person.take(pose, capture_dir / image)
                taken.append((image, pose))
                clog.write({"type": "photo", "t": float(i), "index": i, "image": image,
                            "sha256": sha256_of(capture_dir / image),
                            **orientation_record(person, pose),
                            **(motion.record(pose) if motion else {}), "truth": truth})  # fmt: skip
            tape = _tape(person, taken, ps)
            if tape is not None:
                clog.write({"type": "event", "t": float(len(taken)), "event": "known_distance",
                            **tape})  # fmt: skip
            clog.write({"type": "end", "t": float(len(taken)), "photos": len(taken),
                        "reason": "perimeter walk done"})  # fmt: skip
        finish_capture(capture_dir, plot_person_capture)
    return {"photos": len(taken), "eye_height_m": person.eye_height_m}


def _tape(person, taken: list[tuple[str, object]], ps) -> dict | None:
    """The tape measurement between the camera centres of ``ps.tape_photos`` (None when the
    walk has fewer photos)."""
    a, b = ps.tape_photos
    if max(a, b) >= len(taken):
        return None
    d = float(np.linalg.norm(taken[a][1].center - taken[b][1].center))
    d += float(person.rng.normal(0.0, ps.tape_std_m))
    return {"image_a": taken[a][0], "image_b": taken[b][0], "distance_m": round(d, 3),
            "how": "measured with a tape between where the person took the two photos"}  # fmt: skip


def run_person_sim_shots(cfg: Config, scene_dir: Path, round_index: int) -> dict:
    """The simulated person takes the shots of round ``round_index - 1``'s guide
    (``goals.json``) and puts the photos in round ``round_index``'s inbox, with
    ``person-sim.jsonl`` beside them (one record per shot: the photo or why it was skipped,
    and the truth).

    It reads the guide's map (``sfm/``) through its own photos: where they registered and
    where it truly took them (:func:`~scenebot.robot.person_sim.map_to_world`). An earlier
    attempt's photos in the inbox move to ``capture/superseded/<time>/inbox/``.
    """
    from scenebot.geometry import read_sparse_map
    from scenebot.robot.person_sim import (
        map_to_world,
        orientation_record,
        phone_motion,
        shot_in_world,
    )

    scene_dir = Path(scene_dir)
    prev = scene_dir / f"round_{round_index - 1:03d}"
    capture_dir = scene_dir / f"round_{round_index:03d}" / "capture"
    inbox = capture_dir / INBOX
    goals = json.loads((prev / "goals.json").read_text(encoding="utf-8"))["goals"]
    smap = read_sparse_map(prev / "sfm")
    truths = {}
    for k in range(round_index):
        cap = scene_dir / f"round_{k:03d}" / "capture"
        for rec in photo_records(cap / "log.jsonl"):
            if "truth" in rec:
                truths[f"round_{k:03d}/capture/{rec['image']}"] = rec["truth"]["center"]
    both = [i for i, n in enumerate(smap.names) if n in truths]
    sim = map_to_world(smap.centres[both], np.array([truths[smap.names[i]] for i in both]))
    person = _person(cfg, round_index)
    ps = cfg.person_sim
    motion = phone_motion(person, f"round_{round_index:03d}")
    _archive_inbox(capture_dir)
    inbox.mkdir(parents=True, exist_ok=True)
    records, n = [], 0
    for g in goals:
        aimed = shot_in_world(g, sim)
        for j in range(ps.photos_per_shot):
            offset = (j - (ps.photos_per_shot - 1) / 2) * math.radians(ps.fan_step_deg)
            want = type(aimed)(aimed.center, aimed.heading + offset, aimed.pitch)
            shot = person.shoot(want)
            rec = {"type": "shot", "aimed_shot": g["rank"], "photo_of_shot": j,
                   "aimed": _pose_dict(want), **shot.extra}  # fmt: skip
            if shot.taken is None:
                rec["skipped"] = shot.skipped
                log.info("shot %d skipped: %s", g["rank"], shot.skipped)
            else:
                name = f"person_r{round_index:03d}_{n:03d}.jpg"
                truth = person.take(shot.taken, inbox / name)
                truth["aimed"] = rec["aimed"]
                tracked = motion.record(shot.taken) if motion else {}
                rec |= {"image": name, **orientation_record(person, shot.taken), **tracked,
                        "truth": truth}  # fmt: skip
                n += 1
            records.append(rec)
    skipped = [r for r in records if "skipped" in r]
    taken = {r["aimed_shot"] for r in records if "image" in r}
    not_taken = {r["aimed_shot"]: r["skipped"] for r in skipped if r["aimed_shot"] not in taken}
    if not_taken:  # what a person says of the shots it could not take
        write_skipped(inbox, not_taken)
    tmp = inbox / f".{PERSON_SIM_LOG}.{os.getpid()}.part"
    tmp.write_text("".join(json.dumps(r) + "\n" for r in records), encoding="utf-8")
    os.replace(tmp, inbox / PERSON_SIM_LOG)
    return {"shots": len(goals), "photos": n, "skipped": len(skipped),
            "eye_height_m": person.eye_height_m, "map_to_world_scale": sim[0]}  # fmt: skip


def _pose_dict(p) -> dict:
    return {"center": [float(v) for v in p.center], "heading": float(p.heading),
            "pitch": float(p.pitch)}  # fmt: skip


def _archive_inbox(capture_dir: Path) -> None:
    """Move an earlier simulated person's photos out of the inbox (never deleted)."""
    inbox = capture_dir / INBOX
    old = [p for p in inbox.iterdir()] if inbox.is_dir() else []
    if not old:
        return
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    dest = capture_dir / SUPERSEDED / stamp / INBOX
    k = 1
    while dest.exists():
        dest = capture_dir / SUPERSEDED / f"{stamp}-{k}" / INBOX
        k += 1
    dest.mkdir(parents=True)
    for p in old:
        os.rename(p, dest / p.name)
    log.warning("the simulated person's earlier photos in %s moved to %s", inbox, dest)


# ------------------------------------------------------------------------------ picture


def plot_person_capture(log_path: Path, png: Path) -> Path:
    """The picture of a person's round: with the simulator's truth, the true camera
    positions and headings from above (a picture for people, not an input to a decision);
    else a contact sheet of the photos."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    log_path = Path(log_path)
    cap = log_path.parent
    photos = photo_records(log_path)
    left = [r for r in read_log(log_path) if r.get("event") == "photo_left_out"]
    title = f"{cap.parent.name}: {len(photos)} photos taken in, {len(left)} left out"
    if photos and all("truth" in p for p in photos):
        fig, ax = plt.subplots(figsize=(7, 6), dpi=100)
        for p in photos:
            c = np.array(p["truth"]["center"])
            f = np.array(p["truth"]["R_cam_from_world"])[2]
            ax.arrow(c[0], c[1], 0.3 * f[0], 0.3 * f[1], width=0.01, color="tab:green",
                     length_includes_head=True)  # fmt: skip
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(title + " (true poses, world frame)", fontsize=9)
    else:
        n = max(len(photos), 1)
        cols = min(8, n)
        rows = min(6, math.ceil(n / cols))
        fig, axes = plt.subplots(rows, cols, figsize=(1.6 * cols, 1.3 * rows + 0.4), dpi=100,
                                 squeeze=False)  # fmt: skip
        for ax, p in zip(axes.ravel(), photos, strict=False):
            with Image.open(cap / p["image"]) as im:
                im.thumbnail((160, 120))
                ax.imshow(np.asarray(im.convert("RGB")))
            ax.set_title(Path(p["image"]).name, fontsize=6)
        for ax in axes.ravel():
            ax.axis("off")
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)
    return png
