"""Which shots of the guide a round's photos fulfilled (``round_XXX/fulfilment.json``).

A guided round's photos (``robot: guided``, ``person-sim``) were taken following the
previous round's guide page. After the round's map is built, each photo is compared with
each shot of the previous round's ``goals.json``: it *fulfils* a shot when its camera centre
lies within ``guide.fulfil_distance_m`` of the shot's, its heading within
``guide.fulfil_heading_deg`` and its tilt within ``guide.fulfil_pitch_deg``. The shots are in
the previous map's frame and a person's frame is fixed anew each round (origin below the
cameras' centroid), so they are moved into this round's frame by the similarity that
carries the previous round's photos from the one map to the other.

A photo that fulfils no shot is kept (it still adds to the map) and named; one that did not
register is named with the sfm stage's reason. The messages go to the log and the file.

A shot no photo fulfilled is *unfulfilled* (``unfulfilled``: its place in this round's frame):
the person could not stand there (behind a wall the map lacks, inside furniture), did not
take it, or took a photo that did not register there. The goals stage does not ask for a view
near it again (as it does with the goals a robot abandoned: :mod:`scenebot.goals.failures`);
the previous round's unfulfilled shots are carried into this round's frame with the shots, so
the list holds every round's so far.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.capturelog import json_default, photo_records, skipped_shots
from scenebot.geometry import similarity_fit, view_direction
from scenebot.guide.config import GuideConfig

log = logging.getLogger(__name__)


@dataclass
class FulfilInputs:
    """Inputs: this round's map (``sfm_dir``) and its ``report.json`` (``sfm_report``: the
    photos not registered and why), the previous round's map (``previous_sfm_dir``) and
    shots (``goals_json``), this round's capture log (``capture_log``)."""

    sfm_dir: Path
    previous_sfm_dir: Path
    goals_json: Path
    capture_log: Path
    sfm_report: Path
    previous_fulfilment_json: Path | None = None  # round r-1's (its unfulfilled shots)


@dataclass
class FulfilOutputs:
    """``fulfilment_json``: ``round_XXX/fulfilment.json``."""

    fulfilment_json: Path


def _cameras(sfm_dir: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Name -> (camera centre (3,), optical axis (3,)) of the registered photos."""
    import pycolmap

    rec = pycolmap.Reconstruction(str(sfm_dir))
    out = {}
    for i in rec.reg_image_ids():
        im = rec.image(i)
        out[im.name] = (
            np.asarray(im.projection_center(), float),
            np.asarray(im.cam_from_world().rotation.matrix(), float)[2],
        )
    return out


def _heading_pitch(axis: np.ndarray) -> tuple[float, float]:
    return math.atan2(axis[1], axis[0]), math.asin(float(np.clip(axis[2], -1.0, 1.0)))


def _angle_deg(a: float) -> float:
    return abs(math.degrees(math.remainder(a, 2 * math.pi)))


def _moved(sim, x: float, y: float, z: float) -> np.ndarray:
    """The point (x, y, z) moved by the similarity ``sim`` = (s, R, t)."""
    s, R, t = sim
    return s * R @ np.array([x, y, z], float) + t


def shots_in_frame(goals: list[dict], sim) -> list[dict]:
    """The shots (goals.json: x, y, z, theta, pitch) moved by the similarity ``sim`` =
    (s, R, t): ``rank``, ``center`` (3,), ``heading`` and ``pitch`` (rad)."""
    R = sim[1]
    out = []
    for g in goals:
        c = _moved(sim, g["x"], g["y"], g.get("z", 0.0))
        h, p = _heading_pitch(R @ view_direction(g["theta"], g.get("pitch", 0.0)))
        out.append({"rank": g["rank"], "center": c, "heading": h, "pitch": p})
    return out


def carried_unfulfilled(path: Path | None, sim) -> list[dict]:
    """The unfulfilled shots of the previous fulfilment.json (its frame) moved into this
    round's by the similarity ``sim`` = (s, R, t); none without the file."""
    if path is None or not Path(path).is_file():
        return []
    out = []
    for u in json.loads(Path(path).read_text(encoding="utf-8")).get("unfulfilled", []):
        c = _moved(sim, u["x"], u["y"], u.get("z", 0.0))
        out.append({**u, "x": float(c[0]), "y": float(c[1]), "z": float(c[2])})
    return out


def compare(center: np.ndarray, axis: np.ndarray, shot: dict) -> dict:
    """How far a photo (centre, optical axis) is from a shot: ``distance`` (map units),
    ``heading_deg``, ``pitch_deg``."""
    h, p = _heading_pitch(axis)
    return {
        "distance": float(np.linalg.norm(center - shot["center"])),
        "heading_deg": _angle_deg(h - shot["heading"]),
        "pitch_deg": abs(math.degrees(p - shot["pitch"])),
    }


def fulfils(d: dict, cfg: GuideConfig) -> bool:
    """Whether a comparison (:func:`compare`) is within the tolerances of ``cfg``."""
    return (
        d["distance"] <= cfg.fulfil_distance_m
        and d["heading_deg"] <= cfg.fulfil_heading_deg
        and d["pitch_deg"] <= cfg.fulfil_pitch_deg
    )


def run(cfg: GuideConfig, inputs: FulfilInputs, outputs: FulfilOutputs) -> dict:
    """Write ``fulfilment.json``: per photo the shots it fulfilled (or why none, or why it
    did not register), per shot the photos that fulfilled it, and a summary.

    Raises:
        ValueError: fewer than 3 photos of the previous round in both maps (the shots cannot
            be carried into this round's frame).
    """
    cams = _cameras(inputs.sfm_dir)
    prev = _cameras(inputs.previous_sfm_dir)
    common = sorted(cams.keys() & prev.keys())
    if len(common) < 3:
        raise ValueError(
            f"{inputs.sfm_dir}: only {len(common)} photos of the previous map "
            f"{inputs.previous_sfm_dir} are in this round's map; the guide's shots cannot be "
            "placed in it"
        )
    sim = similarity_fit(
        np.array([prev[n][0] for n in common]), np.array([cams[n][0] for n in common])
    )
    goals_doc = json.loads(Path(inputs.goals_json).read_text(encoding="utf-8"))
    shots = shots_in_frame(goals_doc.get("goals", []), sim)
    report = json.loads(Path(inputs.sfm_report).read_text(encoding="utf-8"))
    dropped = report.get("dropped", {})
    capture = Path(inputs.capture_log).parent
    rnd = capture.parent.name
    guide = f"{Path(inputs.goals_json).parent.name}/guide/index.html"
    tol = {"distance": cfg.fulfil_distance_m, "heading_deg": cfg.fulfil_heading_deg,
           "pitch_deg": cfg.fulfil_pitch_deg}  # fmt: skip
    photos, messages = [], []
    by_shot: dict[int, list[str]] = {s["rank"]: [] for s in shots}
    for rec in photo_records(inputs.capture_log):
        name = f"{rnd}/capture/{rec['image']}"
        label = _label(rec)
        row = {"image": name, "source": rec.get("source"), "registered": name in cams,
               "fulfils": [], "nearest_shot": None}  # fmt: skip
        if "aimed_shot" in rec:
            row["aimed_shot"] = rec["aimed_shot"]
        if name not in cams:
            why = dropped.get(name, "not in the map")
            row["message"] = (
                f"{label} did not register ({why}): it adds nothing to the map. Take it again "
                "with more overlap: a step nearer a photo already taken, the same things in view"
            )
            messages.append(row["message"])
            photos.append(row)
            continue
        c, axis = cams[name]
        near = None
        for shot in shots:
            d = compare(c, axis, shot)
            if fulfils(d, cfg):
                row["fulfils"].append(shot["rank"])
                by_shot[shot["rank"]].append(name)
            if near is None or d["distance"] < near["distance"]:
                near = {"rank": shot["rank"], **d}
        row["nearest_shot"] = near
        if not row["fulfils"]:
            where = (
                f"the nearest, shot {near['rank']}, is {near['distance']:.2f} away, "
                f"{near['heading_deg']:.0f} deg off in heading and {near['pitch_deg']:.0f} deg "
                f"in tilt (guide.fulfil_distance_m = {cfg.fulfil_distance_m}, "
                f"fulfil_heading_deg = {cfg.fulfil_heading_deg}, fulfil_pitch_deg = "
                f"{cfg.fulfil_pitch_deg})"
                if near is not None
                else "the guide had no shot"
            )
            row["message"] = (
                f"{label} fulfils no shot of {guide}: {where}. It is kept: it still adds to the map"
            )
            messages.append(row["message"])
        photos.append(row)
    for m in messages:
        log.warning("%s", m)
    shot_rows = [
        {"rank": s["rank"], "fulfilled_by": by_shot[s["rank"]], "x": float(s["center"][0]),
         "y": float(s["center"][1]), "z": float(s["center"][2]), "heading": s["heading"],
         "pitch": s["pitch"]}
        for s in shots
    ]  # fmt: skip
    asked = Path(inputs.goals_json).parent.name
    skipped = skipped_shots(inputs.capture_log)
    for s in shot_rows:
        if s["rank"] in skipped:
            s["skipped"] = skipped[s["rank"]]

    def why(s: dict) -> str:
        if "skipped" in s:
            return f"skipped: the person could not take shot {s['rank']} ({s['skipped']})"
        return f"unfulfilled: no photo of {rnd} fulfilled shot {s['rank']} of {guide}"

    unfulfilled = carried_unfulfilled(inputs.previous_fulfilment_json, sim) + [
        {"round": asked, "rank": s["rank"], "x": s["x"], "y": s["y"], "z": s["z"],
         "reason": why(s)}
        for s in shot_rows if not s["fulfilled_by"]
    ]  # fmt: skip
    summary = {
        "shots": len(shots),
        "fulfilled": sum(1 for s in shot_rows if s["fulfilled_by"]),
        "skipped": sum(1 for s in shot_rows if "skipped" in s),
        "photos": len(photos),
        "registered": sum(1 for p in photos if p["registered"]),
        "fulfilling_none": sum(1 for p in photos if p["registered"] and not p["fulfils"]),
        "not_registered": sum(1 for p in photos if not p["registered"]),
        "unfulfilled_so_far": len(unfulfilled),
    }
    doc = {
        "round": rnd,
        "guide": guide,
        "tolerances": tol,
        "units": "map units (metres with a metric scale)",
        "frame": {"previous_photos_matched": len(common), "scale": sim[0]},
        "summary": summary,
        "shots": shot_rows,
        "unfulfilled": unfulfilled,
        "photos": photos,
        "messages": messages,
    }
    out = Path(outputs.fulfilment_json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1, default=json_default) + "\n", encoding="utf-8")
    log.info("%s: %d of %d shots fulfilled by %d photos (%d fulfil none, %d not registered)",
             rnd, summary["fulfilled"], summary["shots"], summary["photos"],
             summary["fulfilling_none"], summary["not_registered"])  # fmt: skip
    return doc


def _label(rec: dict) -> str:
    """A photo as the person knows it: its file name where it came from, and its name in
    the round."""
    src = rec.get("source")
    return f"{Path(src).name} ({rec['image']})" if src else rec["image"]
