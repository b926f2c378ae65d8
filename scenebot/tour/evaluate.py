"""Quality of view synthesis: leave-one-out PSNR/SSIM of ULR against nearest-photo baselines.

Protocol: hold out ``n`` registered photos (evenly spread over the sorted names); render each
from the *other* photos at its SfM pose and compare with the photo itself (a true render in
the simulator). Two baselines in the same run: the photo with the nearest pose shown as is
("nearest photo"), and that single photo reprojected through the proxy ("nearest photo
reprojected"; ULR restricted to one source, holes black).

The proxy is the dense cloud fused from all photos, the held-out one included (re-fusing it
per held-out photo would re-run the dense stage): its geometry, and the colour of the few
points no other photo sees (``proxy_colour_fraction`` of the view), may still carry the
held-out photo.
"""

from __future__ import annotations

import cv2
import numpy as np

from scenebot.tour.ulr import UlrRenderer


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR (dB) of two uint8 images of the same shape (peak 255)."""
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(255.0**2 / mse)


def ssim(a: np.ndarray, b: np.ndarray) -> float:
    """Mean SSIM (Wang et al. 2004; Gaussian window sigma 1.5, on luma) of two uint8 images."""

    def luma(x):
        x = x.astype(np.float64)
        return x if x.ndim == 2 else x @ np.array([0.299, 0.587, 0.114])

    x, y = luma(a), luma(b)
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2

    def blur(v):
        return cv2.GaussianBlur(v, (11, 11), 1.5)

    mx, my = blur(x), blur(y)
    sxx = blur(x * x) - mx * mx
    syy = blur(y * y) - my * my
    sxy = blur(x * y) - mx * my
    s = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2))
    return float(s.mean())


def nearest_source(renderer: UlrRenderer, j: int, angle_m_per_rad: float = 0.5) -> int:
    """Index of the photo whose pose is nearest to photo ``j`` (itself excluded).

    Distance = centre distance (m) + ``angle_m_per_rad`` x viewing-direction angle (rad).
    """
    src = renderer.sources
    c = renderer.centers
    fwd = np.array([s.R[2] for s in src])
    d = np.linalg.norm(c - c[j], axis=1)
    ang = np.arccos(np.clip(fwd @ fwd[j], -1, 1))
    score = d + angle_m_per_rad * ang
    score[j] = np.inf
    return int(np.argmin(score))


def holdout_indices(n_sources: int, n: int) -> list[int]:
    """``n`` indices evenly spread over ``range(n_sources)``."""
    n = min(n, n_sources)
    return sorted({int(v) for v in np.rint(np.linspace(0, n_sources - 1, n))})


def leave_one_out(renderer: UlrRenderer, n_holdout: int = 24, progress: bool = True) -> dict:
    """Leave-one-out quality of the renderer and the two baselines.

    Args:
        renderer: a renderer over all photos.
        n_holdout: number of held-out photos.
        progress: show a progress bar.

    Returns:
        dict with ``per_view`` rows (name, psnr/ssim of ulr, nearest, nearest_reprojected,
        coverage, black and dense-cloud-coloured fractions of the ULR view) and ``summary``
        (mean and median of each metric).
    """
    from tqdm import tqdm

    if renderer.num_sources < 2:
        raise ValueError("leave-one-out needs at least 2 photos")
    rows = []
    idx = holdout_indices(renderer.num_sources, n_holdout)
    for j in tqdm(idx, desc="tour eval (leave-one-out)", disable=not progress):
        s = renderer.sources[j]
        ulr = renderer.render(s.camera, s.R, s.t, exclude={j})
        nn = nearest_source(renderer, j)
        plain = renderer.sources[nn].image
        if plain.shape != s.image.shape:
            plain = cv2.resize(plain, (s.image.shape[1], s.image.shape[0]))
        rep = renderer.render(s.camera, s.R, s.t, only={nn}, k=1, fill=False)
        rows.append(
            {
                "name": s.name,
                "nearest": renderer.sources[nn].name,
                "coverage": ulr.coverage,
                "black_fraction": ulr.black_fraction,
                "proxy_colour_fraction": ulr.fill_fractions()["proxy"],
                "psnr_ulr": psnr(ulr.image, s.image),
                "ssim_ulr": ssim(ulr.image, s.image),
                "psnr_nearest": psnr(plain, s.image),
                "ssim_nearest": ssim(plain, s.image),
                "psnr_nearest_reprojected": psnr(rep.image, s.image),
                "ssim_nearest_reprojected": ssim(rep.image, s.image),
            }
        )
    keys = [k for k in rows[0] if k.startswith(("psnr", "ssim", "coverage", "black", "proxy"))]
    summary = {
        "n_holdout": len(rows),
        **{f"mean_{k}": float(np.mean([r[k] for r in rows])) for k in keys},
        **{f"median_{k}": float(np.median([r[k] for r in rows])) for k in keys},
    }
    return {"per_view": rows, "summary": summary}
