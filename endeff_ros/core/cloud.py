"""Section 3: depth image + intrinsics -> foreground point cloud.

Steps: back-projection of the valid depth pixels (optionally every ``pixel_stride``-th pixel),
a 3D box that keeps the activity area, removal of the floor plane (fitted by RANSAC among
near-horizontal planes, or given), and an optional voxel grid that bounds the number of points
independently of the distance to the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from .errors import InputError
from .params import EndeffParams
from .types import Intrinsics

if TYPE_CHECKING:
    import numpy.typing as npt

#: Depth beyond this many metres is treated as no reading (no RGB-D sensor of this class
#: measures farther; it also catches garbage such as 65535 mm).
MAX_RANGE_M = 20.0


@dataclass(frozen=True)
class FloorPlane:
    """Plane ``normal . x + offset = 0`` with ``normal`` pointing up (towards -y), unit length."""

    normal: npt.NDArray[np.float64]
    offset: float

    def distance(self, points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Signed height of (N, 3) points above the plane, metres."""
        return points @ self.normal + self.offset


def depth_to_points(depth: npt.NDArray[np.floating], intrinsics: Intrinsics, *,
                    stride: int = 1, z_range: tuple[float, float] = (0.0, MAX_RANGE_M),
                    median: bool = False) -> npt.NDArray[np.float64]:
    """Back-project the valid pixels of a depth image (Section 3).

    Parameters
    ----------
    depth : (H, W) float array, metres; 0, NaN, inf and values beyond ``MAX_RANGE_M`` are
        no reading.
    intrinsics : pinhole model of the depth image; its size must match ``depth``.
    stride : keep every ``stride``-th pixel in u and v.
    z_range : keep depths in this closed interval only (tested on the image, before any
        back-projection, which is the cheapest place to apply the box's z limits).

    Returns
    -------
    (N, 3) float64 points in the optical frame, metres.
    """
    if depth.ndim != 2:
        msg = f'depth must be 2-D, got shape {depth.shape}'
        raise InputError(msg)
    h, w = depth.shape
    if (w, h) != (intrinsics.width, intrinsics.height):
        msg = (f'depth image is {w}x{h} but the intrinsics are for '
               f'{intrinsics.width}x{intrinsics.height}')
        raise InputError(msg)
    if not np.issubdtype(depth.dtype, np.floating):
        msg = f'depth must be float metres, got dtype {depth.dtype} (convert 16UC1 mm first)'
        raise InputError(msg)
    z = depth[::stride, ::stride]
    if median:
        # 3x3 median (no reading = 0): removes flying pixels and halves the depth noise that
        # thickens surfaces into several voxel layers; a pixel with <= 4 readings around it
        # becomes no reading.
        z = cv2.medianBlur(np.nan_to_num(z, nan=0.0, posinf=0.0).astype(np.float32), 3)
    lo, hi = max(z_range[0], 1e-6), min(z_range[1], MAX_RANGE_M)
    with np.errstate(invalid='ignore'):
        valid = (z >= lo) & (z <= hi)  # NaN compares False
    vv, uu = np.nonzero(valid)
    zz = z[vv, uu].astype(np.float64)
    x = (uu * stride - intrinsics.cx) * zz / intrinsics.fx
    y = (vv * stride - intrinsics.cy) * zz / intrinsics.fy
    return np.stack([x, y, zz], axis=1)


def box_mask(points: npt.NDArray[np.float64], params: EndeffParams) -> npt.NDArray[np.bool_]:
    """True for points inside the activity box ``box_min_* .. box_max_*``."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    return ((x >= params.box_min_x) & (x <= params.box_max_x) & (y >= params.box_min_y)
            & (y <= params.box_max_y) & (z >= params.box_min_z) & (z <= params.box_max_z))


def fit_floor(points: npt.NDArray[np.float64], *, distance: float, max_tilt_deg: float,
              min_fraction: float, iterations: int, rng: np.random.Generator | None = None,
              sample: int = 512) -> FloorPlane | None:
    """Fit the floor: the near-horizontal plane with the most inliers (vectorised RANSAC).

    Only planes whose normal is within ``max_tilt_deg`` of the camera's up axis (-y) are
    hypotheses, so a torso or a wall facing the camera is never taken for the floor, and a
    plane with more than 2 % of the points below it is rejected, so the flat top of a limb or
    a seat is not either. The winner is refined by least squares
    on its inliers and accepted only if it holds ``min_fraction`` of the points.

    Returns ``None`` when no plane qualifies.
    """
    n = len(points)
    if n < 3:
        return None
    rng = rng or np.random.default_rng(0)
    sub = points[rng.choice(n, size=min(n, sample), replace=False)] if n > sample else points
    idx = rng.integers(0, len(sub), size=(iterations, 3))
    p0, p1, p2 = sub[idx[:, 0]], sub[idx[:, 1]], sub[idx[:, 2]]
    normals = np.cross(p1 - p0, p2 - p0)
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9
    normals = normals[ok] / norms[ok, None]
    p0 = p0[ok]
    # Orient every normal upwards (optical frame: up is -y).
    normals *= np.where(normals[:, 1] > 0, -1.0, 1.0)[:, None]
    cos_tilt = math.cos(math.radians(max_tilt_deg))
    keep = -normals[:, 1] >= cos_tilt
    if not np.any(keep):
        return None
    normals, p0 = normals[keep], p0[keep]
    offsets = -np.einsum('ij,ij->i', normals, p0)
    heights = sub @ normals.T + offsets  # (S, H)
    counts = np.count_nonzero(np.abs(heights) < distance, axis=0)
    # A floor has (almost) nothing below it: this rejects the flat top of a limb or a seat.
    below = np.count_nonzero(heights < -3 * distance, axis=0)
    counts[below > 0.02 * len(sub)] = 0
    best = int(np.argmax(counts))
    if counts[best] == 0:
        return None
    normal, offset = normals[best], offsets[best]
    inliers = np.abs(points @ normal + offset) < distance
    if np.count_nonzero(inliers) < max(3, min_fraction * n):
        return None
    support = points[inliers]
    if len(support) > sample:  # least squares on a subsample: as good, 10x cheaper
        support = support[rng.choice(len(support), size=sample, replace=False)]
    normal, offset = _refine_plane(support, normal)
    if -normal[1] < cos_tilt:
        return None
    return FloorPlane(normal, offset)


def _refine_plane(points: npt.NDArray[np.float64],
                  normal: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], float]:
    """Least-squares plane through ``points``, oriented like ``normal``."""
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
    refined = vt[2]
    if refined @ normal < 0:
        refined = -refined
    return refined, float(-refined @ centre)


def voxel_downsample(points: npt.NDArray[np.float64], size: float) -> npt.NDArray[np.float64]:
    """Replace the points of each ``size`` cube by their mean; (N, 3) -> (M, 3), M <= N."""
    if size <= 0 or len(points) == 0:
        return points
    cells = np.floor(points / size).astype(np.int64)
    cells -= cells.min(axis=0)
    dims = cells.max(axis=0) + 1
    keys = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    out = np.empty((len(counts), 3))
    for axis in range(3):
        out[:, axis] = np.bincount(inverse, weights=points[:, axis]) / counts
    return out


def foreground_cloud(depth: npt.NDArray[np.floating], intrinsics: Intrinsics,
                     params: EndeffParams, *, floor: FloorPlane | None = None,
                     ) -> tuple[npt.NDArray[np.float64], FloorPlane | None]:
    """Section 3 in one call: back-project, crop to the box, drop the floor, voxelise.

    ``floor`` may give a known plane; otherwise it is fitted when ``params.floor_removal``.
    Returns the (N, 3) foreground points and the floor plane used (or None).
    """
    points = depth_to_points(depth, intrinsics, stride=params.pixel_stride,
                             z_range=(params.box_min_z, params.box_max_z),
                             median=params.depth_median)
    points = points[box_mask(points, params)]
    if params.floor_removal:
        if floor is None:
            floor = fit_floor(points, distance=params.floor_distance,
                              max_tilt_deg=params.floor_max_tilt_deg,
                              min_fraction=params.floor_min_fraction,
                              iterations=params.floor_iterations)
        if floor is not None:
            points = points[floor.distance(points) > params.floor_distance]
    return voxel_downsample(points, params.voxel_size), floor
