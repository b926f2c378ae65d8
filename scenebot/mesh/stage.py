"""The mesh stage's entry point: ``run(cfg, inputs, outputs)`` with the rule's paths."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from scenebot.artifacts import round_name
from scenebot.artifacts.mesh import MeshError, write_mesh
from scenebot.geometry import read_sparse_map
from scenebot.mesh.config import MeshConfig
from scenebot.mesh.freespace import compute_freespace, observation_rays
from scenebot.mesh.poisson import build_mesh


@dataclass
class MeshInputs:
    """Inputs of the mesh stage: ``sfm_dir`` = ``round_{r}/sfm/`` (COLMAP binary model)."""

    sfm_dir: Path


@dataclass
class MeshOutputs:
    """Outputs: ``mesh.ply``, ``freespace.json``, ``freespace.npz``, ``freespace.png``."""

    mesh_ply: Path
    freespace_json: Path
    freespace_npz: Path
    freespace_png: Path | None = None


def run(cfg: MeshConfig, inputs: MeshInputs, outputs: MeshOutputs, person: bool = False) -> dict:
    """Poisson mesh of the map and its free space.

    Args:
        cfg: mesh settings.
        inputs: the round's map.
        outputs: the files to write.
        person: the photos are a person's (``robot: photos``): the free space is the 3-D
            space the photos saw through (:mod:`scenebot.mesh.volume`), not the robot's cut at
            the camera plane.

    Returns:
        Summary: vertex/face counts, free area (m^2), whether the free space is closed (and
        for a person the free volume).
    """
    where = round_name(inputs.sfm_dir, outputs.mesh_ply)
    smap = read_sparse_map(inputs.sfm_dir)
    if len(smap.names) == 0:
        raise MeshError(f"{where}: the map in {inputs.sfm_dir} has no registered images")
    V, F = build_mesh(smap.xyz, smap.view_dir, smap.track_len, cfg, where, smap.centres)
    write_mesh(outputs.mesh_ply, V, F)
    if person:
        return _person(cfg, inputs, outputs, V, F, where)
    cam_xy = smap.centres[:, :2]
    rays = observation_rays(inputs.sfm_dir, cfg.min_track_length) if cfg.seen_free_space else None
    fs = compute_freespace(
        V, F, cam_xy, cfg.robot_radius_m, cfg.cut_heights_m, cfg.grid_resolution_m, where,
        rays=rays,
    )  # fmt: skip
    fs.save(outputs.freespace_json, outputs.freespace_npz, where)
    if outputs.freespace_png is not None:
        from scenebot.mesh.plots import plot_freespace

        plot_freespace(outputs.freespace_png, fs, cam_xy, where)
    return {
        "vertices": len(V),
        "faces": len(F),
        "free_area_m2": fs.area_m2,
        "closed": fs.closed,
    }


def _person(cfg: MeshConfig, inputs: MeshInputs, outputs: MeshOutputs, V, F, where: str) -> dict:
    """The free space of a person's photos: 3-D, with its layer at camera height."""
    from scenebot.mesh.volume import person_freespace

    vol, plane, stopped = person_freespace(inputs.sfm_dir, V, F, cfg, where)
    plane.save(outputs.freespace_json, outputs.freespace_npz, where, volume=vol)
    if outputs.freespace_png is not None:
        from scenebot.geometry import read_map_geometry
        from scenebot.mesh.plots import plot_volume

        pts = read_map_geometry(inputs.sfm_dir)[0]
        plot_volume(outputs.freespace_png, vol, pts, where)
    return {
        "vertices": len(V),
        "free_volume_m3": vol.volume_m3,
        "free_voxels": vol.n_free,
        "voxel_m": vol.voxel,
        "free_area_m2": plane.area_m2,
        "closed": plane.closed,
        "lines_stopped_by_the_mesh": stopped,
    }
