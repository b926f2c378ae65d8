"""The map's point descriptors and a FLANN KD-tree index over them, built once and cached.

``round_{r}/sfm/point_descriptors.npz`` holds ``point_ids`` (N,) int64, ``xyz`` (N, 3) float64
and ``descriptors`` (N, 128) uint8: one row per observation of a 3D point (several rows per
point), descriptors as pycolmap's SIFT produces them. The paper precomputes a balanced
KD-tree and searches it with best-bin-first; here OpenCV's FLANN builds randomised KD-trees
(``flann_trees``) searched with a budget of ``flann_checks`` leaves. The index is saved next
to the descriptors (``point_descriptors.flann``) with a fingerprint of the descriptors, and
reused while the fingerprint matches.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

FLANN_KDTREE = 1


@dataclass(frozen=True)
class MapDescriptors:
    """Descriptors of the map's 3D points.

    Attributes:
        point_ids: (N,) int64 3D point id of each row.
        xyz: (N, 3) float64 position of that point (m, map frame).
        descriptors: (N, 128) uint8 SIFT descriptors.
    """

    point_ids: np.ndarray
    xyz: np.ndarray
    descriptors: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.point_ids)
        if self.xyz.shape != (n, 3) or self.descriptors.shape != (n, 128):
            raise ValueError(
                "point descriptors: expected point_ids (N,), xyz (N, 3), descriptors (N, 128); "
                f"got {self.point_ids.shape}, {self.xyz.shape}, {self.descriptors.shape}"
            )

    @staticmethod
    def load(path: Path) -> MapDescriptors:
        """Read ``point_descriptors.npz``.

        Raises:
            FileNotFoundError: no such file (the sfm stage writes it).
            ValueError: arrays missing or of the wrong shape or type.
        """
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(
                f"{path}: no point descriptors; the sfm stage writes point_descriptors.npz"
            )
        with np.load(path) as z:
            missing = {"point_ids", "xyz", "descriptors"} - set(z.files)
            if missing:
                raise ValueError(f"{path}: missing arrays {sorted(missing)}")
            d = z["descriptors"]
            if d.dtype != np.uint8:
                raise ValueError(f"{path}: descriptors must be uint8 (COLMAP scale), got {d.dtype}")
            return MapDescriptors(z["point_ids"].astype(np.int64), z["xyz"].astype(np.float64), d)

    def fingerprint(self) -> str:
        """A hash of the descriptors and point ids (to validate a cached index)."""
        h = hashlib.blake2b(digest_size=16)
        h.update(np.ascontiguousarray(self.descriptors).tobytes())
        h.update(np.ascontiguousarray(self.point_ids).tobytes())
        return h.hexdigest()


class DescriptorIndex:
    """Approximate nearest neighbours of SIFT descriptors (FLANN randomised KD-trees).

    Args:
        descriptors: (N, 128) uint8 map descriptors.
        trees: number of randomised KD-trees.
        checks: leaves visited per query.
        index_file: a saved index of exactly these descriptors to load instead of building.
    """

    def __init__(
        self,
        descriptors: np.ndarray,
        trees: int = 4,
        checks: int = 32,
        index_file: Path | None = None,
    ):
        if len(descriptors) < 2:
            raise ValueError("DescriptorIndex: the map has fewer than 2 point descriptors")
        # FLANN keeps a pointer to this array: hold it for the index's lifetime.
        self._data = np.ascontiguousarray(descriptors, dtype=np.float32)
        self.trees = trees
        self.checks = checks
        if index_file is not None:
            self._index = cv2.flann_Index()
            if not self._index.load(self._data, str(index_file)):
                raise OSError(f"{index_file}: cannot load the FLANN index")
        else:
            self._index = cv2.flann_Index(self._data, {"algorithm": FLANN_KDTREE, "trees": trees})

    def __len__(self) -> int:
        return len(self._data)

    def save(self, path: Path) -> None:
        self._index.save(str(path))

    def knn(self, query: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest map descriptors of each query descriptor.

        Args:
            query: (Q, 128) uint8 or float32 descriptors.
            k: neighbours per query (at most the map size).

        Returns:
            indices (Q, k) int64 into the map rows, distances (Q, k) float32 Euclidean,
            ascending along each row.
        """
        q = np.ascontiguousarray(query, dtype=np.float32).reshape(-1, 128)
        k = min(k, len(self._data))
        if len(q) == 0:
            return np.zeros((0, k), np.int64), np.zeros((0, k), np.float32)
        idx, d2 = self._index.knnSearch(q, k, params={"checks": self.checks})
        return idx.astype(np.int64), np.sqrt(np.maximum(d2, 0.0))

    @staticmethod
    def cached(
        desc: MapDescriptors, cache_file: Path | None, trees: int = 4, checks: int = 32
    ) -> DescriptorIndex:
        """Load the index from ``cache_file`` if it was built from ``desc``; else build it and
        save it there (``cache_file`` None: build, do not cache).

        A sidecar ``<cache_file>.json`` records the descriptor fingerprint and the tree count.
        """
        if cache_file is None:
            return DescriptorIndex(desc.descriptors, trees, checks)
        cache_file = Path(cache_file)
        meta_file = cache_file.with_suffix(cache_file.suffix + ".json")
        meta = {"fingerprint": desc.fingerprint(), "trees": trees, "n": len(desc.point_ids)}
        if cache_file.exists() and meta_file.exists():
            try:
                if json.loads(meta_file.read_text(encoding="utf-8")) == meta:
                    return DescriptorIndex(desc.descriptors, trees, checks, index_file=cache_file)
            except (OSError, ValueError):
                pass  # stale or damaged cache: rebuild below
        index = DescriptorIndex(desc.descriptors, trees, checks)
        try:
            index.save(cache_file)
            meta_file.write_text(json.dumps(meta), encoding="utf-8")
        except OSError:
            pass  # read-only map folder: work without a cache
        return index
