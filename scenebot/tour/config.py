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
    see_through_tolerance: float = Field(
        0.15,
        gt=0,
        description="A source that sees a surface more than this fraction deeper than the "
        "point looks through it: the point is empty space (a guess of the hole filling, e.g. "
        "beside an object's silhouette) and that source does not colour it (fraction).",
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
        description="Fill pixels without any proxy surface (the only ones left black: a "
        "point no photo sees takes the dense cloud's colour) by image inpainting within this "
        "radius, pixels (0 = leave them black).",
    )


class PathConfig(Settings):
    """The tour path: a smooth walk through the photos' positions, looking at what they show.

    The robot's photos: the path in the camera plane, a level camera. A person's photos
    (``robot: photos``): a 3-D path, the camera pitched towards what the photos show, and the
    lengths (``*_m``) scaled to the scene (``tour.photos_depth_m``)."""

    frames: int = Field(300, ge=2, description="Frames of the tour (count).")
    cluster_radius_m: float = Field(
        0.25,
        gt=0,
        description="Camera positions closer than this are one stop of the tour, metres.",
    )
    open_gap: float = Field(
        2.5,
        gt=1,
        description="The shortest loop through the stops is opened at its longest leg when "
        "that leg is longer than this many median legs (a ring of photos with a gap, a walk "
        "along a facade), so the tour never jumps across the scene (ratio).",
    )
    blocked_cost: float = Field(
        10.0,
        ge=1,
        description="A straight leg between two stops that crosses an obstacle (clearance or "
        "free space) counts this many times its length when ordering the stops (ratio; 1 = "
        "ignore obstacles).",
    )
    clearance_m: float = Field(
        0.25,
        ge=0,
        description="Every path point keeps at least this distance from the dense cloud: "
        "horizontally from the points in the camera's height band (robot), in 3-D (a person's "
        "photos), metres.",
    )
    height_band_m: float = Field(
        0.2,
        gt=0,
        description="Robot: dense points within this height of the camera plane are obstacles "
        "for the path (keep it below the camera's height above the floor), metres.",
    )
    obstacle_min_points: int = Field(
        20,
        ge=1,
        description="Dense points within the clearance that make an obstacle; fewer are "
        "floaters of the fusion (count).",
    )
    smoothing: float = Field(
        0.0,
        ge=0,
        description="The spline may pass up to about this many median legs (RMS) from the "
        "stops, so that it turns more gently (fraction; 0 = through every stop).",
    )
    look_bandwidth: float = Field(
        0.5,
        gt=0,
        description="A path point looks at the mean target of the photos near it: Gaussian "
        "weights over the distance, with this width in median legs between stops (ratio).",
    )
    look_smoothing: float = Field(
        0.02,
        ge=0,
        description="Gaussian smoothing of the viewing direction along the tour, as a fraction "
        "of its frames (fraction; 0 = none).",
    )
    max_turn_deg: float = Field(
        3.0,
        gt=0,
        description="The view turns (heading or pitch) by at most this angle from one frame to "
        "the next, or twice its mean turn per frame where a short tour must turn more, "
        "degrees.",
    )
    sweep_deg: float = Field(
        35.0,
        ge=0,
        le=180,
        description="Where the photos near a path point look every way (a robot's circle of "
        "photos), the camera looks along the path, swaying by up to this angle so the tour "
        "looks around, degrees.",
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
        True,
        description="Robot: also keep the path inside the mesh stage's free space when present "
        "(a person's photos never use it).",
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
    overview_margin_m: float = Field(
        0.3, ge=0, description="Border of the overview around the cloud and the path, metres."
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
    photos_depth_m: float = Field(
        2.0,
        gt=0,
        description="A person's photos (robot: photos) carry no metric scale the tour relies "
        "on (sfm.known_distance or not): every length setting of the tour (the *_m fields) "
        "is scaled so that the photos' median distance to what they see (sparse model) "
        "counts as this many metres.",
    )
    eval_holdout: int = Field(
        24,
        ge=0,
        description="Photos held out for the leave-one-out quality check written with the tour "
        "(count, 0 = skip).",
    )
