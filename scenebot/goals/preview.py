"""A preview of each shot advised to a person (``robot: photos``): the view from the shot
rendered from the round's photos by the tour's unstructured-lumigraph renderer, the part no
photo sees tinted red.

There is no dense cloud yet at the goals stage: the renderer's proxy is the sparse map's
points (coloured, splatted, holes filled by the proxy's push-pull). A pixel is *missing*
when no photo sees its surface point: the renderer filled it with the cloud's colour
(``FILL_PROXY``) or found no surface at all (``FILL_NONE``). Entry point :func:`run` (the
``goals-preview`` command, rule ``goals_preview``) writes ``round_XXX/goals_preview.png``.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.goals.config import GoalsConfig
from scenebot.tour.config import TourConfig

log = logging.getLogger(__name__)

MISSING_TINT = np.array([255.0, 0.0, 0.0])
"""The colour blended half-and-half into the pixels no photo sees."""


@dataclass
class PreviewInputs:
    """Inputs of the previews: the round's map, the folder its image names are relative to
    (a person's photo folder) and the goals."""

    sfm_dir: Path
    image_dir: Path
    goals_json: Path


@dataclass
class PreviewOutputs:
    """Outputs: one tile per advised shot, and the tiles themselves for the guide page."""

    preview_png: Path
    preview_npz: Path | None = None  # the tiles as arrays (scenebot.artifacts.previews)


@dataclass
class Preview:
    """One shot's preview.

    Attributes:
        render: (H, W, 3) uint8 RGB, the renderer's image (nothing tinted).
        missing: (H, W) bool, the pixels no photo sees.
        seconds: time of the render.
    """

    render: np.ndarray
    missing: np.ndarray
    seconds: float

    @property
    def missing_fraction(self) -> float:
        """Share of the view no photo sees."""
        return float(self.missing.mean())

    @property
    def image(self) -> np.ndarray:
        """The render with the missing part tinted red."""
        out = self.render.astype(np.float64)
        out[self.missing] = 0.5 * out[self.missing] + 0.5 * MISSING_TINT
        return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def sparse_proxy(rec, cfg: TourConfig, source: str):
    """The renderer's proxy from the sparse map's points and their colours.

    Raises:
        TourInputError: fewer points than ``tour.proxy.min_points`` (named with ``source``).
    """
    from scenebot.tour.proxy import build_proxy

    pts = np.array([p.xyz for p in rec.points3D.values()], np.float64).reshape(-1, 3)
    col = np.array([p.color for p in rec.points3D.values()], np.uint8).reshape(-1, 3)
    return build_proxy(pts, None, col, cfg.proxy, source=f"{source} (the sparse map's points)")


class ShotPreviewer:
    """Renders views of a person's scene from its photos and sparse map.

    Args:
        tour_cfg: the tour's settings (renderer, proxy); lengths are scaled to the scene as
            the tour scales them for a person's photos (:func:`scenebot.tour.stage.photo_units`).
        sfm_dir: the round's COLMAP model.
        image_dir: the folder the model's image names are relative to.
        tile_width: width of a preview (pixels); the height keeps the photos' aspect.
    """

    def __init__(self, tour_cfg: TourConfig, sfm_dir: Path, image_dir: Path, tile_width: int):
        import pycolmap

        from scenebot.taichi_setup import init_taichi
        from scenebot.tour.camera import Camera, TourInputError
        from scenebot.tour.stage import photo_units
        from scenebot.tour.ulr import UlrRenderer, load_sources

        if not (Path(sfm_dir) / "images.bin").is_file():
            raise TourInputError(f"{sfm_dir}: no COLMAP model (images.bin); run the sfm stage")
        rec = pycolmap.Reconstruction(str(sfm_dir))
        cfg, _ = photo_units(tour_cfg, rec)
        init_taichi(cfg.taichi_arch, cfg.num_threads)
        sources = load_sources(rec, image_dir)
        proxy = sparse_proxy(rec, cfg, str(sfm_dir))
        self.renderer = UlrRenderer(proxy, sources, cfg)
        photo = sources[0].camera
        height = max(1, round(tile_width * photo.height / photo.width))
        self.camera: Camera = photo.resized(tile_width, height)

    def render(self, R: np.ndarray, t: np.ndarray, camera=None) -> Preview:
        """The preview of a view (``R``, ``t``: cam_from_world; ``camera``: the tiles')."""
        from scenebot.tour.ulr import FILL_NONE, FILL_PROXY

        start = time.perf_counter()
        res = self.renderer.render(camera or self.camera, R, t)
        missing = (res.fill == FILL_NONE) | (res.fill == FILL_PROXY)
        return Preview(res.image, missing, time.perf_counter() - start)

    def render_goal(self, goal: dict) -> Preview:
        """The preview of a goal of goals.json (x, y, z, theta, pitch)."""
        from scenebot.geometry import tilted_cam_from_world

        xyz = np.array([[goal["x"], goal["y"], goal["z"]]])
        Rt = tilted_cam_from_world(xyz, goal["theta"], goal["pitch"])[0]
        return self.render(Rt[:9].reshape(3, 3), Rt[9:])


def run(cfg: GoalsConfig, tour_cfg: TourConfig, inputs: PreviewInputs,
        outputs: PreviewOutputs) -> dict:  # fmt: skip
    """Render every advised shot of goals.json and write the tiles.

    Args:
        cfg: goals settings (``goals.preview_width``).
        tour_cfg: the tour's renderer settings.
        inputs: the round's map, photo folder and goals.
        outputs: the picture.

    Returns:
        Per shot: rank, predicted gain (deg), share missing, seconds.
    """
    from scenebot.goals.plots import plot_shot_previews

    doc = json.loads(Path(inputs.goals_json).read_text(encoding="utf-8"))
    goals = doc["goals"]
    if goals and "z" not in goals[0]:
        raise ValueError(
            f"{inputs.goals_json}: the goals have no height (z, pitch); previews are for a "
            "person's photos (robot: photos)"
        )
    start = time.perf_counter()
    previewer = ShotPreviewer(tour_cfg, inputs.sfm_dir, inputs.image_dir, cfg.preview_width)
    setup = time.perf_counter() - start
    previews = [previewer.render_goal(g) for g in goals]
    shots = [
        {"rank": g["rank"], "score_deg": g["score_deg"],
         "missing_fraction": round(p.missing_fraction, 4), "seconds": round(p.seconds, 3)}
        for g, p in zip(goals, previews, strict=True)
    ]  # fmt: skip
    plot_shot_previews(
        outputs.preview_png, [p.image for p in previews], shots,
        f"{doc.get('round', '')}: what each shot would add (rendered from the photos; "
        "red: no photo sees it)",
    )  # fmt: skip
    if outputs.preview_npz is not None:
        from scenebot.artifacts.previews import write_previews

        write_previews(outputs.preview_npz, [g["rank"] for g in goals],
                       [p.image for p in previews], [p.missing for p in previews])  # fmt: skip
    summary = {"setup_seconds": round(setup, 3), "shots": shots}
    log.info("goals preview: %s", summary)
    return summary
