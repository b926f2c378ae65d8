"""Settings of the virtual-tour stage (issue 8).

The lead merges :class:`TourConfig` into the single project config (a ``tour:`` section); every
field carries its unit in the description so the generated JSON schema documents itself.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from scenebot.settings import Settings


class ProxyConfig(Settings):
    """The geometric proxy: the dense cloud splatted into a view, holes filled."""

    min_points: int = Field(
        500, ge=10, description="Fewer finite points than this in the dense cloud is an error."
    )
    spacing_knn: int = Field(
        6, ge=1, le=32, description="A point's splat radius comes from its k-th neighbour (count)."
    )
    outlier_radius: float = Field(
        4.0,
        ge=0,
        description="Isolated points (floaters of the fusion) are dropped: a point needs "
        "outlier_min_neighbors others within this many median point spacings (the cloud's "
        "median distance to the spacing_knn-th neighbour) (0 = keep all).",
    )
    outlier_min_neighbors: int = Field(
        16, ge=0, description="Neighbours a point needs within outlier_radius (count)."
    )
    splat_scale: float = Field(
        1.0,
        gt=0,
        description="Splat radius = this x the distance to the k-th neighbour (fraction).",
    )
    max_splat_px: float = Field(
        2.0, ge=0.5, description="Largest splat radius on screen, pixels (at 640 px width)."
    )
    oriented_splats: bool = Field(
        True,
        description="Depth across a splat follows the point's normal (a small plane) rather "
        "than being constant.",
    )
    hole_fill_levels: int = Field(
        10,
        ge=0,
        le=10,
        description="Push-pull pyramid levels that interpolate inverse depth into holes: holes "
        "up to about 2^levels pixels wide are filled, larger ones stay empty.",
    )
    min_blob_px: int = Field(
        200,
        ge=0,
        description="Connected patches of splats smaller than this (pixels at 640x480, scaled "
        "with the image area) are dropped before hole filling: lone floaters would otherwise "
        "spread a wrong depth over a textureless hole (0 = keep all).",
    )
    occlusion_window_px: int = Field(
        7,
        ge=0,
        description="Remove splats seen through gaps of nearer surfaces: a pixel deeper than "
        "the nearest depth on both sides within this window by more than occlusion_rel_depth "
        "becomes a hole (pixels at 640 px width, scaled with the image; 0 = off).",
    )
    occlusion_rel_depth: float = Field(
        0.15, gt=0, description="Relative depth step of the occlusion test (fraction)."
    )
    camera_clearance_m: float = Field(
        0.15,
        ge=0,
        description="Points closer than this to a photo's camera centre are fusion artefacts "
        "(the robot stood there) and are dropped, metres (0 = keep).",
    )
    near_m: float = Field(0.05, gt=0, description="Near clipping distance, metres.")


class UlrConfig(Settings):
    """Unstructured lumigraph blending (Buehler et al. 2001)."""

    k: int = Field(4, ge=1, le=8, description="Sources blended per pixel (count).")
    angle_weight: float = Field(
        1.0, ge=0, description="Weight of the angular penalty (per radian between the rays)."
    )
    resolution_weight: float = Field(
        0.3,
        ge=0,
        description="Weight of the resolution penalty max(0, |P-Ci| - |P-C|) / |P-C| "
        "(per unit of relative extra distance).",
    )
    fov_weight: float = Field(
        0.5, ge=0, description="Weight of the field-of-view penalty near a source's border."
    )
    border_px: float = Field(
        12.0,
        gt=0,
        description="Field-of-view penalty ramps from 0 at this distance from the source's "
        "border to fov_weight at the border, pixels (source resolution).",
    )
    visibility_scale: float = Field(
        0.5,
        gt=0,
        le=1,
        description="Resolution of the proxy depth rendered into each source for visibility, "
        "as a fraction of the source photo size.",
    )
    visibility_tolerance: float = Field(
        0.05,
        gt=0,
        description="A source sees a point if its depth there is at most this fraction deeper "
        "than the proxy depth in that source (fraction).",
    )
    epsilon: float = Field(
        1e-3,
        gt=0,
        description="Blending weight (1 - p/p_k) / (p + epsilon): a source at the novel view's "
        "position dominates (epipole consistency); penalty units.",
    )
    max_sources: int = Field(
        24,
        ge=0,
        description="Per frame, only sources that are among some coarse-grid point's k+1 best "
        "angles are evaluated, at most this many (speed; 0 = evaluate every source).",
    )
    inpaint_px: int = Field(
        0,
        ge=0,
        description="Fill pixels that no source covers by image inpainting within this radius, "
        "pixels (0 = leave them black).",
    )


class PathConfig(Settings):
    """The tour path: a smooth closed spline at camera height through the free space."""

    frames: int = Field(300, ge=2, description="Frames of the tour (count).")
    cluster_radius_m: float = Field(
        0.25,
        gt=0,
        description="Camera positions closer than this are one waypoint of the tour, metres.",
    )
    clearance_m: float = Field(
        0.25,
        ge=0,
        description="Every path point keeps at least this distance from the dense cloud, metres.",
    )
    height_band_m: float = Field(
        0.2,
        gt=0,
        description="Dense points within this height of the camera plane are obstacles for the "
        "path (keep it below the camera's height above the floor), metres.",
    )
    obstacle_min_points: int = Field(
        20,
        ge=1,
        description="Dense points within clearance_m (in the camera's height band) that make "
        "an obstacle; fewer are floaters of the fusion (count).",
    )
    smoothing: float = Field(
        0.0,
        ge=0,
        description="Spline smoothing factor (scipy splprep s, m^2); 0 interpolates the waypoints.",
    )
    look_ahead_m: float = Field(
        0.6,
        gt=0,
        description="The camera looks along the path towards the point this far ahead, metres.",
    )
    sweep_deg: float = Field(
        35.0,
        ge=0,
        le=180,
        description="The heading sways by up to this angle around the travel direction, "
        "so the tour looks around the room, degrees.",
    )
    min_coverage: float = Field(
        0.05,
        ge=0,
        le=1,
        description="A tour pose is valid if the cloud's splats (before hole filling, at "
        "160x120 pixels) cover at least this fraction of its view; textureless walls leave "
        "the cloud sparse, so this only rejects views of (almost) nothing (fraction).",
    )
    use_freespace: bool = Field(
        True, description="Also keep the path inside the mesh stage's free space when present."
    )


class ViewerConfig(Settings):
    """The static web viewer."""

    viewpoints: int = Field(
        12, ge=1, description="Clickable viewpoints on the overview map (count)."
    )
    fps: float = Field(24.0, gt=0, description="Playback rate of the viewer and video, frames/s.")
    jpeg_quality: int = Field(88, ge=30, le=100, description="Quality of the frame JPEGs (%).")
    overview_cut_m: float = Field(
        0.5,
        description="The overview shows the cloud below this height above the cameras "
        "(cuts the ceiling away), metres.",
    )
    overview_px: int = Field(
        480, ge=64, description="Longest side of the top-down overview image, pixels."
    )


class TourConfig(Settings):
    """Settings of the tour stage: proxy, ULR renderer, tour path, video and viewer."""

    width: int = Field(640, ge=16, description="Width of the tour frames, pixels.")
    height: int = Field(480, ge=16, description="Height of the tour frames, pixels.")
    hfov_deg: float = Field(
        0.0,
        ge=0,
        lt=170,
        description="Horizontal field of view of the tour camera, degrees (0 = the photos').",
    )
    taichi_arch: Literal["auto", "cpu", "gpu"] = Field(
        "auto", description="Taichi arch: auto tries CUDA, then Vulkan, then CPU."
    )
    num_threads: int = Field(-1, description="CPU threads of taichi (-1 = all cores).")
    proxy: ProxyConfig = Field(default_factory=ProxyConfig)
    ulr: UlrConfig = Field(default_factory=UlrConfig)
    path: PathConfig = Field(default_factory=PathConfig)
    viewer: ViewerConfig = Field(default_factory=ViewerConfig)
    video: bool = Field(True, description="Write tour.mp4 (H.264 when imageio-ffmpeg is present).")
    eval_holdout: int = Field(
        24,
        ge=0,
        description="Photos held out for the leave-one-out quality check written with the tour "
        "(count, 0 = skip).",
    )
