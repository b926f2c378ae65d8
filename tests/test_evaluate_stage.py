"""Dense metrics against the observable surface, the robot->world similarity, the stage."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation

from scenebot.capturelog import CaptureLog
from scenebot.config import Config
from scenebot.dense.evaluate import cloud_metrics
from scenebot.evaluate.config import EvaluateConfig
from scenebot.evaluate.metrics import (
    EvaluationError,
    capture_stats,
    goal_truth,
    localization_accuracy,
    robot_to_world,
    weighted_cloud_metrics,
)
from scenebot.evaluate.observable import observable_surface
from scenebot.evaluate.stage import EvaluateInputs, EvaluateOutputs, run
from scenebot.sim.renderer import look_rotation
from scenebot.testing.score import default_intrinsics, write_colmap_model
from tests.fixtures.rooms import box_room

ECFG = EvaluateConfig(grid_step_m=0.4, headings=6, sample_spacing_m=0.05)
TAUS = ECFG.thresholds_m  # the default 1, 2, 5 cm
# the map's robot frame: world = S * R @ robot + T (a yawed, scaled, shifted frame)
S_TRUE = 1.25
R_TRUE = Rotation.from_euler("z", 35, degrees=True).as_matrix()
T_TRUE = np.array([2.0, 1.5, 0.35])


@pytest.fixture(scope="module")
def scene():
    return box_room(obstacles=[((1.0, 1.0, 0.0), (1.6, 1.6, 0.5))], start=(3.0, 1.5, 0.0))


@pytest.fixture(scope="module")
def surf(scene):
    return observable_surface(scene, Config().sim, ECFG)


def to_robot(x):
    return (np.asarray(x) - T_TRUE) @ R_TRUE / S_TRUE


def write_round(tmp_path, n_photos=8, goals=(), truth=True):
    """A round_000 with a capture log (with the true poses unless ``truth`` is False) and a
    COLMAP model in the robot frame."""
    cap = tmp_path / "round_000" / "capture"
    rng = np.random.default_rng(0)
    centers_w = np.c_[rng.uniform(2.2, 3.6, n_photos), rng.uniform(0.6, 2.4, n_photos),
                      np.full(n_photos, 0.35)]  # fmt: skip
    heads = rng.uniform(0, 2 * np.pi, n_photos)
    Rw = np.array([look_rotation(h) for h in heads])
    with CaptureLog(cap / "log.jsonl") as log:
        log.write({"type": "session", "robot": "sim"})
        for k in range(n_photos):
            rec = {"type": "photo", "index": k, "image": f"images/im{k:04d}.jpg",
                   "odometry": {"x": 0, "y": 0, "theta": 0}}  # fmt: skip
            if truth:
                rec["truth"] = {"center": centers_w[k].tolist(), "R_cam_from_world": Rw[k].tolist()}
            log.write(rec)
        for g in goals:
            log.write({"type": "event", "event": g, "t": 1.0})
        log.write({"type": "end", "photos": n_photos})
    # robot-frame cameras: R_r = R_w @ R_TRUE, centre c_r = to_robot(c_w)
    Rr = Rw @ R_TRUE
    cr = to_robot(centers_w)
    tr = -np.einsum("kij,kj->ki", Rr, cr)
    pts = to_robot(rng.uniform([0.5, 0.5, 0.2], [3.5, 2.5, 2.0], (50, 3)))
    write_colmap_model(tmp_path / "round_000" / "sfm", default_intrinsics(),
                       Rr, tr, pts, np.ones((n_photos, 50), bool))  # fmt: skip
    return cap, tmp_path / "round_000" / "sfm"


def write_cloud(path, pts):
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(pts, np.float64)))
    o3d.io.write_point_cloud(str(path), pc)
    return path


def test_uniform_weights_give_the_dense_stage_metrics(scene, surf):
    rng = np.random.default_rng(2)
    ref = surf.observable_points
    cloud = ref[rng.random(len(ref)) < 0.5] + rng.normal(0, 0.008, (1, 3))
    ours = weighted_cloud_metrics(cloud, scene.vertices, scene.triangles, ref, thresholds_m=TAUS)
    theirs = cloud_metrics(cloud, scene.vertices, scene.triangles, ref)
    for tau in ("1cm", "2cm", "5cm"):
        for k in ("accuracy", "completeness", "fscore"):
            assert ours[tau][k] == pytest.approx(theirs[tau][k], abs=1e-9)


def test_a_perfect_cloud_is_complete_and_a_shifted_one_is_not_accurate(scene, surf):
    ref, w = surf.observable_points, surf.observable_weights
    m = weighted_cloud_metrics(ref, scene.vertices, scene.triangles, ref, w, thresholds_m=TAUS)
    assert m["1cm"]["accuracy"] == 1.0 and m["1cm"]["completeness"] == 1.0
    # 3 cm off the surface along its normal: inaccurate at 1 and 2 cm, accurate at 5 cm
    from scenebot.evaluate.observable import triangle_normals

    n, _ = triangle_normals(scene.vertices, scene.triangles)
    off = ref + 0.03 * n[surf.triangle[surf.observable]]
    m = weighted_cloud_metrics(off, scene.vertices, scene.triangles, ref, w, thresholds_m=TAUS)
    assert m["2cm"]["accuracy"] < 0.02 and m["5cm"]["accuracy"] > 0.98
    assert m["median_error_m"]["accuracy"] == pytest.approx(0.03, abs=0.002)


def test_completeness_is_weighted_by_area(scene, surf):
    ref = surf.observable_points[:1000]
    w = np.ones(len(ref))
    w[:100] = 9.0  # the first 100 samples stand for 900 of 1800 area units
    m = weighted_cloud_metrics(
        ref[:100], scene.vertices, scene.triangles, ref, w, thresholds_m=TAUS
    )
    d = np.linalg.norm(ref[:, None] - ref[None, :100], axis=2).min(1)
    expect = np.sum(w * (d < 0.01)) / w.sum()
    assert m["1cm"]["completeness"] == pytest.approx(expect)
    assert m["1cm"]["completeness"] >= 0.5


def test_the_similarity_recovers_the_robot_frame(tmp_path):
    cap, sfm = write_round(tmp_path)
    sim = robot_to_world(sfm, [cap])
    assert sim.photos == 8
    assert sim.scale == pytest.approx(S_TRUE, rel=1e-6)
    assert np.allclose(sim.R, R_TRUE, atol=1e-6) and np.allclose(sim.t, T_TRUE, atol=1e-6)
    assert sim.residual_m["max"] < 1e-6


def test_capture_stats_count_photos_and_goals(tmp_path):
    cap, _ = write_round(tmp_path, goals=["goal_reached", "goal_reached", "goal_abandoned"])
    st = capture_stats([cap, cap / "log.jsonl"])
    assert st["photos_per_round"] == [8, 8] and st["photos_total"] == 16
    assert st["goals"]["reached"] == 4 and st["goals"]["attempted"] == 6
    assert st["goals"]["reached_fraction"] == pytest.approx(4 / 6)
    with pytest.raises(EvaluationError, match="not found"):
        capture_stats([tmp_path / "nowhere"])


def test_goal_truth_counts_reachable_goals_and_true_stopping_distances(tmp_path):
    """Goals in the map frame are moved to the world; one inside the obstacle box is not
    reachable; a reached goal's distance is the true robot position's distance to it."""
    cap, sfm = write_round(tmp_path)
    sim = robot_to_world(sfm, [cap])
    free = np.array([3.0, 2.0])  # world
    blocked = np.array([1.3, 1.3])  # inside the obstacle box
    near, far = free + np.array([0.03, 0.04]), free + np.array([0.3, 0.0])
    with CaptureLog(tmp_path / "r1.jsonl") as log:
        for k, (gw, ev, stop) in enumerate(
            [(free, "goal_reached", near), (free, "goal_reached", far),
             (blocked, "goal_abandoned", None), (free, "goal_skipped", None)]
        ):  # fmt: skip
            rec = {"type": "event", "event": ev, "goal_index": k,
                   "robot_goal": to_robot([*gw, 0.35])[:2].tolist()}  # fmt: skip
            if stop is not None:
                rec["truth"] = {"x": float(stop[0]), "y": float(stop[1]), "theta": 0.0}
            log.write(rec)
        log.write({"type": "event", "event": "goal_skipped", "goal_index": 4})  # old log
    inside_box = lambda xy: not (0.9 <= xy[0] <= 1.7 and 0.9 <= xy[1] <= 1.7)  # noqa: E731
    gt = goal_truth([cap, tmp_path / "r1.jsonl"], sim, inside_box)
    assert [g["reachable"] for g in gt["goals"]] == [True, True, False, True, None]
    assert gt["reachable"] == 3 and gt["unknown"] == 1
    assert gt["goals"][0]["true_distance_m"] == pytest.approx(0.05, abs=1e-3)
    assert gt["goals"][1]["true_distance_m"] == pytest.approx(0.30, abs=1e-3)
    assert gt["reached_within"] == 1
    assert gt["reached_within_fraction_of_reachable"] == pytest.approx(1 / 3)


def test_goal_truth_measures_a_moved_goal_where_the_robot_drove(tmp_path):
    """A goal the planner moved off an obstacle cell (``driven_goal``) is measured there; the
    distance to the position first asked for is reported beside it."""
    cap, sfm = write_round(tmp_path)
    sim = robot_to_world(sfm, [cap])
    asked, driven = np.array([3.0, 2.0]), np.array([3.0, 2.13])  # world
    stop = driven + np.array([0.03, 0.0])
    with CaptureLog(tmp_path / "r1.jsonl") as log:
        log.write({"type": "event", "event": "goal_reached", "goal_index": 0,
                   "robot_goal": to_robot([*asked, 0.35])[:2].tolist(),
                   "driven_goal": to_robot([*driven, 0.35])[:2].tolist(),
                   "truth": {"x": float(stop[0]), "y": float(stop[1]), "theta": 0.0}})  # fmt: skip
    gt = goal_truth([cap, tmp_path / "r1.jsonl"], sim, lambda xy: xy[1] > 2.05)
    g = gt["goals"][0]
    assert g["reachable"] is True  # judged where the robot was sent
    assert g["true_distance_m"] == pytest.approx(0.03, abs=1e-3)
    assert g["true_distance_to_asked_m"] == pytest.approx(np.hypot(0.03, 0.13), abs=1e-3)
    assert g["moved_m"] == pytest.approx(0.13, abs=1e-3)
    assert gt["reached_within"] == 1 and gt["reached_within_asked"] == 0


def test_the_stage_writes_the_round_evaluation(tmp_path, scene, surf):
    cap, sfm = write_round(tmp_path, goals=["goal_reached", "goal_abandoned"])
    # the true observable surface in the robot frame, with half of it missing
    ref = surf.observable_points
    keep = ref[:, 0] < 2.0
    cloud = write_cloud(tmp_path / "fused.ply", to_robot(ref[keep]))
    per_photo = [{"name": "a", "position_error_m": 0.01, "heading_error_deg": 0.2}]
    acc = {"evaluated": 8, "position_error_m": {"median": 0.01}, "per_photo": per_photo}
    (sfm / "accuracy.json").write_text(json.dumps(acc))
    outs = EvaluateOutputs(tmp_path / "round_000" / "evaluation.json",
                           tmp_path / "round_000" / "evaluation.png")  # fmt: skip
    obs = tmp_path / "eval" / "observable_surface.npz"
    ev = run(Config(), EvaluateInputs(sfm, [cap], cloud, obs), outs, ECFG, scene=scene)
    assert ev["round"] == 0 and ev["capture"]["photos_total"] == 8
    assert ev["capture"]["goals"]["reached"] == 1
    expect = surf.observable_weights[keep].sum() / surf.observable_weights.sum()
    for tau in ("1cm", "2cm", "5cm"):
        assert ev["dense"][tau]["accuracy"] > 0.999
    # float32 round trips through the PLY and the similarity: within 1 cm everywhere
    assert ev["dense"]["1cm"]["completeness"] == pytest.approx(expect, abs=0.01)
    assert ev["sfm"]["per_photo_position_error_m"] == [0.01]
    assert ev["alignment"]["scale"] == pytest.approx(S_TRUE, rel=1e-6)
    # the breakdown: 8 photos see part of the room; the materials partition the area
    b = ev["dense"]["breakdown"]
    assert 0.0 < b["photographed_share"] < 1.0
    assert sum(c["area_share"] for c in b["by_views"]) == pytest.approx(1.0)
    assert sum(m["area_share"] for m in b["by_material"]) == pytest.approx(1.0)
    assert {m["material"] for m in b["by_material"]} <= {"carpet", "poster", "cardboard"}
    unseen = next(c for c in b["by_views"] if c["views"] == "0")
    assert unseen["area_share"] > 0.0
    # the coverage curve: every 5 photos and the last, ending on the breakdown's share
    cov = ev["coverage_by_photos"]
    assert cov["photos"] == [5, 8]
    assert cov["seen_2"][-1] == b["photographed_share"]
    assert all(s2 <= s1 for s1, s2 in zip(cov["seen_1"], cov["seen_2"], strict=True))
    assert cov["seen_1"][0] <= cov["seen_1"][1] and cov["seen_2"][0] <= cov["seen_2"][1]
    saved = json.loads(outs.json.read_text())
    assert saved["dense"]["points"] == int(keep.sum())
    assert outs.png.stat().st_size > 20_000 and obs.is_file()
    # a second round reuses the cached observable surface
    ev2 = run(Config(), EvaluateInputs(sfm, [cap], cloud, obs), outs, ECFG, scene=scene)
    assert ev2["observable"]["cached"]


def test_without_truth_only_counts_are_written(tmp_path):
    cap, sfm = write_round(tmp_path, truth=False)
    cfg = Config.model_validate({"robot": "photos", "photos": {"folder": str(tmp_path)}})
    out = EvaluateOutputs(tmp_path / "ev.json")
    ev = run(cfg, EvaluateInputs(sfm, [cap], None, None, round_index=3), out)
    assert ev["round"] == 3 and ev["dense"] is None and ev["alignment"] is None
    assert ev["capture"]["photos_total"] == 8 and ev["notes"]


def photos_cfg(tmp_path, **evaluate):
    return Config.model_validate(
        {"robot": "photos", "photos": {"folder": str(tmp_path)}, "evaluate": evaluate}
    )


def test_photos_with_reference_cameras_report_the_camera_errors(tmp_path, surf):
    """robot: photos with evaluate.reference_cameras: the map is fitted to the given cameras
    (errors ~0 here: the model is an exact similarity of them); with an object box the
    dense cloud's share inside it is reported, and no scene metric is made up."""
    from scenebot.evaluate.reference import read_reference_cameras, write_reference_log

    cap, sfm = write_round(tmp_path)
    ref = tmp_path / "eval" / "reference_cameras.jsonl"
    write_reference_log(read_reference_cameras(cap / "log.jsonl"), ref)
    box = [[0.5, 0.5, 0.0], [2.0, 2.5, 2.5]]
    cfg = photos_cfg(tmp_path, reference_cameras=str(ref), reference_bbox=box)
    ref_pts = surf.observable_points
    inside = np.all((ref_pts >= box[0]) & (ref_pts <= box[1]), axis=1)
    cloud = write_cloud(tmp_path / "fused.ply", to_robot(ref_pts))
    out = EvaluateOutputs(tmp_path / "ev.json")
    ev = run(cfg, EvaluateInputs(sfm, [ref], cloud, None, round_index=0), out, cfg.evaluate)
    assert ev["alignment"]["scale"] == pytest.approx(S_TRUE, rel=1e-6)
    r = ev["reference"]
    assert r["cameras"] == 8 and r["registered"] == 8 and r["not_registered"] == []
    assert r["centre_error"]["max"] < 1e-6
    assert ev["dense"]["inside_bbox"] == pytest.approx(inside.mean(), abs=0.005)
    assert "1cm" not in ev["dense"] and ev["localization"] is None
    # one photo the map lacks is named
    recs = [json.loads(x) for x in ref.read_text().splitlines()]
    recs.append({**recs[0], "image": "extra.jpg"})
    ref.write_text("".join(json.dumps(x) + "\n" for x in recs))
    ev = run(cfg, EvaluateInputs(sfm, [ref], None, None, round_index=0), out, cfg.evaluate)
    assert ev["reference"]["not_registered"] == ["extra.jpg"]


def test_photos_taken_in_a_known_world_are_evaluated_like_a_simulated_robot(tmp_path, scene, surf):
    cap, sfm = write_round(tmp_path)
    keep = surf.observable_points[:, 0] < 2.0
    cloud = write_cloud(tmp_path / "fused.ply", to_robot(surf.observable_points[keep]))
    cfg = photos_cfg(tmp_path, reference_cameras=str(cap / "log.jsonl"), reference_world=True)
    ecfg = ECFG.model_copy(update={"reference_cameras": cap / "log.jsonl", "reference_world": True})
    obs = tmp_path / "eval" / "observable_surface.npz"
    out = EvaluateOutputs(tmp_path / "ev.json")
    ev = run(cfg, EvaluateInputs(sfm, [cap], cloud, obs, round_index=0), out, ecfg, scene=scene)
    expect = surf.observable_weights[keep].sum() / surf.observable_weights.sum()
    assert ev["dense"]["2cm"]["completeness"] == pytest.approx(expect, abs=0.01)
    assert ev["reference"]["registered"] == 8


def test_reference_cameras_read_the_same_from_every_format(tmp_path):
    """A Middlebury par file, a COLMAP model and a capture log of the same cameras."""
    from scenebot.evaluate.reference import ReferenceError, read_reference_cameras

    cap, sfm = write_round(tmp_path)
    from_log = read_reference_cameras(cap / "log.jsonl")
    from_model = read_reference_cameras(sfm)  # the robot frame: same rotations up to R_TRUE
    lines = [str(len(from_log))]
    for name, (R, c) in from_log.items():
        K = np.diag([500.0, 500.0, 1.0])
        lines.append(" ".join([name, *map(str, K.ravel()), *map(str, R.ravel()),
                               *map(str, -R @ c)]))  # fmt: skip
    par = tmp_path / "cams_par.txt"
    par.write_text("\n".join(lines) + "\n")
    from_par = read_reference_cameras(par)
    assert from_par.keys() == from_log.keys() == from_model.keys()
    for name in from_log:
        np.testing.assert_allclose(from_par[name][1], from_log[name][1], atol=1e-9)
        np.testing.assert_allclose(from_par[name][0], from_log[name][0], atol=1e-9)
        np.testing.assert_allclose(from_model[name][1], to_robot(from_log[name][1]), atol=1e-5)
    par.write_text("1\nim0000.jpg 1 2 3\n")
    with pytest.raises(ReferenceError, match="22 fields"):
        read_reference_cameras(par)
    with pytest.raises(ReferenceError, match="not found"):
        read_reference_cameras(tmp_path / "nope.txt")


def _round_and_truth(tmp_path):
    """A written round, its robot-to-world similarity, and a true camera pose (centre c_w,
    heading th, rotation R_w) as a log's ``truth``."""
    cap, sfm = write_round(tmp_path)
    sim = robot_to_world(sfm, [cap])
    c_w, th = np.array([2.5, 1.0, 0.35]), 0.7
    R_w = look_rotation(th)
    truth = {"robot": {"x": 2.4, "y": 1.0, "theta": th}, "center": c_w.tolist(),
             "R_cam_from_world": R_w.tolist()}  # fmt: skip
    return sim, c_w, th, R_w, truth


def test_localization_estimates_are_compared_in_the_world_frame(tmp_path):
    sim, c_w, th, R_w, truth = _round_and_truth(tmp_path)
    fix = {"ok": True, "center": to_robot(c_w + np.array([0.03, 0.0, 0.0])).tolist(),
           "R_cam_from_world": (R_w @ R_TRUE).tolist()}  # fmt: skip
    xy = to_robot(np.array([2.4, 1.04, 0.35]))
    robot = {"x": float(xy[0]), "y": float(xy[1]), "theta": th - np.radians(35) + 0.02}
    with CaptureLog(tmp_path / "r1" / "log.jsonl") as log:
        log.write({"type": "event", "event": "localize", "localization": fix, "truth": truth})
        log.write({"type": "event", "event": "localize_failed", "localization": {"ok": False}})
        log.write({"type": "photo", "image": "images/a.jpg", "localization": robot,
                   "localization_source": "this photo", "truth": truth})  # fmt: skip
        carried = "odometry since the last fix"
        log.write({"type": "photo", "image": "images/b.jpg", "localization": robot,
                   "localization_source": carried, "truth": truth})  # fmt: skip
    acc = localization_accuracy([tmp_path / "r1"], sim)
    assert acc["failed_fixes"] == 1
    assert acc["fixes"]["count"] == 1 and acc["photos"]["count"] == 1
    assert acc["fixes"]["position_error_m"]["median"] == pytest.approx(0.03, abs=1e-6)
    assert acc["fixes"]["heading_error_deg"]["median"] == pytest.approx(0.0, abs=1e-6)
    assert acc["photos"]["position_error_m"]["median"] == pytest.approx(0.04, abs=1e-6)
    assert acc["photos"]["heading_error_deg"]["median"] == pytest.approx(np.degrees(0.02))
    assert acc["turned_away"] == {}  # the failure had no pose


def test_fixes_turned_away_are_judged_against_the_truth(tmp_path):
    """A fix the robot's checks turned away with a pose in hand (``rejected_pose`` of a
    ``localize_failed``, a ``localize_rejected``'s fix) is compared with the truth: per
    reason, how many were right (within 5 cm) and how many wrong (beyond 25 cm)."""
    sim, c_w, _th, R_w, truth = _round_and_truth(tmp_path)

    def pose(dx: float) -> dict:
        return {"center": to_robot(c_w + np.array([dx, 0.0, 0.0])).tolist(),
                "R_cam_from_world": (R_w @ R_TRUE).tolist()}  # fmt: skip

    with CaptureLog(tmp_path / "r1" / "log.jsonl") as log:
        for dx in (0.01, 0.02, 1.5):
            failed = {"ok": False, "reason": "uncertain_pose", "rejected_pose": pose(dx)}
            log.write({"type": "event", "event": "localize_failed", "localization": failed,
                       "truth": truth})  # fmt: skip
        log.write({"type": "event", "event": "localize_failed", "truth": truth,
                   "localization": {"ok": False, "reason": "too_few_matches"}})  # fmt: skip
        log.write({"type": "event", "event": "localize_rejected", "reason": "odometry",
                   "localization": {"ok": True} | pose(2.0), "truth": truth})  # fmt: skip
    acc = localization_accuracy([tmp_path / "r1"], sim)
    assert acc["failed_fixes"] == 4 and acc["fixes"]["count"] == 0
    uncertain = acc["turned_away"]["uncertain_pose"]
    assert uncertain["count"] == 3 and uncertain["right"] == 2 and uncertain["wrong"] == 1
    assert uncertain["position_error_m"]["median"] == pytest.approx(0.02, abs=1e-6)
    odometry = acc["turned_away"]["odometry"]
    assert odometry["count"] == 1 and odometry["wrong"] == 1 and odometry["right"] == 0
    assert set(acc["turned_away"]) == {"uncertain_pose", "odometry"}
