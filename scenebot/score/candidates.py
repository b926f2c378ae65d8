"""Random candidate viewpoints inside the free space (written as ``candidates.csv`` with
:mod:`scenebot.artifacts.candidates`): a robot's (x, y, theta) in the plane of its camera, or a
person's six degrees of freedom (x, y, z, theta, pitch) in the 3-D free space.
"""

from __future__ import annotations

import numpy as np

from scenebot.artifacts.freespace import FreeSpace, FreeSpaceError, FreeVolume
from scenebot.geometry import Intrinsics
from scenebot.score.config import PersonConfig


def sample_candidates(fs: FreeSpace, n: int, rng: np.random.Generator, where: str) -> np.ndarray:
    """Uniform random poses in free space with uniform random headings.

    Positions are drawn uniformly over the free cells (jittered inside the cell) and kept when
    their exact distance to the cut mesh is at least the robot radius.

    Args:
        fs: the free space.
        n: number of candidates (> 0).
        rng: random generator.
        where: round name for error messages.

    Returns:
        (n, 3) poses (x m, y m, theta rad in [-pi, pi)).

    Raises:
        FreeSpaceError: zero candidates asked for, or none can be placed.
    """
    if n <= 0:
        raise FreeSpaceError(f"{where}: score.n_candidates is {n}; set it to at least 1")
    jj, ii = np.nonzero(fs.mask)
    if len(jj) == 0:
        raise FreeSpaceError(
            f"{where}: the free space is empty, no candidate can be placed; see the mesh stage's "
            "freespace.png, lower mesh.robot_radius_m or capture more photos"
        )
    out = np.zeros((0, 2))
    for _ in range(20):
        k = rng.integers(0, len(jj), size=2 * (n - len(out)) + 16)
        xy = fs.origin + (np.stack([ii[k], jj[k]], 1) + rng.random((len(k), 2))) * fs.resolution
        xy = xy[fs.contains(xy)]
        out = np.concatenate([out, xy])[:n]
        if len(out) == n:
            break
    if len(out) < n:
        raise FreeSpaceError(
            f"{where}: only {len(out)} of {n} candidates fit in the free space "
            f"({fs.area_m2:.3f} m^2); lower mesh.robot_radius_m or score.n_candidates"
        )
    theta = rng.uniform(-np.pi, np.pi, size=n)
    return np.concatenate([out, theta[:, None]], axis=1)


def sample_person_candidates(
    vol: FreeVolume,
    verts: np.ndarray,
    faces: np.ndarray,
    n: int,
    cfg: PersonConfig,
    intr: Intrinsics,
    rng: np.random.Generator,
    where: str,
) -> np.ndarray:
    """Random poses of a person's camera: in the 3-D free space, at a height of the person's
    band, looking at the map.

    Positions are drawn uniformly over the free voxels whose centres lie in the band
    ``cfg.heights_m`` around the photos' median camera height (jittered inside the voxel, kept
    in the band). Each candidate looks at a random point of the mesh (area-weighted), the aim
    moved by up to half the field of view either way, so the point stays in view: from inside
    a room that is every direction, around an object it is the object. The tilt is clipped to
    ``cfg.pitch_deg``; roll is 0.

    Args:
        vol: the 3-D free space.
        verts: (V, 3) mesh vertices (m).
        faces: (F, 3) triangles.
        n: number of candidates (> 0).
        cfg: ``score.person``.
        intr: the candidates' camera (its field of view).
        rng: random generator.
        where: round name for error messages.

    Returns:
        (n, 5) poses: x, y, z (m), heading theta (rad in [-pi, pi), ccw from x), pitch (rad,
        up positive).

    Raises:
        FreeSpaceError: zero candidates asked for, or no free voxel at a person's heights.
    """
    if n <= 0:
        raise FreeSpaceError(f"{where}: score.n_candidates is {n}; set it to at least 1")
    z0 = vol.camera_height
    lo, hi = z0 + cfg.heights_m[0], z0 + cfg.heights_m[1]
    kk, jj, ii = np.nonzero(vol.free)
    c = vol.centres(kk, jj, ii)
    band = (c[:, 2] >= lo - 0.5 * vol.voxel) & (c[:, 2] <= hi + 0.5 * vol.voxel)
    if not band.any():
        raise FreeSpaceError(
            f"{where}: no free space at a person's heights {z0 + cfg.heights_m[0]:.2f} .. "
            f"{z0 + cfg.heights_m[1]:.2f} m (score.person.heights_m = {cfg.heights_m} around "
            f"the photos' median camera height {z0:.2f} m) among {vol.n_free} free voxels; "
            "widen score.person.heights_m, or see the mesh stage's freespace.png"
        )
    c = c[band]
    k = rng.integers(0, len(c), size=n)
    xyz = c[k] + (rng.random((n, 3)) - 0.5) * vol.voxel
    xyz[:, 2] = np.clip(xyz[:, 2], lo, hi)
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    f = rng.choice(len(faces), size=n, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)
    w = np.stack([1 - r1, r1 * (1 - r2), r1 * r2], 1)
    d = np.einsum("nk,nkd->nd", w, tri[f]) - xyz
    half_h = np.arctan(0.5 * intr.width / intr.fx)
    half_v = np.arctan(0.5 * intr.height / intr.fy)
    theta = np.arctan2(d[:, 1], d[:, 0]) + rng.uniform(-half_h, half_h, n)
    theta = (theta + np.pi) % (2 * np.pi) - np.pi
    pitch = np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])) + rng.uniform(-half_v, half_v, n)
    pitch = np.clip(pitch, *np.deg2rad(cfg.pitch_deg))
    return np.column_stack([xyz, theta, pitch])
