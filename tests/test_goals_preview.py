"""The preview of each shot advised to a person (goals_preview.png) on real photos: the
Middlebury temple ring (tests/data/temple, 16 photos), mapped by the sfm stage.

Ground truth: a view at a photo's own pose must reproduce that photo (the renderer's proxy is
only the sparse map's points) with little marked missing; a view looking out of the ring, away
from everything the photos saw, must be marked mostly missing.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import cv2
import numpy as np
import pytest

TEMPLE = Path(__file__).resolve().parent / "data" / "temple"

pytestmark = pytest.mark.slow  # sfm of 16 photos (~15 s)


@pytest.fixture(scope="module")
def temple(tmp_path_factory):
    from scenebot.goals.preview import ShotPreviewer
    from scenebot.sfm.config import SfmConfig
    from scenebot.sfm.stage import SfmInputs, SfmOutputs
    from scenebot.sfm.stage import run as sfm_run
    from scenebot.tour.config import TourConfig

    root = tmp_path_factory.mktemp("temple")
    photos = root / "photos"
    photos.mkdir()
    for f in sorted(TEMPLE.glob("*.jpg")):
        shutil.copy(f, photos / f.name)  # never touch the set itself
    sfm_run(SfmConfig(), SfmInputs(root / "db" / "database.db", photo_folder=photos),
            SfmOutputs(root / "sfm"))  # fmt: skip
    tour_cfg = TourConfig.model_validate({"taichi_arch": "cpu"})
    return root, tour_cfg, ShotPreviewer(tour_cfg, root / "sfm", photos, 240)


def _psnr(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    err = (a.astype(np.float64) - b.astype(np.float64))[mask]
    return float(10 * np.log10(255.0**2 / max(np.mean(err**2), 1e-12)))


def test_a_photos_own_view_reproduces_it_and_little_is_missing(temple):
    _, _, pv = temple
    for s in (0, 7):
        src = pv.renderer.sources[s]
        cam = src.camera.resized(pv.camera.width, pv.camera.height)
        p = pv.render(src.R, src.t, cam)
        truth = cv2.resize(src.image, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
        seen = ~p.missing
        psnr = _psnr(p.render, truth, seen)
        print(f"photo {s}: PSNR {psnr:.1f} dB over the seen pixels, "
              f"{100 * p.missing_fraction:.1f}% missing, {p.seconds:.2f} s")  # fmt: skip
        assert p.missing_fraction < 0.1
        assert psnr > 28.0
        # the tint marks exactly the missing pixels
        changed = np.any(p.image != p.render, axis=2)
        assert not changed[seen].any()


def test_a_view_away_from_everything_seen_is_mostly_missing(temple):
    _, _, pv = temple
    src = pv.renderer.sources[0]
    # from the photo's position, turned round: out of the ring, at nothing a photo saw
    flip = np.diag([-1.0, 1.0, -1.0])
    R = flip @ src.R
    t = -R @ src.center
    p = pv.render(R, t)
    print(f"turned round: {100 * p.missing_fraction:.1f}% missing, {p.seconds:.2f} s")
    assert p.missing_fraction > 0.9
    red = p.image[p.missing].astype(int)
    assert np.all(red[:, 0] >= red[:, 1])  # tinted red


def test_the_command_writes_one_tile_per_goal(temple, tmp_path):
    from scenebot.goals.config import GoalsConfig
    from scenebot.goals.preview import PreviewInputs, PreviewOutputs, run

    root, tour_cfg, pv = temple
    goals = []
    for rank, s in enumerate((3, 0)):
        src = pv.renderer.sources[s]
        fwd = src.R[2] * (1 if rank == 0 else -1)  # the second looks out of the ring
        x, y, z = src.center
        goals.append({"rank": rank, "x": x, "y": y, "z": z, "score_deg": 12.5 - rank,
                      "theta": float(np.arctan2(fwd[1], fwd[0])),
                      "pitch": float(np.arcsin(np.clip(fwd[2], -1, 1)))})  # fmt: skip
    gj = tmp_path / "goals.json"
    gj.write_text(json.dumps({"round": "round_000", "goals": goals}))
    png = tmp_path / "goals_preview.png"
    out = run(GoalsConfig(preview_width=160), tour_cfg,
              PreviewInputs(root / "sfm", root / "photos", gj), PreviewOutputs(png))  # fmt: skip
    img = cv2.imread(str(png))
    assert img is not None and img.shape[1] >= 2 * 160
    first, second = out["shots"]
    print(out)
    # a goal along photo 3's axis (its roll removed) still sees what photo 3 saw
    assert first["missing_fraction"] < 0.2 < 0.9 < second["missing_fraction"]
    assert first["score_deg"] == 12.5
