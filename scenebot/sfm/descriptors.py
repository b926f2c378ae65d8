"""``point_descriptors.npz``: the SIFT descriptors of every observation of every 3D point.

Arrays (one row per observation, so several rows per point):

* ``point_ids`` (N,) int64: the COLMAP point3D id;
* ``xyz`` (N, 3) float64: the point's position in the robot frame (m);
* ``descriptors`` (N, 128) uint8: the observing keypoint's descriptor exactly as pycolmap's
  SIFT extractor stored it in the database (same normalization as a query photo's
  ``pycolmap.extract_features`` / ``pycolmap.Sift`` output), so they can be matched directly;
* ``image_ids`` (N,) int64 and ``point2D_idx`` (N,) int64: where the observation comes from.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pycolmap

from scenebot.sfm.features import open_database


def collect_point_descriptors(rec: pycolmap.Reconstruction, db_path: Path) -> dict[str, np.ndarray]:
    """Gather the descriptors of all observations of ``rec``'s 3D points.

    Args:
        rec: the (aligned) model; its image ids are those of the database.
        db_path: the database holding the images' descriptors.

    Returns:
        The arrays described in the module docstring.
    """
    obs_img, obs_kp, obs_pid = [], [], []
    for pid, pt in rec.points3D.items():
        for el in pt.track.elements:
            obs_img.append(el.image_id)
            obs_kp.append(el.point2D_idx)
            obs_pid.append(pid)
    obs_img = np.asarray(obs_img, np.int64)
    obs_kp = np.asarray(obs_kp, np.int64)
    obs_pid = np.asarray(obs_pid, np.int64)
    desc = np.zeros((len(obs_pid), 128), np.uint8)
    with open_database(db_path) as db:
        for iid in np.unique(obs_img):
            name = rec.image(int(iid)).name
            dbim = db.read_image_with_name(name)
            if dbim is None or dbim.image_id != iid:
                raise RuntimeError(
                    f"model image {name} (id {iid}) is not the same image in {db_path}: "
                    "the model and database are out of sync; delete the sfm outputs and re-run"
                )
            d = np.asarray(db.read_descriptors(int(iid)).data)
            if d.dtype != np.uint8 or d.shape[1] != 128:
                raise RuntimeError(f"unexpected descriptors {d.dtype} {d.shape} for {name}")
            sel = obs_img == iid
            desc[sel] = d[obs_kp[sel]]
    xyz = np.array([rec.point3D(int(p)).xyz for p in obs_pid]).reshape(-1, 3)
    return {
        "point_ids": obs_pid,
        "xyz": xyz.astype(np.float64),
        "descriptors": desc,
        "image_ids": obs_img,
        "point2D_idx": obs_kp,
    }


def write_point_descriptors(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write the arrays to ``path`` (``.npz``, uncompressed for fast loading)."""
    np.savez(path, **arrays)
