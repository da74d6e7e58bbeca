"""Section 3: depth image + intrinsics -> foreground point cloud.

Steps: back-projection of the valid depth pixels (optionally every ``pixel_stride``-th pixel),
a 3D box that keeps the activity area, removal of the floor plane (:mod:`.floor`: fitted by
RANSAC among near-horizontal planes, or given by the frame before and then following the
floor each frame shows), of walls and table tops (:mod:`.surfaces`; the points a dropped top
hides the rest of are marked as cut), the static background (:mod:`.background`), and an
optional voxel grid that bounds the number of points independently of the distance to the
camera. This module wires those steps together (:func:`foreground_cloud`) and owns the
back-projection, the box and the voxels.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, NamedTuple

import cv2
import numpy as np

from .errors import InputError
from .floor import (
    FLOOR_BAND,
    FLOOR_MOVED_CHANGED,
    FloorPlane,
    fit_inside,
    follow_floor,
    moved_floor,
)
from .params import EndeffParams
from .surfaces import beside_dropped, level_surface_points, wall_points
from .types import Intrinsics, Pixels

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

    from .background import BackgroundModel
    from .types import Columns

#: :func:`fill_dropouts`: at least this many readings in the window, and their standard
#: deviation at most half of ``FILL_AGREE_M`` plus ``FILL_AGREE_PER_M`` times their depth (two
#: readings at most that far apart: 2 cm plus sensor noise, which grows with depth, and the
#: slope of a surface seen obliquely across the window).
FILL_MIN_READINGS = 2
FILL_AGREE_M = 0.02
FILL_AGREE_PER_M = 0.01

#: Depth beyond this many metres is treated as no reading (no RGB-D sensor of this class
#: measures farther; it also catches garbage such as 65535 mm).
MAX_RANGE_M = 20.0


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
    median : 3x3 median filter on the (strided) depth image first.

    Returns
    -------
    (N, 3) float64 points in the optical frame, metres, in row-major pixel order.
    """
    return np.stack(_backproject(depth, intrinsics, stride, z_range, median), axis=1)


def _backproject(depth: npt.NDArray[np.floating], intrinsics: Intrinsics, stride: int,
                 z_range: tuple[float, float], median: bool) -> Columns:
    """:func:`depth_to_points` as three (N,) columns x, y, z (the cheaper form: compressing
    1-D arrays is several times faster than (N, 3) rows)."""
    z, valid = _valid_pixels(depth, intrinsics, stride, z_range, median)
    return _columns(z, Pixels.of(valid), intrinsics, stride)


def _valid_pixels(depth: npt.NDArray[np.floating], intrinsics: Intrinsics, stride: int,
                  z_range: tuple[float, float], median: bool, fill: bool = False,
                  ) -> tuple[npt.NDArray[np.floating], npt.NDArray[np.bool_]]:
    """The strided depth image (its dropouts filled, :func:`fill_dropouts`, if ``fill``;
    then median-filtered if ``median``) and its pixels within ``z_range``, both
    (H / stride, W / stride), after checking the input."""
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
    z = fill_dropouts(depth, stride) if fill else depth[::stride, ::stride]
    if median:
        # 3x3 median (no reading = 0): removes flying pixels and halves the depth noise that
        # thickens surfaces into several voxel layers; a pixel with <= 4 readings around it
        # becomes no reading.
        z = cv2.medianBlur(np.nan_to_num(z, nan=0.0, posinf=0.0).astype(np.float32), 3)
    lo, hi = max(z_range[0], 1e-6), min(z_range[1], MAX_RANGE_M)
    with np.errstate(invalid='ignore'):
        valid = (z >= lo) & (z <= hi)  # NaN compares False
    return z, valid


#: 3 x 3 kernels picking a block's two opposite neighbours: left and right, above and below,
#: and the two diagonals (an erosion with one is "both have readings").
_OPPOSITE_PAIRS = [np.array(k, np.uint8) for k in (
    [[0, 0, 0], [1, 0, 1], [0, 0, 0]], [[0, 1, 0], [0, 0, 0], [0, 1, 0]],
    [[1, 0, 0], [0, 0, 0], [0, 0, 1]], [[0, 0, 1], [0, 0, 0], [1, 0, 0]])]


def _inside_or_scattered(per_block: npt.NDArray[np.uint8], area: int) -> npt.NDArray[np.bool_]:
    """Per block of ``per_block`` (H, W: readings in each block of ``area`` pixels): whether
    two opposite neighbours (left and right, above and below, or a diagonal's two ends) both
    have readings, i.e. the block lies inside a surface, not beside its outline (there the
    readings all lie on one side, and the block would extend the surface into what the
    sensor saw as nothing); or whether the readings around it are scattered, no block of
    the 3 x 3 more than half read (a ToF sensor's weak returns, not a solid part's edge)."""
    seen = cv2.compare(per_block, 0, cv2.CMP_GT)
    inside = np.zeros_like(seen)
    for kernel in _OPPOSITE_PAIRS:
        cv2.bitwise_or(inside, cv2.erode(seen, kernel, borderType=cv2.BORDER_CONSTANT,
                                         borderValue=0), dst=inside)
    scattered = cv2.compare(cv2.dilate(per_block, np.ones((3, 3), np.uint8)), area // 2,
                            cv2.CMP_LE)
    return cv2.bitwise_or(inside, scattered) > 0


def fill_dropouts(depth: npt.NDArray[np.floating], stride: int) -> npt.NDArray[np.float32]:
    """The strided depth image ``depth[::stride, ::stride]`` (float32), where a pixel without
    a reading takes the mean of the readings in the 3 x 3 blocks of ``stride`` x ``stride``
    pixels around it (the block it starts and its eight neighbours: a window 3 ``stride``
    pixels on a side), when at least ``FILL_MIN_READINGS`` exist and they agree
    (``FILL_AGREE_M``, ``FILL_AGREE_PER_M``). No reading: 0, NaN, inf, negative or beyond
    ``MAX_RANGE_M``; pixels still without one keep what they held.

    Why: ToF sensors lose weak returns (dark clothes, shoes, hair, far or grazing surfaces),
    and a Kinect v2 reads a dark leg at 4 m in one pixel of ten. Striding keeps one pixel
    in ``stride``^2, so such a part keeps a few scattered points that fail the density test
    (Eq. 3) and the leg vanishes, foot and all. The window's readings are all the pixels of
    nine blocks, not only the strided ones (four times as many with stride 2: 36 pixels, of
    which a one-in-ten part still shows three or four). Agreement keeps a hole at a depth
    edge (a hand before the chest, a leg before the wall) empty: readings of two surfaces
    disagree; a surface seen obliquely agrees within the tolerance. The window statistics
    are 3 x 3 box filters over block means (``cv2.resize`` with ``INTER_AREA``): whole-image
    OpenCV calls, no loop. docs/design.md, "Dropouts filled when striding", has the
    measurements.
    """
    d = np.asarray(depth)
    h, w = -(-d.shape[0] // stride), -(-d.shape[1] // stride)
    z = np.array(d[::stride, ::stride], dtype=np.float32)
    # One full-resolution float buffer: its readings (no reading: 0), then (in place) their
    # squares. The first threshold writes a new image (the negatives zeroed; NaN passes
    # OpenCV's threshold unchanged, hence the patch).
    m = cv2.threshold(d.astype(np.float32, copy=False), 0, 0, cv2.THRESH_TOZERO)[1]
    cv2.patchNaNs(m, 0)
    cv2.threshold(m, MAX_RANGE_M, 0, cv2.THRESH_TOZERO_INV, dst=m)  # also inf
    if m.shape != (h * stride, w * stride):  # whole blocks: pad with no readings
        m = cv2.copyMakeBorder(m, 0, h * stride - m.shape[0], 0, w * stride - m.shape[1],
                               cv2.BORDER_CONSTANT, value=0)
    area = np.float32(stride * stride)

    def window_sum(blocks: npt.NDArray, ddepth: int = -1) -> npt.NDArray[np.float32]:
        """Per block, the sum over it and its eight neighbours (nothing beyond the image)."""
        return cv2.boxFilter(blocks, ddepth, (3, 3), normalize=False,
                             borderType=cv2.BORDER_CONSTANT)

    def block_sum(image: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        return cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA) * area  # exact mean

    # Readings per block: INTER_AREA's mean of a 0/255 mask, 255 k / stride^2 rounded to an
    # integer, gives k back exactly for any stride up to 15 (a lookup table).
    mask_mean = cv2.resize(cv2.compare(m, 0, cv2.CMP_GT), (w, h), interpolation=cv2.INTER_AREA)
    per_block = cv2.LUT(mask_mean, np.rint(np.arange(256) * (stride * stride / 255)).astype(
        np.uint8))
    count = window_sum(per_block, cv2.CV_32F)
    total = window_sum(block_sum(m))
    squares = window_sum(block_sum(cv2.multiply(m, m, dst=m)))
    with np.errstate(invalid='ignore'):
        empty = np.flatnonzero((count >= FILL_MIN_READINGS - 0.5) & ~(z > 0)
                               & _inside_or_scattered(per_block, stride * stride))
    n, s1, s2 = count.ravel()[empty], total.ravel()[empty], squares.ravel()[empty]
    mean = s1 / n
    tol = np.float32(0.5) * (np.float32(FILL_AGREE_M) + np.float32(FILL_AGREE_PER_M) * mean)
    agree = s2 / n - mean * mean <= tol * tol
    z.ravel()[empty[agree]] = mean[agree]
    return z


def _columns(z: npt.NDArray[np.floating], pixels: Pixels, intrinsics: Intrinsics,
             stride: int) -> Columns:
    """x, y, z columns of the ``pixels`` of the strided depth image ``z``."""
    h, w = intrinsics.height, intrinsics.width
    zz = pixels.read(z).astype(np.float64)
    # Pixel offsets from the principal point per column and row, broadcast over the image:
    # no pixel-coordinate arrays are materialised.
    du = np.arange(0, w, stride, dtype=np.float64) - intrinsics.cx
    dv = np.arange(0, h, stride, dtype=np.float64) - intrinsics.cy
    x = pixels.read(np.broadcast_to(du[None, :], z.shape)) * zz / intrinsics.fx
    y = pixels.read(np.broadcast_to(dv[:, None], z.shape)) * zz / intrinsics.fy
    return x, y, zz


def box_mask(points: npt.NDArray[np.float64], params: EndeffParams) -> npt.NDArray[np.bool_]:
    """True for points inside the activity box ``box_min_* .. box_max_*``."""
    return _in_box(points[:, 0], points[:, 1], points[:, 2], params)


def _in_box(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64],
            z: npt.NDArray[np.float64], params: EndeffParams) -> npt.NDArray[np.bool_]:
    return ((x >= params.box_min_x) & (x <= params.box_max_x) & (y >= params.box_min_y)
            & (y <= params.box_max_y) & (z >= params.box_min_z) & (z <= params.box_max_z))


def voxel_downsample(points: npt.NDArray[np.float64], size: float) -> npt.NDArray[np.float64]:
    """Replace the points of each ``size`` cube by their mean; (N, 3) -> (M, 3), M <= N.

    The output is ordered by cell (x-major)."""
    if size <= 0 or len(points) == 0:
        return points
    return _voxel_means((points[:, 0], points[:, 1], points[:, 2]), size)


def _voxel_means(cols: Sequence[npt.NDArray[np.float64]],
                 size: float) -> npt.NDArray[np.float64]:
    """:func:`voxel_downsample` on x, y, z columns (N >= 1), and the means of any further
    columns (a colour) over the same cells: one sort of the cell keys, then per-cell sums of
    the sorted columns; (M, len(cols))."""
    cells = []
    for c in cols[:3]:
        cell = np.floor(c / size).astype(np.int64)
        cell -= cell.min()
        cells.append(cell)
    keys = (cells[0] * (int(cells[1].max()) + 1) + cells[1]) * (int(cells[2].max()) + 1) + cells[2]
    order = np.argsort(keys)
    sorted_keys = keys[order]
    starts = np.flatnonzero(np.r_[True, sorted_keys[1:] != sorted_keys[:-1]])
    counts = np.diff(np.r_[starts, len(keys)])
    out = np.empty((len(starts), len(cols)))
    for axis, c in enumerate(cols):
        out[:, axis] = np.add.reduceat(c[order], starts) / counts
    return out


def _off_background(background: BackgroundModel, z_image: npt.NDArray[np.floating],
                    pixels: Pixels, cols: Columns, keep: npt.NDArray[np.bool_],
                    params: EndeffParams, plane: FloorPlane) -> bool:
    """True when most of ``plane``'s points inside the box (``keep``) differ in depth from
    ``background``'s (FLOOR_MOVED_CHANGED of those whose background is known)."""
    on = pixels.image(keep & (np.abs(plane.heights(*cols)) < params.floor_distance), False,
                      bool)
    changed = background.changed_fraction(z_image, on, params)
    return changed is not None and changed >= FLOOR_MOVED_CHANGED


class ForegroundCloud(NamedTuple):
    """What :func:`foreground_cloud` keeps of a frame."""

    #: (N, 3) foreground points, metres, optical frame.
    points: npt.NDArray[np.float64]
    #: The floor plane for the next frame (or None).
    floor: FloorPlane | None
    #: (N, 3) mean colour (0-255 RGB) of each point's pixels, when the colour image was given
    #: and ``color_edge_rgb`` asks for it; else None.
    colors: npt.NDArray[np.float64] | None = None
    #: (N,) whether each point lies beside a table top that was dropped (the table hid what
    #: lies beyond: :func:`beside_dropped`), or None when none was.
    cut: npt.NDArray[np.bool_] | None = None


def foreground_cloud(depth: npt.NDArray[np.floating], intrinsics: Intrinsics,
                     params: EndeffParams, *, floor: FloorPlane | None = None,
                     background: BackgroundModel | None = None, stamp_ns: int = 0,
                     color: npt.NDArray[np.uint8] | None = None) -> ForegroundCloud:
    """Section 3 in one call: back-project, crop to the box, drop the floor, drop the static
    background, voxelise.

    ``floor`` may give a known plane (the previous frame's); otherwise it is fitted when
    ``params.floor_removal``.
    ``background``: a :class:`~endeff_ros.core.background.BackgroundModel` that learns from
    this frame (stamped ``stamp_ns``, with its registered ``color`` image if given) and keeps
    only the parts of the box that moved.
    Returns the (N, 3) foreground points, the floor plane (or None: the one fitted, or the
    known one moved towards this frame's floor, :func:`follow_floor`, for the next frame)
    and, with ``color`` and ``params.color_edge_rgb`` > 0, each point's mean colour.
    """
    z_image, valid = _valid_pixels(depth, intrinsics, params.pixel_stride,
                                   (params.box_min_z, params.box_max_z), params.depth_median,
                                   params.dropout_fill)
    pixels = Pixels.of(valid)
    x, y, z = _columns(z_image, pixels, intrinsics, params.pixel_stride)
    keep = _in_box(x, y, z, params)
    if params.floor_removal:
        pixel_area = params.pixel_stride ** 2 / (intrinsics.fx * intrinsics.fy)
        known = floor is not None
        if floor is None or floor.refit:
            fitted = fit_inside((x, y, z), keep, params, pixel_area)
            if fitted is not None:
                floor, known = fitted, False
            else:  # none found: the old plane (better than none), fitted again next frame
                known = False
        if floor is not None:
            height = floor.heights(x, y, z)
            if known:
                near = np.flatnonzero(keep & (np.abs(height) < params.floor_distance))
                n_inside = int(np.count_nonzero(keep))
                moved = None
                if len(near) < params.floor_min_fraction * n_inside:
                    off = None if background is None else functools.partial(
                        _off_background, background, z_image, pixels, (x, y, z), keep, params)
                    moved = moved_floor(floor, (x, y, z), keep, params, pixel_area, off)
                if moved is not None:  # the camera moved (see moved_floor)
                    floor = moved
                    height = floor.heights(x, y, z)
                    if background is not None:
                        background.camera_moved()
                else:  # the next frame's floor: this one's, following what it shows
                    floor = follow_floor(floor, (x, y, z), near, n_inside, params)
            keep &= height > params.floor_distance
    if params.wall_min_area > 0:
        keep &= ~wall_points(x, y, z, keep, pixels, intrinsics, params)
    beside = None
    if params.table_min_area > 0 and params.floor_removal and floor is not None:
        level = level_surface_points((x, y, z), height, keep, pixels, floor.normal, params)
        if level.any():
            keep &= ~level
            beside = beside_dropped(z, pixels, level, keep)
    if background is not None:
        # The model sees every reading of the strided image (walls beyond the box included:
        # a person in front of them changed those pixels), and the box and floor as a mask.
        candidate = pixels.image(keep, False, bool)
        low = None
        if params.floor_removal and floor is not None:
            low = pixels.image(keep & (height < FLOOR_BAND), False, bool)
        z_image = np.where(z_image <= MAX_RANGE_M, z_image, 0)  # NaN compares False: 0 too
        keep = pixels.read(background.foreground(z_image, candidate, stamp_ns, params,
                                                 low=low, color=color))
    cols: tuple[npt.NDArray[np.float64], ...] = (x[keep], y[keep], z[keep])
    with_rgb = color is not None and params.color_edge_rgb > 0
    if with_rgb:
        rgb = pixels.read(color[::params.pixel_stride, ::params.pixel_stride])[keep]
        cols += tuple(rgb[:, k].astype(np.float64) for k in range(3))
    if beside is not None:
        cols += (beside[keep].astype(np.float64),)  # a voxel is beside if any pixel is
    if params.voxel_size <= 0 or len(cols[0]) == 0:
        out = np.stack(cols, axis=1)
    else:
        out = _voxel_means(cols, params.voxel_size)
    colors = np.ascontiguousarray(out[:, 3:6]) if with_rgb else None
    cut = out[:, -1] > 0 if beside is not None else None
    return ForegroundCloud(np.ascontiguousarray(out[:, :3]), floor, colors, cut)


