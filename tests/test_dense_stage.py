"""The dense stage end to end on a small synthetic capture, and its input errors."""

import json
import shutil

import numpy as np
import open3d as o3d
import pycolmap
import pytest

from scenebot.dense import colmap_cuda, stage
from scenebot.dense import workspace as ws
from scenebot.dense.colmap_io import read_array, write_array
from scenebot.dense.config import DenseConfig
from scenebot.dense.evaluate import depth_map_metrics, mesh_raycaster
from scenebot.testing.dense import box_room_scene, make_dataset, stereo_rig

W, H = 192, 144


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("dense_capture")
    sc = box_room_scene()
    centers, headings = stereo_rig(num_per_row=4, half_width_m=0.4)
    rec, views = make_dataset(root, sc, centers, headings, W, H, num_points=3000)
    return root, sc, rec, views


def _cfg(**kw):
    return DenseConfig(max_image_size=W, num_threads=2, taichi_arch="cpu", **kw)


def test_end_to_end(capture, tmp_path):
    root, sc, _rec, views = capture
    out = stage.DenseOutputs(tmp_path / "dense")
    summary = stage.run(_cfg(), stage.DenseInputs(root / "sparse", root / "images"), out)
    assert summary["backend"] == "taichi"
    assert summary["num_views"] == len(views)
    assert json.loads(out.summary_json.read_text())["num_fused_points"] > 1000
    for name in ("fused_views.png", "depth_normal_mosaic.png", "planes.png", "fused.ply"):
        assert (out.dense_dir / name).stat().st_size > 1000
    from scenebot.dense.planes.store import PLANES_NPZ, load_planes

    planes, centres = load_planes(out.dense_dir / PLANES_NPZ)  # the planes of the summary
    assert len(planes) == len(summary["plane_fill"]["planes"]) and len(centres) == len(views)
    # depth maps in COLMAP format, good where they exist
    accs = []
    for v in views:
        d, n = ws.read_maps(out.dense_dir, v.name, "geometric")
        assert d.shape == (H, W) and n.shape == (H, W, 3)
        m = depth_map_metrics(d, v.depth)
        assert m["coverage"] > 0.4
        accs.append(m["accuracy"])
    assert np.mean(accs) > 0.9
    # plane completion: the room's planes found; what it filled lies on the true surface
    pf = summary["plane_fill"]
    assert len(pf["planes"]) >= 2 and pf["measured_fraction"] > 0.4
    rel_errors = []
    for v in views:
        d, _ = ws.read_maps(out.dense_dir, v.name, "geometric")
        measured = read_array(
            out.dense_dir / "stereo/depth_maps_measured" / f"{v.name}.geometric.bin"
        )
        filled = (d > 0) & (measured == 0) & np.isfinite(v.depth)
        rel_errors.append(np.abs(d[filled] - v.depth[filled]) / v.depth[filled])
    rel_errors = np.concatenate(rel_errors)
    assert len(rel_errors) > 0.005 * len(views) * W * H
    assert np.mean(rel_errors < 0.02) > 0.9
    # the fused cloud lies on the true surface
    pts = np.asarray(o3d.io.read_point_cloud(str(out.fused_ply)).points)
    dist = mesh_raycaster(sc.vertices, sc.triangles).compute_distance(
        o3d.core.Tensor(pts.astype(np.float32))
    )
    dist = dist.numpy()
    assert np.median(dist) < 0.01
    assert np.mean(dist < 0.02) > 0.9


def test_missing_photo(capture, tmp_path):
    root, *_ = capture
    images = tmp_path / "images"
    shutil.copytree(root / "images", images)
    (images / "view_003.jpg").unlink()
    with pytest.raises(FileNotFoundError, match=r"1 registered photo\(s\) missing .*view_003.jpg"):
        stage.run(_cfg(), stage.DenseInputs(root / "sparse", images), stage.DenseOutputs(tmp_path))


def test_missing_model(capture, tmp_path):
    root, *_ = capture
    sparse = tmp_path / "sparse"
    shutil.copytree(root / "sparse", sparse)
    (sparse / "points3D.bin").unlink()
    with pytest.raises(FileNotFoundError, match=r"points3D\.bin"):
        stage.run(_cfg(), stage.DenseInputs(sparse, root / "images"), stage.DenseOutputs(tmp_path))


def test_single_registered_view(capture, tmp_path):
    root, _, rec, _ = capture
    one = pycolmap.Reconstruction(rec)
    for i in sorted(one.reg_image_ids())[1:]:
        one.deregister_frame(one.image(i).frame_id)
    (tmp_path / "sparse").mkdir()
    one.write_binary(str(tmp_path / "sparse"))
    with pytest.raises(ValueError, match="1 registered image"):
        stage.run(
            _cfg(),
            stage.DenseInputs(tmp_path / "sparse", root / "images"),
            stage.DenseOutputs(tmp_path),
        )


def test_view_without_overlap(tmp_path):
    sc = box_room_scene()
    centers = np.array([[0.0, -0.2, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.0]])
    headings = np.array([0.0, 0.0, np.pi])  # the third looks backwards
    make_dataset(tmp_path / "cap", sc, centers, headings, 128, 96, num_points=2000)
    inputs = stage.DenseInputs(tmp_path / "cap" / "sparse", tmp_path / "cap" / "images")
    strict = _cfg(skip_isolated_views=False)
    with pytest.raises(ValueError, match=r"share no usable overlap.*view_002.jpg"):
        stage.run(strict, inputs, stage.DenseOutputs(tmp_path / "strict"))
    # the default leaves it out with a warning naming it, and fuses the others
    summary = stage.run(_cfg(), inputs, stage.DenseOutputs(tmp_path / "dense"))
    assert (tmp_path / "dense" / "fused.ply").stat().st_size > 0
    assert "view_002.jpg" in json.dumps(summary)


def test_colmap_cuda_backend_requires_cuda():
    if pycolmap.has_cuda:
        pytest.skip("this pycolmap has CUDA")
    with pytest.raises(RuntimeError, match="has no CUDA"):
        stage.choose_backend(DenseConfig(backend="colmap_cuda"))
    assert stage.choose_backend(DenseConfig()) == "taichi"


def test_colmap_patch_match_options_follow_the_dense_config():
    cfg = DenseConfig(max_image_size=480, num_threads=2,
                      patchmatch={"window_radius": 5, "geom_iterations": 1,
                                  "filter_min_consistent": 3})  # fmt: skip
    opts = colmap_cuda.patch_match_options(cfg, (0.4, 6.0))
    assert (opts.max_image_size, opts.window_radius, opts.num_threads) == (480, 5, 2)
    assert opts.geom_consistency and opts.filter and opts.filter_min_num_consistent == 3
    assert (opts.depth_min, opts.depth_max) == pytest.approx((0.4, 6.0))
    # without a range COLMAP takes each view's from the sparse points; no geometric pass
    opts = colmap_cuda.patch_match_options(DenseConfig(patchmatch={"geom_iterations": 0}))
    assert opts.depth_min < 0 and opts.depth_max < 0 and not opts.geom_consistency


def test_colmap_patch_match_without_cuda_names_the_wheel(tmp_path):
    if pycolmap.has_cuda:
        pytest.skip("this pycolmap has CUDA")
    with pytest.raises(RuntimeError, match="pycolmap-cuda12"):
        colmap_cuda.run_patch_match(DenseConfig(), tmp_path)


def test_without_geometric_pass(capture, tmp_path):
    root, _, _, views = capture
    cfg = _cfg(plots=False, patchmatch={"geom_iterations": 0})
    out = stage.DenseOutputs(tmp_path / "dense")
    stage.run(cfg, stage.DenseInputs(root / "sparse", root / "images"), out)
    m = [
        depth_map_metrics(ws.read_maps(out.dense_dir, v.name, "geometric")[0], v.depth)
        for v in views
    ]
    assert np.mean([x["coverage"] for x in m]) > 0.4
    assert np.mean([x["accuracy"] for x in m]) > 0.85
    assert not (out.dense_dir / "stereo" / "unfiltered").exists()


def test_a_rerun_completes_its_own_depth_maps(capture, tmp_path):
    """Re-run into the same workspace (the workflow re-runs the stage when a setting
    changes): plane completion starts from this run's depth maps, not the measured maps an
    earlier run left in stereo/depth_maps_measured."""
    root, _, _, views = capture
    out = stage.DenseOutputs(tmp_path / "dense")
    inputs = stage.DenseInputs(root / "sparse", root / "images")
    stage.run(_cfg(plots=False), inputs, out)
    stale = out.dense_dir / "stereo" / "depth_maps_measured" / f"{views[0].name}.geometric.bin"
    write_array(stale, np.zeros_like(read_array(stale)))  # an earlier run's map: empty
    stage.run(_cfg(plots=False), inputs, out)
    assert np.mean(read_array(stale) > 0) > 0.2
