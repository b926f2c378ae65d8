"""COLMAP dense workspace: input validation, undistortion, loading views, writing maps.

Layout (what ``colmap image_undistorter`` writes, so COLMAP's own tools can read it)::

    {dense}/images/{name}                 undistorted photos
    {dense}/sparse/{cameras,images,points3D}.bin   pinhole model of the undistorted photos
    {dense}/stereo/depth_maps/{name}.{photometric,geometric}.bin
    {dense}/stereo/normal_maps/{name}.{photometric,geometric}.bin
    {dense}/stereo/cost_maps/{name}.photometric.bin   (scenebot extra, 1 - NCC)
    {dense}/stereo/patch-match.cfg, fusion.cfg
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pycolmap

from scenebot.dense.colmap_io import read_array, write_array
from scenebot.dense.patchmatch import StereoView

LOG = logging.getLogger(__name__)

MODEL_FILES = ("cameras.bin", "images.bin", "points3D.bin")


def check_inputs(sparse_dir: str | Path, image_dir: str | Path) -> pycolmap.Reconstruction:
    """Validate the stage inputs and load the sparse model.

    Args:
        sparse_dir: COLMAP binary model folder.
        image_dir: folder with the photos named as in the model.

    Returns:
        The reconstruction.

    Raises:
        FileNotFoundError: a model file or registered photo is missing (all are named).
        ValueError: fewer than 2 registered images.
    """
    sparse_dir, image_dir = Path(sparse_dir), Path(image_dir)
    missing = [str(sparse_dir / f) for f in MODEL_FILES if not (sparse_dir / f).is_file()]
    if missing:
        raise FileNotFoundError(
            "dense: sparse model incomplete, missing " + ", ".join(missing) + " (run the sfm "
            "stage first, or point inputs.sparse_dir at a COLMAP binary model)"
        )
    rec = pycolmap.Reconstruction(str(sparse_dir))
    reg = rec.reg_image_ids()
    if len(reg) < 2:
        raise ValueError(
            f"dense: the sparse model {sparse_dir} has {len(reg)} registered image(s); dense "
            "stereo needs at least 2 registered, overlapping views"
        )
    absent = [rec.image(i).name for i in reg if not (image_dir / rec.image(i).name).is_file()]
    if absent:
        shown = ", ".join(absent[:10]) + (
            f" and {len(absent) - 10} more" if len(absent) > 10 else ""
        )
        raise FileNotFoundError(
            f"dense: {len(absent)} registered photo(s) missing from {image_dir}: {shown}"
        )
    return rec


def undistort(
    sparse_dir: str | Path,
    image_dir: str | Path,
    dense_dir: str | Path,
    max_image_size: int = 640,
    image_names: list[str] | None = None,
) -> pycolmap.Reconstruction:
    """Undistort the photos into a COLMAP dense workspace with pycolmap.

    Args:
        sparse_dir: COLMAP binary model folder.
        image_dir: photo folder.
        dense_dir: workspace folder to create.
        max_image_size: longest side of the undistorted images, pixels.
        image_names: subset of images to undistort (default: all registered).

    Returns:
        The undistorted (pinhole) reconstruction read back from ``dense_dir/sparse``.
    """
    dense_dir = Path(dense_dir)
    dense_dir.mkdir(parents=True, exist_ok=True)
    opts = pycolmap.UndistortCameraOptions()
    opts.max_image_size = int(max_image_size)
    pycolmap.undistort_images(
        str(dense_dir),
        str(sparse_dir),
        str(image_dir),
        image_names=list(image_names or []),
        output_type="COLMAP",
        undistort_options=opts,
    )
    for sub in ("depth_maps", "normal_maps"):
        (dense_dir / "stereo" / sub).mkdir(parents=True, exist_ok=True)
    return pycolmap.Reconstruction(str(dense_dir / "sparse"))


@dataclass(frozen=True)
class ViewCamera:
    """A view of the workspace without its pixels (what a worker process needs to load it).

    Attributes:
        name: image name.
        K: (3, 3) pinhole intrinsics.
        R: (3, 3) cam_from_world rotation.
        t: (3,) cam_from_world translation.
        width: image width, pixels.
        height: image height, pixels.
    """

    name: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int

    @classmethod
    def of_image(cls, rec: pycolmap.Reconstruction, image_id: int) -> ViewCamera:
        """The camera of a registered image.

        Raises:
            ValueError: the camera is not a pinhole model.
        """
        img = rec.image(image_id)
        cam = rec.camera(img.camera_id)
        if cam.model_name not in ("PINHOLE", "SIMPLE_PINHOLE"):
            raise ValueError(f"dense: camera of {img.name} is {cam.model_name}, expected a pinhole")
        pose = img.cam_from_world()
        t = np.asarray(pose.translation, dtype=np.float64)
        K, R = cam.calibration_matrix(), pose.rotation.matrix()
        return cls(img.name, K, R, t, cam.width, cam.height)


def read_view(dense_dir: str | Path, cam: ViewCamera) -> StereoView:
    """Load an undistorted image as a grey :class:`StereoView`.

    Raises:
        FileNotFoundError: the undistorted image is missing.
        ValueError: the image size does not match the camera.
    """
    path = Path(dense_dir) / "images" / cam.name
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise FileNotFoundError(f"dense: undistorted image {path} is missing or unreadable")
    if bgr.shape[:2] != (cam.height, cam.width):
        raise ValueError(
            f"dense: {path} is {bgr.shape[1]}x{bgr.shape[0]}, camera says {cam.width}x{cam.height}"
        )
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32) / 255.0
    return StereoView(name=cam.name, gray=gray, K=cam.K, R=cam.R, t=cam.t)


def load_view(rec: pycolmap.Reconstruction, image_id: int, dense_dir: str | Path) -> StereoView:
    """Load a registered image of the workspace as a grey :class:`StereoView`.

    Raises:
        FileNotFoundError: the undistorted image is missing.
        ValueError: the camera is not a pinhole model or the image size does not match it.
    """
    return read_view(dense_dir, ViewCamera.of_image(rec, image_id))


def map_path(dense_dir: str | Path, kind: str, name: str, stage: str) -> Path:
    """Path of a map: kind in {"depth", "normal", "cost"} ("cost" is a scenebot extra: the
    photometric 1 - NCC of the selected sources), stage in {"photometric", "geometric"}."""
    return Path(dense_dir) / "stereo" / f"{kind}_maps" / f"{name}.{stage}.bin"


def write_maps(
    dense_dir: str | Path, name: str, stage: str, depth: np.ndarray, normal: np.ndarray
) -> None:
    """Write a depth (H, W) and normal (H, W, 3) map in COLMAP format."""
    write_array(map_path(dense_dir, "depth", name, stage), depth)
    write_array(map_path(dense_dir, "normal", name, stage), normal)


def read_maps(dense_dir: str | Path, name: str, stage: str) -> tuple[np.ndarray, np.ndarray]:
    """Read a depth (H, W) and normal (H, W, 3) map in COLMAP format."""
    return (
        read_array(map_path(dense_dir, "depth", name, stage)),
        read_array(map_path(dense_dir, "normal", name, stage)),
    )


def write_configs(dense_dir: str | Path, sources: dict[str, list[str]]) -> None:
    """Write ``stereo/patch-match.cfg`` (explicit sources) and ``stereo/fusion.cfg``.

    Args:
        dense_dir: workspace.
        sources: reference image name -> source image names, for the views that get depth.
    """
    stereo = Path(dense_dir) / "stereo"
    stereo.mkdir(parents=True, exist_ok=True)
    with open(stereo / "patch-match.cfg", "w") as fh:
        for ref, srcs in sources.items():
            fh.write(f"{ref}\n{', '.join(srcs)}\n")
    with open(stereo / "fusion.cfg", "w") as fh:
        fh.write("".join(f"{ref}\n" for ref in sources))
