"""``scenebot guide serve``: the current round's guide page for a phone, and the photos it
takes back into the next round's inbox (Flask).

* ``GET /``: the guide page of the round (the latest ``round_XXX/guide/index.html`` under the
  campaign's folder, looked up at each request, or the round asked for);
* ``GET /api/status``: the round, the inbox and the upload limit (JSON; the page shows its
  upload form when this answers);
* ``POST /upload``: photos (multipart form, any field name) into the inbox
  (:func:`scenebot.artifacts.inbox_dir`: the next round's ``capture/inbox/``);
* ``POST /skip``: ``{"shot": N}`` (JSON or form): a shot the person cannot take, into the
  inbox's ``skipped.json`` (:mod:`scenebot.artifacts.skipped`); the page's "I cannot take this
  shot" button sends it, and ``/api/status`` lists the shots marked so.

Each photo is checked before it is written (:func:`save_photo`): a plain file name (no
folder), at most ``guide.max_upload_mb``, a JPEG or PNG that decodes. A photo is never
overwritten: a name already in the inbox (or the round's images) gets ``-1``, ``-2``, ...
before its suffix. Each refusal is a message naming the photo. The answer is JSON (the page's
script asks for it) or, to a plain form post, a short HTML page.

It listens on ``guide.host`` (127.0.0.1 unless ``--host`` says otherwise: 0.0.0.0 lets a phone
on the same network in, and anyone else on it).
"""

from __future__ import annotations

import html
import json
import logging
import os
import re
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from scenebot.artifacts import inbox_dir, round_dir
from scenebot.artifacts.skipped import read_skipped, write_skipped
from scenebot.guide.config import GuideConfig

log = logging.getLogger(__name__)

MB = 1_000_000
JPEG_MAGIC = b"\xff\xd8\xff"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SUFFIXES = {"jpeg": (".jpg", ".jpeg"), "png": (".png",)}
"""The suffixes a saved photo keeps, per format (the first is added to a name without one)."""
MAX_NAME = 200
"""Longest file name taken (characters)."""


class GuideNotFound(FileNotFoundError):
    """No guide page to serve (the message says which and how to make one)."""


def guide_rounds(scene_dir: Path) -> list[int]:
    """The rounds with a guide page under ``scene_dir``, in order."""
    out = []
    for d in Path(scene_dir).glob("round_*"):
        m = re.fullmatch(r"round_(\d+)", d.name)
        if m and (d / "guide" / "index.html").is_file():
            out.append(int(m.group(1)))
    return sorted(out)


def check_shots(scene_dir: Path, r: int, shots: list, shown: str | None = None) -> None:
    """Whether round ``r``'s guide (its goals.json) has the ``shots`` (ranks, the numbers on
    its page). Raises ValueError naming the ones it lacks (``shown``: as the person gave
    them) and its shots."""
    goals = round_dir(scene_dir, r) / "goals.json"
    ranks = sorted(g["rank"] for g in json.loads(goals.read_text(encoding="utf-8"))["goals"])
    wrong = [k for k in shots if k not in ranks]
    if wrong:
        raise ValueError(
            f"round_{r:03d}'s guide has no shot {shown or ', '.join(map(str, wrong))}: its "
            f"shots are {', '.join(map(str, ranks))} (the numbers on its guide page)"
        )


def current_round(scene_dir: Path, round_: int | None = None) -> int:
    """The round whose guide is served: ``round_``, else the latest with a guide page.

    Raises:
        GuideNotFound: no such page.
    """
    rounds = guide_rounds(scene_dir)
    if round_ is not None:
        if round_ not in rounds:
            raise GuideNotFound(
                f"{round_dir(scene_dir, round_)}/guide/index.html does not exist: run snakemake "
                "for that round (robot: photos) first"
            )
        return round_
    if not rounds:
        raise GuideNotFound(
            f"no guide page under {scene_dir} (round_XXX/guide/index.html): run snakemake with "
            "robot: photos first, or give --scene-dir"
        )
    return rounds[-1]


@dataclass
class Upload:
    """What became of one uploaded photo.

    Attributes:
        name: the name it was sent with.
        saved_as: the file written (None: refused).
        message: a sentence naming the photo (what was done, or why not).
    """

    name: str
    saved_as: Path | None
    message: str

    @property
    def ok(self) -> bool:
        return self.saved_as is not None


def name_problem(name: str) -> str | None:
    """Why ``name`` is not a plain file name to save a photo under, or None."""
    if not name or not name.strip():
        return "has no file name"
    if "/" in name or "\\" in name:
        return "has a folder in its name; send the file by its name alone"
    if name in (".", "..") or name.startswith("."):
        return "has a hidden or relative name (it starts with a dot)"
    if any(ord(c) < 32 or ord(c) == 127 for c in name):
        return "has control characters in its name"
    if len(name) > MAX_NAME:
        return f"has a name longer than {MAX_NAME} characters"
    return None


def image_format(data: bytes) -> str | None:
    """ "jpeg" or "png" when ``data`` is a JPEG or PNG that decodes, else None."""
    import cv2
    import numpy as np

    if data.startswith(JPEG_MAGIC):
        fmt = "jpeg"
    elif data.startswith(PNG_MAGIC):
        fmt = "png"
    else:
        return None
    # decoded at an eighth of the size: a whole check of the stream, in a fraction of the time
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_REDUCED_GRAYSCALE_8)
    return fmt if img is not None and img.size > 0 else None


def _with_suffix(name: str, fmt: str) -> str:
    """``name`` with a suffix of its format (added, or put in place of another one)."""
    stem, suffix = os.path.splitext(name)
    if suffix.lower() in SUFFIXES[fmt]:
        return name
    if suffix.lower() in {s for v in SUFFIXES.values() for s in v}:
        return stem + SUFFIXES[fmt][0]  # a PNG sent as .jpg (or the other way round)
    return name + SUFFIXES[fmt][0]


def _write_new(folder: Path, name: str, data: bytes, taken: set[str]) -> Path:
    """Write ``data`` under ``name`` in ``folder``, or ``stem-1.ext``, ``stem-2.ext``, ...
    when that name exists there or is in ``taken``; never over a file (exclusive create)."""
    stem, suffix = os.path.splitext(name)
    k = 0
    while True:
        candidate = name if k == 0 else f"{stem}-{k}{suffix}"
        path = folder / candidate
        if candidate not in taken:
            try:
                fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                pass
            else:
                with os.fdopen(fd, "wb") as f:
                    f.write(data)
                return path
        k += 1


def save_photo(inbox: Path, name: str, stream: IO[bytes], max_bytes: int,
               keep_clear_of: set[str] | None = None) -> Upload:  # fmt: skip
    """Check one uploaded photo and write it into ``inbox`` (created if missing).

    Args:
        inbox: the folder.
        name: the file name it was sent with.
        stream: its bytes.
        max_bytes: the largest photo taken.
        keep_clear_of: more names not to use (the photos of the round already registered).

    Returns:
        What was done, with a message naming the photo.
    """
    problem = name_problem(name)
    if problem:
        return Upload(name, None, f"{name!r}: refused: it {problem}.")
    data = stream.read(max_bytes + 1)
    if len(data) > max_bytes:
        return Upload(name, None, f"{name}: refused: larger than the limit of "
                      f"{max_bytes / MB:g} MB (guide.max_upload_mb).")  # fmt: skip
    if not data:
        return Upload(name, None, f"{name}: refused: the file is empty.")
    fmt = image_format(data)
    if fmt is None:
        return Upload(name, None, f"{name}: refused: not a JPEG or PNG photo (it does not "
                      "decode as one).")  # fmt: skip
    inbox.mkdir(parents=True, exist_ok=True)
    target = _with_suffix(name, fmt)
    path = _write_new(inbox, target, data, keep_clear_of or set())
    why = ([f"the suffix of a {fmt.upper()}"] if target != name else []) + (
        [f"a photo named {target} is there already"] if path.name != target else []
    )
    note = f" as {path.name} ({'; '.join(why)})" if why else ""
    log.info("guide serve: %s saved%s to %s", name, note, inbox)
    return Upload(name, path, f"{name}: saved{note} in {inbox}.")


def create_app(cfg: GuideConfig, scene_dir: Path, round_: int | None = None):
    """The Flask app of ``scenebot guide serve``.

    Args:
        cfg: guide settings (upload limits).
        scene_dir: the campaign's folder (``results/<scene>``).
        round_: serve this round's guide (default: the latest, looked up at each request).
    """
    from flask import Flask, jsonify, request, send_file
    from werkzeug.exceptions import RequestEntityTooLarge

    max_bytes = int(cfg.max_upload_mb * MB)
    app = Flask("scenebot.guide")
    # the request as a whole (werkzeug refuses more before any photo is looked at)
    app.config["MAX_CONTENT_LENGTH"] = cfg.max_request_photos * max_bytes + MB
    scene_dir = Path(scene_dir)

    def where() -> tuple[int, Path]:
        r = current_round(scene_dir, round_)
        return r, inbox_dir(scene_dir, r)

    def wants_json() -> bool:
        best = request.accept_mimetypes.best_match(["application/json", "text/html"])
        return best == "application/json"

    @app.errorhandler(GuideNotFound)
    def _no_guide(exc):
        return (jsonify(error=str(exc)), 404) if wants_json() else (html.escape(str(exc)), 404)

    @app.errorhandler(RequestEntityTooLarge)
    def _too_large(exc):
        msg = (
            f"the upload is larger than {app.config['MAX_CONTENT_LENGTH'] / MB:g} MB "
            f"({cfg.max_request_photos} photos of at most {cfg.max_upload_mb:g} MB: "
            "guide.max_request_photos, guide.max_upload_mb); send fewer photos at once"
        )
        return jsonify(error=msg, accepted=[], rejected=[]), 413

    @app.get("/")
    def index():
        r, _ = where()
        page = round_dir(scene_dir, r) / "guide" / "index.html"
        resp = send_file(page.resolve(), mimetype="text/html", max_age=0)
        resp.headers["Cache-Control"] = "no-store"  # a new round's page shows on reload
        return resp

    @app.get("/favicon.ico")
    def favicon():
        return "", 204  # the page has its own (none): browsers ask anyway

    @app.get("/api/status")
    def status():
        r, inbox = where()
        photos = sorted(p.name for p in inbox.iterdir()) if inbox.is_dir() else []
        try:
            skipped = sorted(read_skipped(inbox))
        except ValueError as exc:
            skipped, photos = [], [*photos, str(exc)]
        return jsonify(round=f"round_{r:03d}", inbox=inbox.as_posix() + "/",
                       max_upload_mb=cfg.max_upload_mb, photos_in_inbox=photos,
                       skipped=skipped)  # fmt: skip

    @app.post("/skip")
    def skip():
        r, inbox = where()
        body = request.get_json(silent=True) or request.form
        try:
            rank = int(body.get("shot"))
        except (TypeError, ValueError):
            rank = None
        try:
            check_shots(scene_dir, r, [rank], shown=repr(body.get("shot")))
        except ValueError as exc:
            return jsonify(error=f'{exc}; send {{"shot": N}}'), 400
        reason = str(body.get("reason") or "marked on the guide page")[:200]
        try:
            write_skipped(inbox, {rank: reason})
            skipped = sorted(read_skipped(inbox))
        except ValueError as exc:
            return jsonify(error=str(exc)), 409
        log.info("guide serve: shot %d of round_%03d marked as not taken", rank, r)
        return jsonify(round=f"round_{r:03d}", skipped=skipped,
                       message=f"shot {rank} marked as not taken: the next guide asks for "
                       "another")  # fmt: skip

    @app.post("/upload")
    def upload():
        r, inbox = where()
        files = [f for _, f in request.files.items(multi=True)]
        if not files:
            msg = "no photo in the upload (a multipart form with one file field or more)"
            return jsonify(error=msg, accepted=[], rejected=[]), 400
        images = inbox.parent / "images"
        registered = {p.name for p in images.iterdir()} if images.is_dir() else set()
        results = [save_photo(inbox, f.filename or "", f.stream, max_bytes, registered)
                   for f in files]  # fmt: skip
        accepted = [{"name": u.name, "saved_as": u.saved_as.name, "message": u.message}
                    for u in results if u.ok]  # fmt: skip
        rejected = [{"name": u.name, "message": u.message} for u in results if not u.ok]
        for u in results:
            if not u.ok:
                log.warning("guide serve: %s", u.message)
        code = 422 if rejected else 200
        if wants_json():
            return jsonify(round=f"round_{r:03d}", inbox=inbox.as_posix() + "/",
                           accepted=accepted, rejected=rejected), code  # fmt: skip
        items = "".join(f"<li>{html.escape(u.message)}</li>" for u in results)
        return (f"<!DOCTYPE html><meta charset='utf-8'><meta name='viewport' "
                f"content='width=device-width'><ul>{items}</ul><a href='./'>back to the "
                "guide</a>"), code  # fmt: skip

    return app


def lan_address() -> str | None:
    """This computer's address on its network (the interface of the default route; nothing
    is sent), None when there is none."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.connect(("10.255.255.255", 1))
        return s.getsockname()[0]
    except OSError:
        return None
    finally:
        s.close()


def serve(cfg: GuideConfig, scene_dir: Path, round_: int | None = None) -> None:
    """Serve the guide on ``cfg.host``:``cfg.port`` until interrupted (Ctrl-C).

    Raises:
        GuideNotFound: no guide page to serve yet.
    """
    from werkzeug.serving import make_server

    r = current_round(scene_dir, round_)  # fails early, with the message
    app = create_app(cfg, scene_dir, round_)
    server = make_server(cfg.host, cfg.port, app, threaded=True)
    port = server.socket.getsockname()[1]
    hosts = [cfg.host]
    if cfg.host in ("0.0.0.0", "::"):
        hosts = [h for h in (lan_address(), "127.0.0.1") if h]
    print(f"guide of round_{r:03d} ({scene_dir}); photos go to {inbox_dir(scene_dir, r)}/")
    for h in hosts:
        print(f"  open http://{h}:{port}/")
    if cfg.host in ("127.0.0.1", "localhost", "::1"):
        print("  (this computer only: --host 0.0.0.0 lets a phone on the same network in)")
    print("Ctrl-C stops.", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
