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

from scenebot.dense.planes.geometry import Plane, backproject_pixels

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
    label = np.full((h, w), -1, np.int32)  # -1: measured, off every plane
    v, u = np.nonzero(measured)  # only measured pixels can lie on a plane
    d = depth[v, u]
    X = backproject_pixels(d, v, u, K, R, t)
    lab = label[v, u]
    best = np.full(len(d), np.inf)
    tol = np.maximum(distance_m, rel_distance * d)
    for j, pl in enumerate(planes):
        dist = np.abs(X @ pl.normal + pl.offset)
        on = (dist < tol) & (dist < best)
        lab[on], best[on] = j, dist[on]
    label[v, u] = lab
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
    """(8, h, w) label of the nearest measured cell in each direction, at most ``max_steps``
    cells away (-2: none found)."""
    out = np.full((len(DIRECTIONS), *cell_label.shape), -2, np.int32)
    for k, (dr, dc) in enumerate(DIRECTIONS):
        lab, meas, along_row = cell_label, measured, dr == 0
        if along_row:  # down the columns of the transposed grid
            lab, meas, dr, dc = lab.T, meas.T, dc, 0
        if dr < 0:  # up: down the rows of the flipped grid
            lab, meas = lab[::-1], meas[::-1]
        near = _unshear(_nearest_below(_shear(lab, dc, -2), _shear(meas, dc, False), max_steps), dc)
        near = near[::-1] if dr < 0 else near
        out[k] = near.T if along_row else near
    return out


def _shear(a: np.ndarray, dc: int, fill) -> np.ndarray:
    """(h, w + h - 1) grid in which the step (1, dc) from (r, c) stays in its column: row
    r shifted by ``-dc * r`` (``fill`` outside the grid); ``a`` itself for dc = 0."""
    if dc == 0:
        return a
    h, w = a.shape
    out = np.full((h, w + h - 1), fill, a.dtype)
    rows = np.arange(h)[:, None]
    out[rows, np.arange(w) - dc * rows + (h - 1 if dc > 0 else 0)] = a
    return out


def _unshear(a: np.ndarray, dc: int) -> np.ndarray:
    """The (h, w) grid of a :func:`_shear` result."""
    if dc == 0:
        return a
    h = a.shape[0]
    w = a.shape[1] - h + 1
    rows = np.arange(h)[:, None]
    return a[rows, np.arange(w) - dc * rows + (h - 1 if dc > 0 else 0)]


def _nearest_below(label: np.ndarray, measured: np.ndarray, max_steps: int) -> np.ndarray:
    """(h, w) label of the nearest measured cell below each cell in its column, at most
    ``max_steps`` rows away (-2: none)."""
    h = label.shape[0]
    rows = np.arange(h)[:, None]
    at = np.where(measured, rows, h)  # row of a measured cell, h: none
    nxt = np.minimum.accumulate(at[::-1], axis=0)[::-1]  # nearest measured row at or below
    nxt = np.vstack([nxt[1:], np.full((1, label.shape[1]), h)])  # strictly below
    found = (nxt < h) & (nxt - rows <= max_steps)
    cols = np.broadcast_to(np.arange(label.shape[1]), label.shape)
    return np.where(found, label[np.minimum(nxt, h - 1), cols], -2).astype(np.int32)
