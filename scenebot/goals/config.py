"""Settings of the goals stage (``goals:`` in config.yaml)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from scenebot.settings import Settings


class GoalsConfig(Settings):
    """Choice of goals among the scored candidates (``goals`` stage)."""

    method: Literal["score", "frontier"] = Field(
        "score",
        description="score: the paper's heuristic (poorest predicted rendering first); "
        "frontier: the baseline, nearest boundary between seen and unseen free space first.",
    )
    k: int = Field(5, ge=1, description="Most goals chosen per round (count).")
    backups: int = Field(
        5,
        ge=0,
        description="Next-ranked candidates listed as backups: the plan stage takes one in "
        "place of a goal it cannot route to (inside an obstacle of its grid, outside it, or "
        "walled off).",
    )
    frontier_range_m: float = Field(
        3.0, gt=0, description="frontier: a photo sees free space up to this distance (m)."
    )
    frontier_min_area_m2: float = Field(
        0.25, ge=0, description="frontier: unseen free space in smaller pieces is ignored (m^2)."
    )
    frontier_look_m: float = Field(
        1.0, gt=0, description="frontier: a goal looks at the unseen free space this near (m)."
    )
    open_frontiers: bool = Field(
        False,
        description="The score's goals come after the free space's open frontiers: where the "
        "free space ends at space the mesh does not enclose (no wall bounds it: a doorway's "
        "far side), a goal looks across, widest opening first (up to k a round; "
        "scenebot.goals.frontier.open_frontier_goals); a place visited for one is not asked "
        "for again, and the map is not complete while one is left. The score cannot value "
        "space the mesh does not contain. Openings narrower than the robot's radius do not "
        "count. Off by default: measured with and without on shared round 0s (docs/results.md), "
        "the flat 30.9% against 29.8% at 2 cm and rooms6 53.8% against 51.1%, but a second "
        "rooms6 campaign with it 29.3% (its corridor goals unreachable on its map): the "
        "frontier photos often do not join the map. false: the score's goals alone (the "
        "paper).",
    )
    nms_radius_m: float = Field(
        0.5, ge=0.0, description="Two goals closer than this (m) must differ in heading."
    )
    nms_angle_deg: float = Field(
        45.0, ge=0.0, le=180.0, description="...by more than this heading difference (degrees)."
    )
    complete_threshold_deg: float = Field(
        10.0,
        ge=0.0,
        description="Exploration is complete when the best (highest) view score is below this.",
    )
    min_score_gain: float = Field(
        0.15,
        ge=0.0,
        lt=1.0,
        description="Diminishing returns: exploration is also complete when, since the "
        "previous round, the mean view score over the candidates (the predicted rendering "
        "error over the free space) moved by less than this fraction either way and the free "
        "space grew by less than min_area_gain. The best score alone rarely falls below "
        "complete_threshold_deg: a view of never-photographed surface (ceiling, behind "
        "furniture) keeps it high. 0: off.",
    )
    min_area_gain: float = Field(
        0.1,
        ge=0.0,
        description="See min_score_gain: a round whose photos added free space the map did "
        "not know (farther than new_area_margin_m from the previous round's free space) of "
        "this fraction of the previous free area or more opened space (another room, a "
        "corridor), and exploration goes on. Without the previous round's free space: the "
        "net growth of the free area.",
    )
    patience: int = Field(
        2,
        ge=1,
        description="Diminishing returns must hold in this many consecutive rounds: one "
        "round's gain varies from campaign to campaign (the same office: 12% in one, 22% in "
        "another), so a single low round does not end the campaign. Also the idle rounds in "
        "a row (most of their new photos not in the map) before the campaign stops as stuck "
        "(scenebot.goals.failures).",
    )
    new_area_margin_m: float = Field(
        0.3,
        ge=0.0,
        description="Free space within this distance (m) of the previous round's does not "
        "count as new (its outline moves a little as the map improves).",
    )
    min_seen_fraction: float = Field(
        0.4,
        ge=0.0,
        le=1.0,
        description="Candidates whose view shows less of the map's already photographed "
        "surface than this share of its pixels are not goals: a photo there could not be "
        "registered to the map (too little overlap). 0: the paper's choice, overlap ignored.",
    )
    min_matchable_points: int = Field(
        100,
        ge=0,
        description="Candidates predicted to match fewer of the map's 3D points than this "
        "(candidates.csv `matchable_points`: in view, seen within score.match_angle_deg and "
        "score.match_scale_ratio of how the map saw them) are not goals: their photos would "
        "not register. An area of photographed surface is not enough: a plain wall at a "
        "grazing angle has no features. 0: off.",
    )
    person_min_matchable_share: float = Field(
        0.7,
        ge=0.0,
        description="A person's shots (robot: photos, guided, person-sim) must be predicted to "
        "match at least this share of the map points the map's median photo observes (and "
        "goals.min_matchable_points): a person's photo has no robot estimate to register "
        "from, only its matches. Measured on a guided office round (74-photo walk, its "
        "median photo 570 points): shots of 102-1,160 predicted points (min_matchable_points "
        "alone) put 9 of 17 photos 0.3-59 m off; shots of 400 or more, 1 of 17. 0 (or "
        "goals.min_matchable_points 0): off.",
    )
    person_min_depth_m: float = Field(
        0.0,
        ge=0.0,
        description="A person's shots must see their surface from at least this far (m, the "
        "median depth of the round's mesh in view; scenebot.goals.depth): a close-up of a "
        "wall does not register. Measured on the guided photos of the flat (50) and the "
        "office (75): under 0.8 m 3 of 19 joined the map, 0.8-2 m 33 of 52, beyond 2 m 50 "
        "of 54. With 0.8 the office's guided campaign reached 95.1% at 2 cm and the flat's "
        "55.2% (66.1% without it; its map less accurate, a confounded comparison: "
        "docs/results.md), so it is off until a clean comparison says it helps. 0: off.",
    )
    min_hit_fraction: float = Field(
        0.2,
        ge=0.0,
        le=1.0,
        description="Candidates whose render hits the mesh on fewer pixels than this are skipped.",
    )
    preview_width: int = Field(
        240,
        ge=16,
        le=2000,
        description="robot: photos: width (pixels) of each advised shot's preview in "
        "goals_preview.png (the view rendered from the photos by the tour's renderer, "
        "tour.ulr and tour.proxy settings; the height keeps the photos' aspect).",
    )
