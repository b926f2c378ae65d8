"""Steps 3 and 4 of the plane fill, in one view: labels and votes.

**Labels**: a measured pixel carries the label of the plane it lies on (within
``distance_m`` or ``rel_distance`` of its depth), or "off-plane" (:func:`pixel_labels`).
**Votes**: on a grid of ``cell_px`` cells, every cell without measured depth looks along 8
directions, up to ``max_gap_frac`` of the image width, for the nearest cell with measured
depth, and counts the planes those cells lie on (:func:`neighbour_votes`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenebot.dense.planes.geometry import Plane, backproject

#: the 8 search directions (row step, column step)
DIRECTIONS = ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))


def pixel_labels(
    depth: np.ndarray,
    measured: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    planes: list[Plane],
    distance_m: float,
    rel_distance: float,
) -> np.ndarray:
    """(H, W) int32: the plane each measured pixel lies on (the nearest within the larger
    of ``distance_m`` and ``rel_distance`` of its depth), -1 where it lies on none or has
    no depth."""
    h, w = depth.shape
    X = backproject(depth, K, R, t)
    label = np.full((h, w), -1, np.int32)  # -1: measured, off every plane
    best = np.full((h, w), np.inf)
    tol = np.maximum(distance_m, rel_distance * depth)
    for j, pl in enumerate(planes):
        dist = np.abs(X @ pl.normal + pl.offset)
        on = measured & (dist < tol) & (dist < best)
        label[on], best[on] = j, dist[on]
    return label


@dataclass
class CellVotes:
    """The view's ``cell_px`` cells and what their nearest measured cells say.

    Attributes:
        cell_label: (hc, wc) the most common label of a cell's measured pixels (-1: off
            every plane), -2 where the cell has none.
        cell_measured: (hc, wc) bool: the cell holds measured depth.
        votes: (P, hc, wc) of the 8 directions, how many find a cell of each plane first.
        found: (hc, wc) how many of the 8 directions find a measured cell at all.
    """

    cell_label: np.ndarray
    cell_measured: np.ndarray
    votes: np.ndarray
    found: np.ndarray

    def agree(self, count: np.ndarray, min_votes: int, min_agreement: float) -> np.ndarray:
        """(hc, wc) bool: ``count`` (votes per cell) reaches ``min_votes`` and
        ``min_agreement`` of the directions that found measured depth."""
        return (count >= min_votes) & (count >= min_agreement * np.maximum(self.found, 1))


def neighbour_votes(
    label: np.ndarray, measured: np.ndarray, n_planes: int, cell_px: int, max_gap_frac: float
) -> CellVotes:
    """Label every ``cell_px`` cell by its measured pixels and count, per plane, the
    directions in which a hole's nearest measured cell (at most ``max_gap_frac`` of the
    image width away) lies on it."""
    h, w = label.shape
    hc, wc = -(-h // cell_px), -(-w // cell_px)
    pad = ((0, hc * cell_px - h), (0, wc * cell_px - w))
    lab = np.pad(np.where(measured, label, -3), pad, constant_values=-3)
    lab = lab.reshape(hc, cell_px, wc, cell_px).transpose(0, 2, 1, 3).reshape(hc, wc, -1)
    counts = np.stack([(lab == j).sum(-1) for j in range(-1, n_planes)], -1)
    cell_measured = counts.sum(-1) > 0
    cell_label = np.where(cell_measured, counts.argmax(-1) - 1, -2).astype(np.int32)
    near = _nearest_labels(cell_label, cell_measured, max(1, int(max_gap_frac * wc)))
    found = (near >= -1).sum(0)
    votes = np.stack([(near == j).sum(0) for j in range(n_planes)])
    return CellVotes(cell_label, cell_measured, votes, found)


def _nearest_labels(cell_label: np.ndarray, measured: np.ndarray, max_steps: int) -> np.ndarray:
    """(8, h, w) label of the nearest measured cell in each direction (-2: none found)."""
    h, w = cell_label.shape
    out = np.full((len(DIRECTIONS), h, w), -2, np.int32)
    rows, cols = np.mgrid[0:h, 0:w]
    for k, (dr, dc) in enumerate(DIRECTIONS):
        found = np.zeros((h, w), bool)
        for s in range(1, max_steps + 1):
            r, c = rows + dr * s, cols + dc * s
            ok = (r >= 0) & (r < h) & (c >= 0) & (c < w) & ~found
            if not ok.any():
                break
            rr, cc = r[ok], c[ok]
            hit = measured[rr, cc]
            sel = np.flatnonzero(ok)[hit]
            out[k].flat[sel] = cell_label[rr[hit], cc[hit]]
            found.flat[sel] = True
    return out
