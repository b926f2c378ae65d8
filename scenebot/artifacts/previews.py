"""``round_XXX/goals_preview.npz``: each shot advised to a person rendered from the photos
(written by the goals preview, read by the guide page)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class ShotPreviews:
    """The previews of a round's advised shots, in goals.json's order.

    Attributes:
        ranks: (K,) the goals' ranks.
        images: (K, H, W, 3) uint8 RGB, each preview tinted red where no photo sees it.
        missing: (K, H, W) bool, those pixels.
    """

    ranks: np.ndarray
    images: np.ndarray
    missing: np.ndarray

    def missing_fraction(self, k: int) -> float:
        """Share of preview ``k`` no photo sees."""
        return float(self.missing[k].mean()) if self.missing[k].size else 0.0


def write_previews(path: str | Path, ranks: list[int], images: list[np.ndarray],
                   missing: list[np.ndarray]) -> None:  # fmt: skip
    """Write ``goals_preview.npz`` (K = 0: empty arrays of shape (0, 1, 1, 3), (0, 1, 1))."""
    imgs = np.stack(images).astype(np.uint8) if images else np.zeros((0, 1, 1, 3), np.uint8)
    miss = np.stack(missing).astype(bool) if missing else np.zeros((0, 1, 1), bool)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:  # np.savez would add ".npz" to a name without it
        np.savez_compressed(f, ranks=np.array(ranks, np.int64), images=imgs, missing=miss)


def read_previews(path: str | Path) -> ShotPreviews:
    """Read ``goals_preview.npz``.

    Raises:
        FileNotFoundError: no such file (named, with the rule that writes it).
        ValueError: the arrays do not agree.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no shot previews; the goals_preview rule writes them")
    with np.load(path) as z:
        out = ShotPreviews(z["ranks"], z["images"], z["missing"])
    n = len(out.ranks)
    if out.images.shape[0] != n or out.missing.shape[0] != n or out.images.ndim != 4:
        raise ValueError(f"{path}: {n} ranks but images {out.images.shape}, missing "
                         f"{out.missing.shape}")  # fmt: skip
    return out
