"""The campaign summary: ``results/{scene}/campaign.json`` and ``campaign.png``.

Per round: photos taken (and in all), photos the map registered, the best remaining score
(``goals.json``: the largest predicted angular error of a candidate view, degrees; below
``goals.complete_threshold_deg`` the map is complete), and for adaptive rounds the goals
reached, abandoned and skipped with their reasons, and for a person's guided rounds the
shots of the previous guide its photos fulfilled (``fulfilment.json``). Why the campaign
stopped: a round's goals said complete, or ``max_rounds`` was reached.

Simulator only, under ``evaluation`` (never an input to a decision): how far the robot
really stopped from each goal it reported reached (its true position mapped into the map
frame through the similarity of the previous round's ``sfm/accuracy.json``), and the error of
the visual fixes taken on the way.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from scenebot.capturelog import map_fingerprint, read_log


def _load(p: Path) -> dict | None:
    return json.loads(p.read_text(encoding="utf-8")) if p.exists() else None


def _world_to_map(similarity: dict):
    """Inverse of the map->world similarity ``x_w = s R x_m + t`` (evaluation only)."""
    s = float(similarity["scale"])
    R = np.asarray(similarity["R"], float)
    t = np.asarray(similarity["t"], float)

    def f(xyz):
        return (R.T @ (np.asarray(xyz, float) - t)) / s

    return f


def _camera_height_world(similarity: dict) -> float:
    return float(similarity["t"][2])


def _round_evaluation(records: list[dict], prev_accuracy: dict | None, reach_m: float) -> dict:
    """Truth-based figures of an adaptive round (simulator logs only)."""
    if prev_accuracy is None or "similarity" not in prev_accuracy:
        return {"evaluated": False, "note": "no true poses (real robot) or no map accuracy"}
    to_map = _world_to_map(prev_accuracy["similarity"])
    z = _camera_height_world(prev_accuracy["similarity"])
    goal_err, fix_err, fix_head = [], [], []
    for r in records:
        tr = r.get("truth")
        if tr is None:
            continue
        rob = tr.get("robot", tr)
        true_map = to_map([rob["x"], rob["y"], z])[:2]
        # the goal where the robot drove (``driven_goal``: the one asked for, or where the
        # planner moved it off an obstacle cell)
        target = r.get("driven_goal") or r.get("robot_goal")
        if r.get("event") == "goal_reached" and target is not None:
            target = np.asarray(target, float)
            goal_err.append(float(np.hypot(*(true_map - target))))
        if r.get("event") == "localize" and "localization" in r:
            c = r["localization"]["center"]
            cam = tr.get("center")
            if cam is not None:
                fix_err.append(float(np.hypot(*(to_map(cam)[:2] - np.asarray(c[:2])))))
            est_h = r["localization"].get("heading")
            if est_h is not None and "theta" in rob:
                yaw = math.atan2(prev_accuracy["similarity"]["R"][1][0],
                                 prev_accuracy["similarity"]["R"][0][0])  # fmt: skip
                d = (est_h + yaw - rob["theta"] + math.pi) % (2 * math.pi) - math.pi
                fix_head.append(abs(math.degrees(d)))
    out: dict = {"evaluated": True, "goals_with_truth": len(goal_err)}
    if goal_err:
        g = np.array(goal_err)
        out["goal_true_error_m"] = {"median": float(np.median(g)), "max": float(g.max())}
        out["goals_within_m"] = reach_m
        out["goals_truly_within"] = int((g <= reach_m).sum())
    if fix_err:
        f = np.array(fix_err)
        out["fix_error_cm"] = {
            "n": len(f),
            "median": 100 * float(np.median(f)),
            "p90": 100 * float(np.percentile(f, 90)),
        }
    if fix_head:
        h = np.array(fix_head)
        out["fix_heading_error_deg"] = {
            "median": float(np.median(h)),
            "p90": float(np.percentile(h, 90)),
        }
    return out


def summarize(scene_dir: Path, rounds: list[int], max_rounds: int, reach_m: float = 0.10) -> dict:
    """The campaign summary of ``rounds`` (written by :func:`write`).

    Args:
        scene_dir: ``results/{scene}``.
        rounds: the rounds the campaign ran (0, 1, ...).
        max_rounds: the configured limit.
        reach_m: a goal counts as truly reached within this distance (evaluation).
    """
    scene_dir = Path(scene_dir)
    out_rounds = []
    total = 0
    for r in rounds:
        rd = scene_dir / f"round_{r:03d}"
        log_path = rd / "capture" / "log.jsonl"
        records = list(read_log(log_path)) if log_path.exists() else []
        photos = sum(1 for x in records if x.get("type") == "photo")
        if not records:  # bring-your-own photos: the sfm report counts them
            photos = (_load(rd / "sfm" / "report.json") or {}).get("photos", 0)
        total += photos
        sfm = _load(rd / "sfm" / "report.json") or {}
        goals = _load(rd / "goals.json") or {}
        entry = {
            "round": r,
            "photos": photos,
            "photos_total": total,
            "registered": sfm.get("registered"),
            "registered_of": sfm.get("photos"),
            "mapping_mode": sfm.get("mapping_mode"),
            "best_remaining_score_deg": goals.get("best_score_deg"),
            "complete": goals.get("complete"),
            "complete_because": goals.get("complete_because"),
            "goals_chosen": len(goals.get("goals", [])),
        }
        fulfilment = _load(rd / "fulfilment.json")  # a guided round: the guide's shots
        if fulfilment is not None:
            entry["shots_fulfilled"] = fulfilment["summary"]
        acc = _load(rd / "sfm" / "accuracy.json")
        if acc and acc.get("evaluated"):
            entry["sfm_position_error_cm_median"] = acc["position_error_cm"]["median"]
            entry["sfm_heading_error_deg_median"] = acc["heading_error_deg"]["median"]
        if r > 0:
            end = next((x for x in records if x.get("type") == "end"), {})
            entry["goals_visited"] = {
                k: end.get(k) for k in ("goals", "reached", "abandoned", "skipped")
            }
            entry["goal_outcomes"] = end.get("outcomes", [])
            prev_sfm = scene_dir / f"round_{r - 1:03d}" / "sfm"
            prev_acc = _load(prev_sfm / "accuracy.json")
            entry["evaluation"] = _round_evaluation(records, prev_acc, reach_m)
            session = next((x for x in records if x.get("type") == "session"), {})
            sha1 = session.get("map_sha1")
            if sha1 and (prev_sfm / "images.bin").exists() and map_fingerprint(prev_sfm) != sha1:
                entry["evaluation"]["stale"] = (
                    f"{prev_sfm} was rebuilt after this round was driven with it: the "
                    "truth-based figures compare against the new map, not the one used"
                )
        out_rounds.append(entry)
    last = out_rounds[-1] if out_rounds else {}
    if last.get("complete"):
        why = last.get("complete_because")
        reason = f"round {last['round']}'s goals.json says the map is complete" + (
            f": {why}" if why else ""
        )
    elif len(rounds) >= max_rounds:
        reason = f"max_rounds = {max_rounds} reached"
    else:
        reason = "stopped early"
    return {
        "scene": scene_dir.name,
        "rounds": out_rounds,
        "photos_total": total,
        "stopped_because": reason,
        "max_rounds": max_rounds,
    }


def plot(summary: dict, png: Path) -> Path:
    """Photos, registered photos and best remaining score per round."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rs = summary["rounds"]
    x = [r["round"] for r in rs]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4), dpi=100)
    a1.bar([i - 0.2 for i in x], [r["photos_total"] for r in rs], 0.4, label="photos (all)")
    a1.bar([i + 0.2 for i in x], [r["registered"] or 0 for r in rs], 0.4, label="registered")
    a1.set_xlabel("round")
    a1.set_ylabel("photos")
    a1.set_xticks(x)
    a1.legend()
    a2.plot(x, [r["best_remaining_score_deg"] for r in rs], "o-")
    a2.set_xlabel("round")
    a2.set_ylabel("best remaining score (deg)")
    a2.set_xticks(x)
    a2.set_title(summary["stopped_because"], fontsize=9)
    fig.suptitle(f"campaign {summary['scene']}: {summary['photos_total']} photos")
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)
    return Path(png)


def write(scene_dir: Path, rounds: list[int], max_rounds: int, out_json: Path) -> dict:
    """Write ``campaign.json`` and ``campaign.png`` next to it."""
    summary = summarize(scene_dir, rounds, max_rounds)
    out_json = Path(out_json)
    out_json.write_text(json.dumps(summary, indent=1), encoding="utf-8")
    plot(summary, out_json.with_suffix(".png"))
    return summary
