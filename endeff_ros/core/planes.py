"""Planes in point clouds: RANSAC hypotheses, least-squares refinement, and the area a
plane's points show (their pixels' footprints on it), shared by the floor (:mod:`.floor`) and
the walls and table tops (:mod:`.surfaces`)."""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import numpy.typing as npt


@functools.lru_cache(maxsize=8)
def hypothesis_triples(n: int, iterations: int) -> npt.NDArray[np.int64]:
    """Index triples of the RANSAC hypotheses: drawn once per sample size (seed 0)."""
    idx = np.random.default_rng(0).integers(0, n, size=(iterations, 3))
    idx.flags.writeable = False
    return idx


def plane_hypotheses(points: npt.NDArray[np.float64], idx: npt.NDArray[np.int64],
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Unit normals and one point each of the planes through the index triples ``idx`` (H, 3)
    of ``points``; degenerate (collinear) triples are left out."""
    p0, p1, p2 = points[idx[:, 0]], points[idx[:, 1]], points[idx[:, 2]]
    a, b = p1 - p0, p2 - p0
    normals = np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],  # a x b (np.cross is slower)
                        a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                        a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9
    return normals[ok] / norms[ok, None], p0[ok]


#: Sample points whose least-squares plane is one local floor hypothesis (see
#: :func:`.floor.fit_floor`): on a 512-1024 point sample of the box, a patch some 10-30 cm across
#: (larger patches reached over walls and legs on a hall's floor 3-5 m away; 8 and 12 gave
#: the mocap dev subset the same scores: docs/design.md, "Floor hypotheses").
_LOCAL_NEIGHBOURS = 6


def local_plane_hypotheses(points: npt.NDArray[np.float64], seeds: npt.NDArray[np.int64],
                           ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Unit normals and centres of the least-squares planes of each seed's
    ``_LOCAL_NEIGHBOURS`` nearest ``points`` (a batched eigen-decomposition)."""
    from scipy.spatial import cKDTree

    k = min(_LOCAL_NEIGHBOURS, len(points))
    _, near = cKDTree(points).query(points[seeds], k=k)
    patch = points[near.reshape(len(seeds), k)]
    centres = patch.mean(axis=1)
    d = patch - centres[:, None]
    normals = np.linalg.eigh(np.einsum('hki,hkj->hij', d, d))[1][:, :, 0]
    return normals, centres


def refine_plane(points: npt.NDArray[np.float64],
                 normal: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], float]:
    """Least-squares plane through ``points``, oriented like ``normal``."""
    centre = points.mean(axis=0)
    d = points - centre
    refined = np.linalg.eigh(d.T @ d)[1][:, 0]  # the normal: least-variance direction
    if refined @ normal < 0:
        refined = -refined
    return refined, float(-refined @ centre)


def footprints(points: npt.NDArray[np.float64], normal: npt.NDArray[np.float64],
               pixel_area: float) -> npt.NDArray[np.float64]:
    """Area (m^2) of the plane with ``normal`` that each of ``points`` (N, 3) stands for: the
    strided pixel's footprint ``pixel_area * z^2`` over the cosine between its viewing ray and
    the normal, at most 1/0.2 (grazing views)."""
    cos = np.abs(points @ normal) / np.linalg.norm(points, axis=1)
    return pixel_area * points[:, 2] ** 2 / np.maximum(cos, 0.2)


def plane_axes(normal: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(3, 2): two orthonormal directions in the plane with unit ``normal`` (columns)."""
    a, b, c = normal
    # normal x (1, 0, 0), or x (0, 1, 0) when the normal is close to the x axis.
    e1 = np.array([0.0, c, -b]) if abs(a) < 0.9 else np.array([-c, 0.0, a])
    e1 /= math.sqrt(e1 @ e1)
    e2 = np.array([b * e1[2] - c * e1[1], c * e1[0] - a * e1[2], a * e1[1] - b * e1[0]])
    return np.stack([e1, e2], axis=1)
