"""Nearest cloud point of a few query points.

The tracker asks this for its handful of end-effectors every frame. Building a KD-tree for a
cloud of ~1-3 k points costs more than comparing the few queries with every point, so this is
a brute-force search in chunks (bounded memory for any number of queries).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import numpy.typing as npt

_CHUNK = 64  # queries per pass: (N, 64) float64 scratch


def nearest_point(points: npt.NDArray[np.float64], queries: npt.NDArray[np.float64],
                  ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]]:
    """Distance to and index of the nearest of ``points`` (N, 3), N >= 1, for each of
    ``queries`` (M, 3); like ``cKDTree(points).query(queries)``."""
    queries = np.asarray(queries, dtype=np.float64).reshape(-1, 3)
    index = np.zeros(len(queries), dtype=np.intp)
    cols = [np.ascontiguousarray(points[:, a])[:, None] for a in range(3)]
    for start in range(0, len(queries), _CHUNK):
        q = queries[start:start + _CHUNK]
        d2 = (cols[0] - q[:, 0]) ** 2
        d2 += (cols[1] - q[:, 1]) ** 2
        d2 += (cols[2] - q[:, 2]) ** 2
        index[start:start + len(q)] = np.argmin(d2, axis=0)
    dist = np.sqrt(((points[index] - queries) ** 2).sum(axis=1))
    return dist, index
