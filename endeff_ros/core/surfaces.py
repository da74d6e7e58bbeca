"""Large flat surfaces that are no entities, dropped with the floor: walls (planes of any
orientation showing ``wall_min_area``) and table tops (level surfaces above the floor showing
``table_min_area``), and the points a dropped top hides the rest of (cut, like the image
border)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

from .floor import FLOOR_SAMPLE
from .planes import footprints, hypothesis_triples, plane_axes, plane_hypotheses, refine_plane

if TYPE_CHECKING:
    import numpy.typing as npt

    from .params import EndeffParams
    from .types import Columns, Intrinsics, Pixels


def beside_dropped(z: npt.NDArray[np.float64], pixels: Pixels,
                   dropped: npt.NDArray[np.bool_], keep: npt.NDArray[np.bool_]
                   ) -> npt.NDArray[np.bool_]:
    """Points of ``keep`` whose pixel lies within ``_BESIDE_PX`` strided pixels of a
    ``dropped`` point's pixel and not nearer than those by more than ``_BESIDE_STEP``: the
    table top hides what lies beyond it, so a body seen over it (or below its front edge)
    ends there, and that end is a cut, like the image border's; a body in front of the table
    is not cut by it. ``z`` the points' depths, ``pixels`` the strided image's pixels that
    became the points; ``dropped`` and ``keep`` per point."""
    size = 2 * _BESIDE_PX + 1
    z = z.astype(np.float32)
    image = pixels.image(np.where(dropped, z, np.inf), np.inf, np.float32)
    nearest = pixels.read(cv2.erode(image, np.ones((size, size), np.uint8)))
    return keep & (z >= nearest - _BESIDE_STEP)


def wall_points(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64],
                z: npt.NDArray[np.float64], keep: npt.NDArray[np.bool_],
                pixels: Pixels, intrinsics: Intrinsics,
                params: EndeffParams) -> npt.NDArray[np.bool_]:
    """Points of ``keep`` on planes (any orientation) that show at least
    ``params.wall_min_area`` square metres: walls, and above all a wall close behind a person,
    which the static background cannot drop (the person's motion keeps the joined wall) and
    whose noisy surface gives extremes everywhere. A body shows far less flat area (a torso
    facing the camera, about 0.3 m^2); furniture's flat parts are not entities either.

    Up to ``_WALL_PLANES`` planes, each the plane with the most inliers (within
    ``floor_distance`` plus the depth noise's ``0.005 z^2``) among RANSAC hypotheses on a
    strided sample, refined by least squares; its area is the sum of its inlier pixels'
    footprints (the strided pixel's area at that depth, divided by the cosine between the
    viewing ray and the plane's normal, at most 1/0.2), counted per 8-connected stretch of
    inlier pixels: only stretches of at least that area go. ``pixels``: the strided image's
    pixels that became the points.
    """
    out = np.zeros(len(z), dtype=bool)
    left = np.flatnonzero(keep)
    stride = params.pixel_stride
    pixel_area = (stride / intrinsics.fx) * (stride / intrinsics.fy)
    for _ in range(_WALL_PLANES):
        if len(left) < 3:
            break
        pts = np.stack([x[left], y[left], z[left]], axis=1)
        sub = pts[::max(1, len(left) // FLOOR_SAMPLE)]
        normals, p0 = plane_hypotheses(sub, hypothesis_triples(len(sub), params.floor_iterations))
        if not len(normals):
            break
        offsets = -np.einsum('ij,ij->i', normals, p0)
        tol_sub = params.floor_distance + _WALL_NOISE_Z2 * sub[:, 2:3] ** 2
        on_sub = np.abs(sub @ normals.T + offsets) < tol_sub
        best = int(np.argmax(np.count_nonzero(on_sub, axis=0)))
        # The sample's estimate of the plane's area (each sample point stands for
        # len(pts) / len(sub) points): far below the threshold, no full pass is needed.
        estimate = (footprints(sub[on_sub[:, best]], normals[best], pixel_area).sum()
                    * len(pts) / len(sub))
        if estimate < _WALL_SAMPLE_SHARE * params.wall_min_area:
            break
        tol = params.floor_distance + _WALL_NOISE_Z2 * pts[:, 2] ** 2
        on = np.abs(pts @ normals[best] + offsets[best]) < tol
        if np.count_nonzero(on) < 3:
            break
        normal, offset = refine_plane(pts[on], normals[best])
        on = np.flatnonzero(np.abs(pts @ normal + offset) < tol)
        # Only connected stretches of the plane that are large themselves: a slab at a
        # person's depth also holds their torso and whatever stands beside them.
        _, part = _stretches(pixels.index[left[on]], pixels.shape)
        inliers = pts[on]
        area = np.bincount(part, weights=footprints(inliers, normal, pixel_area))
        big = area >= params.wall_min_area
        # ... and, where grazing views made up half of that, the plane's cells they cover.
        seen = np.bincount(part, weights=pixel_area * inliers[:, 2] ** 2, minlength=len(area))
        check = big & (area > 2 * seen)
        mine = check[part]
        if mine.any():
            cells = _occupied_area(inliers[mine], normal, part[mine], len(area))
            big &= ~check | (cells >= params.wall_min_area)
        gone = on[big[part]]
        if not len(gone):
            break
        out[left[gone]] = True
        left = np.delete(left, gone)
    return out


def level_surface_points(cols: Columns, height: npt.NDArray[np.float64],
                         keep: npt.NDArray[np.bool_], pixels: Pixels,
                         up: npt.NDArray[np.float64], params: EndeffParams
                         ) -> npt.NDArray[np.bool_]:
    """Points of ``keep`` on level surfaces above the floor that cover at least
    ``params.table_min_area`` square metres less a rim: table tops and desks. A person behind
    or at a table joins it in one entity (the static background keeps what a moving part
    joins), and its corners and edges are then extremes; they are no wall (a table shows less
    than ``wall_min_area``, and the walls' two planes are taken first).

    The floor gives the surfaces' normal, so a level is a peak of the points' ``height``
    (above the floor, aligned with the points ``cols``): for each of the ``_LEVELS`` densest
    levels at least ``_LEVEL_MIN_HEIGHT`` up, the points within ``floor_distance`` plus the
    depth noise's ``0.005 z^2`` of it, per 8-connected stretch of their pixels (``pixels``,
    the strided image's pixels that became the points), are projected onto the level and
    counted in ``_WALL_CELL`` cells. The occupied cells are eroded by one cell: a level slab
    through upright things (a body, a wall, a shelf's side) projects to a thin curve, which
    goes, while a table top keeps its inside. A stretch whose inside covers the area goes,
    with the points in or beside (one cell) that inside; ``up`` is the floor's normal.
    """
    out = np.zeros(len(height), dtype=bool)
    idx = np.flatnonzero(keep & (height > _LEVEL_MIN_HEIGHT))
    if len(idx) < _LEVEL_MIN_POINTS:
        return out
    h = height[idx]
    step = params.floor_distance
    bins = ((h - _LEVEL_MIN_HEIGHT) / step).astype(np.intp)
    window = np.bincount(bins)
    window[:-1] += window[1:]  # points within two bins: a level between two bin edges
    tol = step + _WALL_NOISE_Z2 * cols[2][idx] ** 2
    axes = plane_axes(up) / _WALL_CELL
    pixel_of = pixels.index[idx]
    min_cells = params.table_min_area / _WALL_CELL ** 2
    for _ in range(_LEVELS):
        b = int(np.argmax(window))
        if window[b] < max(_LEVEL_MIN_POINTS, min_cells):
            break
        window[max(0, b - 2):b + 3] = 0  # the next level is another surface
        level = np.median(h[(bins == b) | (bins == b + 1)])
        on = np.flatnonzero(np.abs(h - level) < tol)
        points = np.stack([c[idx[on]] for c in cols], axis=1)
        cells = np.floor(points @ axes).astype(np.int64)
        # The whole slab's inside bounds each stretch's: most frames end here.
        if np.count_nonzero(_cells_inside(cells)[0]) < min_cells:
            continue
        n, part = _stretches(pixel_of[on], pixels.shape)
        for label in np.flatnonzero(np.bincount(part, minlength=n) >= min_cells):
            mine = np.flatnonzero(part == label)
            inside, at = _cells_inside(cells[mine])
            if np.count_nonzero(inside) >= min_cells:
                near = cv2.dilate(inside, _CELL_KERNEL)[at] > 0  # in or beside the inside
                out[idx[on[mine[near]]]] = True
    return out


def _stretches(pixels: npt.NDArray[np.intp], shape: tuple[int, int]
               ) -> tuple[int, npt.NDArray[np.int32]]:
    """The 8-connected stretches of the strided image's ``pixels`` (flat indices into an
    image of ``shape``): their number (label 0 included) and each pixel's label."""
    image = np.zeros(shape, dtype=np.uint8)
    image.reshape(-1)[pixels] = 1
    n, labels = cv2.connectedComponents(image, connectivity=8, ltype=cv2.CV_32S)
    return n, labels.reshape(-1)[pixels]


def _cells_inside(cells: npt.NDArray[np.int64]
                  ) -> tuple[npt.NDArray[np.uint8], tuple[npt.NDArray[np.int64], ...]]:
    """The occupancy grid of ``cells`` (K, 2) integer cell coordinates, eroded by one cell
    (what lies inside a one-cell rim), and each cell's index into it."""
    at = tuple(cells[:, k] - cells[:, k].min() + 1 for k in range(2))
    grid = np.zeros((int(at[0].max()) + 2, int(at[1].max()) + 2), np.uint8)
    grid[at] = 1
    return cv2.erode(grid, _CELL_KERNEL), at


#: One cell around a cell (:func:`_cells_inside`).
_CELL_KERNEL = np.ones((3, 3), np.uint8)


def _occupied_area(points: npt.NDArray[np.float64], normal: npt.NDArray[np.float64],
                   part: npt.NDArray[np.int64], n: int) -> npt.NDArray[np.float64]:
    """Per label 0..n-1 of ``part`` (N,), the area (m^2) of the ``_WALL_CELL`` cells of the
    plane with ``normal`` that its ``points`` (N, 3), projected onto the plane, occupy.

    The footprints of :func:`footprints` measure a surface that lies in the plane; a slab
    through a body seen edge-on (a bending person's side) holds the body's front surface
    across its thickness, each pixel at a grazing angle, and their footprints add up to a
    wall's. Projected onto the plane those points cover a thin curve."""
    axes = plane_axes(normal) / _WALL_CELL
    u, v = points @ axes[:, 0], points @ axes[:, 1]
    c0, c1 = (u - u.min()).astype(np.int64), (v - v.min()).astype(np.int64)
    # An occupancy grid per label (no sort: a wall holds tens of thousands of points).
    present = np.bincount(part, minlength=n) > 0
    labels = np.flatnonzero(present)
    index = (np.cumsum(present) - 1)[part]
    s0, s1 = int(c0.max()) + 1, int(c1.max()) + 1
    grid = np.zeros(len(labels) * s0 * s1, dtype=bool)
    grid[(index * s0 + c0) * s1 + c1] = True
    per_label = np.bincount(np.flatnonzero(grid) // (s0 * s1), minlength=len(labels))
    out = np.zeros(n)
    out[labels] = per_label * _WALL_CELL ** 2
    return out


#: Planes :func:`wall_points` looks for (a wall behind the person and one beside).
_WALL_PLANES = 2
#: A plane whose area the sample puts below this share of ``wall_min_area`` is not checked on
#: all points.
_WALL_SAMPLE_SHARE = 0.5
#: Depth-noise term of the wall tolerance, metres per square metre of depth.
_WALL_NOISE_Z2 = 0.005
#: Cell (m) of the plane in which :func:`wall_points` counts occupied area.
_WALL_CELL = 0.1
#: A point this many strided pixels from a dropped table top's pixel, and not nearer than it
#: by more than _BESIDE_STEP (m), lies beside it (:func:`beside_dropped`).
_BESIDE_PX = 2
_BESIDE_STEP = 0.15
#: Level surfaces lower than this (m) are left alone: a person lying on the floor.
_LEVEL_MIN_HEIGHT = 0.2
#: Levels :func:`level_surface_points` looks at (a table, and a desk or bench beside it).
_LEVELS = 2
#: A level needs this many points to be looked at.
_LEVEL_MIN_POINTS = 50
