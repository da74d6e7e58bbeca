"""Section 3: depth image + intrinsics -> foreground point cloud.

Steps: back-projection of the valid depth pixels (optionally every ``pixel_stride``-th pixel),
a 3D box that keeps the activity area, removal of the floor plane (fitted by RANSAC among
near-horizontal planes, or given by the frame before and then following the floor each
frame shows), of walls (:func:`wall_points`) and table tops (:func:`level_surface_points`,
whose neighbours are marked as cut: :func:`beside_dropped`), the static background
(:mod:`.background`), and an optional voxel grid that bounds the number of points
independently of the distance to the camera.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import cv2
import numpy as np

from .errors import InputError
from .params import EndeffParams
from .types import Intrinsics

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    import numpy.typing as npt

    from .background import BackgroundModel

    Columns = tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]

#: Depth beyond this many metres is treated as no reading (no RGB-D sensor of this class
#: measures farther; it also catches garbage such as 65535 mm).
MAX_RANGE_M = 20.0


@dataclass(frozen=True)
class FloorPlane:
    """Plane ``normal . x + offset = 0`` with ``normal`` pointing up (towards -y), unit length.

    ``refit``: a known plane that may no longer hold (the camera moved): :func:`foreground_cloud`
    fits the floor anew and uses this one only if no floor is found, returning it still
    marked ``refit`` so that the next frame tries again.
    """

    normal: npt.NDArray[np.float64]
    offset: float
    refit: bool = False

    def distance(self, points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Signed height of (N, 3) points above the plane, metres."""
        return self.heights(points[:, 0], points[:, 1], points[:, 2])

    def heights(self, x: npt.NDArray[np.float64], y: npt.NDArray[np.float64],
                z: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """:meth:`distance` of points given as x, y, z columns."""
        nx, ny, nz = self.normal
        return x * nx + y * ny + z * nz + self.offset


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
    return _columns(z, valid, intrinsics, stride)


def _valid_pixels(depth: npt.NDArray[np.floating], intrinsics: Intrinsics, stride: int,
                  z_range: tuple[float, float], median: bool,
                  ) -> tuple[npt.NDArray[np.floating], npt.NDArray[np.bool_]]:
    """The strided (and optionally median-filtered) depth image and its pixels within
    ``z_range``, both (H / stride, W / stride), after checking the input."""
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
    return z, valid


def _columns(z: npt.NDArray[np.floating], valid: npt.NDArray[np.bool_],
             intrinsics: Intrinsics, stride: int) -> Columns:
    """x, y, z columns of the ``valid`` pixels of the strided depth image ``z``."""
    h, w = intrinsics.height, intrinsics.width
    zz = z[valid].astype(np.float64)
    # Pixel offsets from the principal point per column and row, broadcast over the image:
    # no pixel-coordinate arrays are materialised.
    du = np.arange(0, w, stride, dtype=np.float64) - intrinsics.cx
    dv = np.arange(0, h, stride, dtype=np.float64) - intrinsics.cy
    x = np.broadcast_to(du[None, :], z.shape)[valid] * zz / intrinsics.fx
    y = np.broadcast_to(dv[:, None], z.shape)[valid] * zz / intrinsics.fy
    return x, y, zz


def box_mask(points: npt.NDArray[np.float64], params: EndeffParams) -> npt.NDArray[np.bool_]:
    """True for points inside the activity box ``box_min_* .. box_max_*``."""
    return _in_box(points[:, 0], points[:, 1], points[:, 2], params)


def _in_box(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64],
            z: npt.NDArray[np.float64], params: EndeffParams) -> npt.NDArray[np.bool_]:
    return ((x >= params.box_min_x) & (x <= params.box_max_x) & (y >= params.box_min_y)
            & (y <= params.box_max_y) & (z >= params.box_min_z) & (z <= params.box_max_z))


def fit_floor(points: npt.NDArray[np.float64], *, distance: float, max_tilt_deg: float,
              min_fraction: float, iterations: int, rng: np.random.Generator | None = None,
              sample: int = 512, min_area: float = 0.0,
              pixel_area: float = 0.0) -> FloorPlane | None:
    """Fit the floor: the near-horizontal plane with the most inliers (vectorised RANSAC).

    Only planes whose normal is within ``max_tilt_deg`` of the camera's up axis (-y) are
    hypotheses, so a torso or a wall facing the camera is never taken for the floor, and a
    plane with more than 2 % of the points below it is rejected, so the flat top of a limb or
    a seat is not either. The camera sees a floor from above: a plane less than
    ``FLOOR_MIN_CLEARANCE_M`` below the camera's centre (or above it) is none. With
    ``min_area`` and ``pixel_area`` (the solid angle of one of ``points``' pixels,
    ``(stride / fx) * (stride / fy)``) a floor must also show ``min_area`` square metres (each
    point standing for its pixel's footprint on the plane): a lap or a seat that the image's
    lower border cuts has nothing below it either, but shows a tenth of a square metre. The
    winner is refined by least squares on its inliers and accepted only if it holds
    ``min_fraction`` of the points.

    Hypotheses: ``iterations`` planes through random triples of points, and as many local
    planes, each the least-squares plane of a random point's ``_LOCAL_NEIGHBOURS`` nearest
    sample points. A random triple lies on a floor that holds a fraction f of the points
    with probability f^3 (a tenth of the points: one triple in a thousand, so 40 triples
    miss it), a random point with probability f.

    Everything runs on an evenly strided subsample of ``sample`` to ``2 * sample`` points
    (the points come in pixel order, so a stride spreads the sample over the image): the
    inlier fraction of a plane holding 5 % of the points is known to about 1 % from it.
    ``rng`` draws the hypotheses; by default a fixed table (seed 0) is reused.

    Returns ``None`` when no plane qualifies.
    """
    n = len(points)
    if n < 3:
        return None
    sub = points[::max(1, n // sample)]
    if rng is None:
        idx = _hypotheses(len(sub), iterations)
    else:
        idx = rng.integers(0, len(sub), size=(iterations, 3))
    normals, p0 = _plane_hypotheses(sub, idx)
    local_normals, local_p0 = _local_plane_hypotheses(sub, idx[:, 0])
    normals, p0 = np.concatenate([normals, local_normals]), np.concatenate([p0, local_p0])
    # Orient every normal upwards (optical frame: up is -y).
    normals *= np.where(normals[:, 1] > 0, -1.0, 1.0)[:, None]
    cos_tilt = math.cos(math.radians(max_tilt_deg))
    keep = -normals[:, 1] >= cos_tilt
    if not np.any(keep):
        return None
    normals, p0 = normals[keep], p0[keep]
    offsets = -np.einsum('ij,ij->i', normals, p0)  # the camera's height above each plane
    heights = sub @ normals.T + offsets  # (S, H)
    on_plane = np.abs(heights) < distance
    counts = np.count_nonzero(on_plane, axis=0)
    # A floor has (almost) nothing below it: this rejects the flat top of a limb or a seat.
    below = np.count_nonzero(heights < -3 * distance, axis=0)
    counts[below > 0.02 * len(sub)] = 0
    counts[offsets < FLOOR_MIN_CLEARANCE_M] = 0
    enough = max(3, min_fraction * len(sub))
    for best in np.argsort(-counts, kind='stable'):
        if counts[best] < enough:
            return None
        if min_area <= 0 or pixel_area <= 0:
            break
        on = sub[on_plane[:, best]]
        if _footprints(on, normals[best], pixel_area * n / len(sub)).sum() >= min_area:
            break
    else:
        return None
    normal, offset = _refine_plane(sub[on_plane[:, best]], normals[best])
    if -normal[1] < cos_tilt or offset < FLOOR_MIN_CLEARANCE_M:
        return None
    return FloorPlane(normal, offset)


def _local_plane_hypotheses(points: npt.NDArray[np.float64], seeds: npt.NDArray[np.int64],
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


#: Sample points whose least-squares plane is one local floor hypothesis (see
#: :func:`fit_floor`): on a 512-1024 point sample of the box, a patch some 10-30 cm across
#: (larger patches reached over walls and legs on a hall's floor 3-5 m away; 8 and 12 gave
#: the mocap dev subset the same scores: docs/design.md, "Floor hypotheses").
_LOCAL_NEIGHBOURS = 6
#: A floor shows at least this area inside the box (square metres; see :func:`fit_floor`).
FLOOR_MIN_AREA_M2 = 0.5
#: A floor lies at least this far below the camera's centre (metres): a camera looks at a
#: floor from above, and a plane through the camera is the fan of rays along an image border.
FLOOR_MIN_CLEARANCE_M = 0.1


@functools.lru_cache(maxsize=8)
def _hypotheses(n: int, iterations: int) -> npt.NDArray[np.int64]:
    """Index triples of the RANSAC hypotheses: drawn once per sample size (seed 0)."""
    idx = np.random.default_rng(0).integers(0, n, size=(iterations, 3))
    idx.flags.writeable = False
    return idx


def _plane_hypotheses(points: npt.NDArray[np.float64], idx: npt.NDArray[np.int64],
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


def _refine_plane(points: npt.NDArray[np.float64],
                  normal: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], float]:
    """Least-squares plane through ``points``, oriented like ``normal``."""
    centre = points.mean(axis=0)
    d = points - centre
    refined = np.linalg.eigh(d.T @ d)[1][:, 0]  # the normal: least-variance direction
    if refined @ normal < 0:
        refined = -refined
    return refined, float(-refined @ centre)


#: Weight of a frame's own least-squares floor when a known floor follows it (see
#: :func:`follow_floor`); the known plane converges to what the frames show in about ten.
FLOOR_FOLLOW = 0.2
#: A floor found anew at more than this angle (degrees) to the known plane, at the same
#: height below the camera within FLOOR_SAME_HEIGHT_M (metres), means the camera turned
#: (see :func:`_moved_floor`).
FLOOR_TURNED_DEG = 2.0
FLOOR_SAME_HEIGHT_M = 0.05
#: A floor found parallel to the known one at another height means the camera was raised or
#: lowered when at least this fraction of its points lies off the learnt background.
FLOOR_MOVED_CHANGED = 0.5
#: At most this many points of a frame's floor feed :func:`follow_floor`'s fit.
_FOLLOW_SAMPLE = 4096


def follow_floor(floor: FloorPlane, cols: Columns, near: npt.NDArray[np.intp], n_inside: int,
                 params: EndeffParams) -> FloorPlane:
    """The known ``floor`` moved towards the least-squares plane of the points ``near`` (indices
    into the x, y, z columns ``cols``), this frame's points within ``floor_distance`` of it
    (``n_inside``: the points inside the box). Only a sample of them is gathered (at most
    ``_FOLLOW_SAMPLE``): the floor is often most of the frame.

    The tracker passes each frame the floor of the frame before; fitted once, a plane that
    the first frame's RANSAC sample got wrong stays wrong for the whole stream (furniture in
    the sample: 1.9 degrees and 3 cm off in one furnished room, whose floor beside the
    person's feet was then foreground). The points near the known plane are mostly the true
    floor's, so their least-squares plane is nearer the truth, and blending it in
    (``FLOOR_FOLLOW``) each frame converges to it while one frame's noise, or a person
    lying on the floor, moves it little. Frames showing too little floor
    (``floor_min_fraction``) or a plane too tilted to be one leave it as it is.
    """
    if len(near) < max(50, params.floor_min_fraction * n_inside):
        return floor
    sample = near[::max(1, len(near) // _FOLLOW_SAMPLE)]
    normal, offset = _refine_plane(np.stack([c[sample] for c in cols], axis=1), floor.normal)
    if -normal[1] < math.cos(math.radians(params.floor_max_tilt_deg)):
        return floor
    blended = (1 - FLOOR_FOLLOW) * floor.normal + FLOOR_FOLLOW * normal
    norm = float(np.linalg.norm(blended))
    return FloorPlane(blended / norm,
                      ((1 - FLOOR_FOLLOW) * floor.offset + FLOOR_FOLLOW * offset) / norm)


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


def _fit_inside(cols: Columns, keep: npt.NDArray[np.bool_], params: EndeffParams,
                pixel_area: float) -> FloorPlane | None:
    """:func:`fit_floor` on a sample of the points ``keep`` (inside the box); ``pixel_area``:
    the solid angle of one of their pixels."""
    inside = np.flatnonzero(keep)
    step = max(1, len(inside) // _FLOOR_SAMPLE)
    return fit_floor(np.stack([c[inside[::step]] for c in cols], axis=1),
                     distance=params.floor_distance, max_tilt_deg=params.floor_max_tilt_deg,
                     min_fraction=params.floor_min_fraction,
                     iterations=params.floor_iterations, sample=_FLOOR_SAMPLE,
                     min_area=FLOOR_MIN_AREA_M2, pixel_area=pixel_area * step)


def _moved_floor(floor: FloorPlane, cols: Columns, keep: npt.NDArray[np.bool_],
                 params: EndeffParams, pixel_area: float,
                 off_background: Callable[[FloorPlane], bool] | None = None,
                 ) -> FloorPlane | None:
    """The floor this frame shows, when the known ``floor`` no longer explains it because
    the camera turned or was raised or lowered; None otherwise.

    Asked only when too few points lie near the known plane for :func:`follow_floor`: a
    person close to the camera hiding the floor, a view with little floor, or a camera that
    moved. A tilt changes depths mostly one way (down: nearer everywhere), and so does a
    camera lowered (a robot's torso going down), so the background's own test, which wants
    pixels both nearer and farther, misses them; but a static floor that now lies elsewhere
    can only mean the camera moved.

    - Turned: a floor found anew at more than ``FLOOR_TURNED_DEG`` to the known one, at the
      same height below the camera (within ``FLOOR_SAME_HEIGHT_M``: a head turns about a
      point near its camera). A hidden floor finds no plane or the same one again, and a
      plane through what hides it (a slope of a body and the strip of floor left) lies at
      another height.
    - Raised or lowered: a floor found anew parallel to the known one (within
      ``FLOOR_TURNED_DEG``) at another height, whose points mostly lie off the learnt
      background (``off_background``, given with a background model). The check is what
      tells a lowered camera from a table top or a seat found while a person hides the
      floor: those are learnt background, at the depths they always had; a floor seen
      from another height is not.
    """
    fitted = _fit_inside(cols, keep, params, pixel_area)
    if fitted is None:
        return None
    cos = float(np.clip(fitted.normal @ floor.normal, -1.0, 1.0))
    turned = math.degrees(math.acos(cos)) > FLOOR_TURNED_DEG
    if abs(fitted.offset - floor.offset) <= FLOOR_SAME_HEIGHT_M:
        return fitted if turned else None
    if turned or off_background is None:
        return None
    return fitted if off_background(fitted) else None


def _off_background(background: BackgroundModel, z_image: npt.NDArray[np.floating],
                    valid: npt.NDArray[np.bool_], cols: Columns, keep: npt.NDArray[np.bool_],
                    params: EndeffParams, plane: FloorPlane) -> bool:
    """True when most of ``plane``'s points inside the box (``keep``) differ in depth from
    ``background``'s (FLOOR_MOVED_CHANGED of those whose background is known)."""
    on = np.zeros(valid.shape, dtype=bool)
    on[valid] = keep & (np.abs(plane.heights(*cols)) < params.floor_distance)
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
                                   (params.box_min_z, params.box_max_z), params.depth_median)
    x, y, z = _columns(z_image, valid, intrinsics, params.pixel_stride)
    keep = _in_box(x, y, z, params)
    if params.floor_removal:
        pixel_area = params.pixel_stride ** 2 / (intrinsics.fx * intrinsics.fy)
        known = floor is not None
        if floor is None or floor.refit:
            fitted = _fit_inside((x, y, z), keep, params, pixel_area)
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
                        _off_background, background, z_image, valid, (x, y, z), keep, params)
                    moved = _moved_floor(floor, (x, y, z), keep, params, pixel_area, off)
                if moved is not None:  # the camera moved (see _moved_floor)
                    floor = moved
                    height = floor.heights(x, y, z)
                    if background is not None:
                        background.camera_moved()
                else:  # the next frame's floor: this one's, following what it shows
                    floor = follow_floor(floor, (x, y, z), near, n_inside, params)
            keep &= height > params.floor_distance
    if params.wall_min_area > 0:
        keep &= ~wall_points(x, y, z, keep, valid, intrinsics, params)
    beside = None
    if params.table_min_area > 0 and params.floor_removal and floor is not None:
        level = level_surface_points((x, y, z), height, keep, valid, floor.normal, params)
        if level.any():
            keep &= ~level
            beside = beside_dropped(z, valid, level, keep)
    if background is not None:
        # The model sees every reading of the strided image (walls beyond the box included:
        # a person in front of them changed those pixels), and the box and floor as a mask.
        candidate = np.zeros(valid.shape, dtype=bool)
        candidate[valid] = keep
        low = None
        if params.floor_removal and floor is not None:
            low = np.zeros(valid.shape, dtype=bool)
            low[valid] = keep & (height < FLOOR_BAND)
        z_image = np.where(z_image <= MAX_RANGE_M, z_image, 0)  # NaN compares False: 0 too
        keep = background.foreground(z_image, candidate, stamp_ns, params, low=low,
                                     color=color)[valid]
    cols: tuple[npt.NDArray[np.float64], ...] = (x[keep], y[keep], z[keep])
    with_rgb = color is not None and params.color_edge_rgb > 0
    if with_rgb:
        rgb = color[::params.pixel_stride, ::params.pixel_stride][valid][keep]
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


def beside_dropped(z: npt.NDArray[np.float64], valid: npt.NDArray[np.bool_],
                   dropped: npt.NDArray[np.bool_], keep: npt.NDArray[np.bool_]
                   ) -> npt.NDArray[np.bool_]:
    """Points of ``keep`` whose pixel lies within ``_BESIDE_PX`` strided pixels of a
    ``dropped`` point's pixel and not nearer than those by more than ``_BESIDE_STEP``: the
    table top hides what lies beyond it, so a body seen over it (or below its front edge)
    ends there, and that end is a cut, like the image border's; a body in front of the table
    is not cut by it. ``z`` the points' depths, ``valid`` (H, W) the strided image's pixels
    that became the points (in order); ``dropped`` and ``keep`` per point."""
    size = 2 * _BESIDE_PX + 1
    z = z.astype(np.float32)
    image = np.full(valid.shape, np.inf, dtype=np.float32)
    image[valid] = np.where(dropped, z, np.inf)
    nearest = cv2.erode(image, np.ones((size, size), np.uint8))[valid]
    return keep & (z >= nearest - _BESIDE_STEP)


def wall_points(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64],
                z: npt.NDArray[np.float64], keep: npt.NDArray[np.bool_],
                valid: npt.NDArray[np.bool_], intrinsics: Intrinsics,
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
    inlier pixels: only stretches of at least that area go. ``valid`` (H, W): the strided
    image's pixels that became the points, in order.
    """
    out = np.zeros(len(z), dtype=bool)
    left = np.flatnonzero(keep)
    pixel_of = np.flatnonzero(valid)  # point i is pixel pixel_of[i] of the strided image
    stride = params.pixel_stride
    pixel_area = (stride / intrinsics.fx) * (stride / intrinsics.fy)
    for _ in range(_WALL_PLANES):
        if len(left) < 3:
            break
        pts = np.stack([x[left], y[left], z[left]], axis=1)
        sub = pts[::max(1, len(left) // _FLOOR_SAMPLE)]
        normals, p0 = _plane_hypotheses(sub, _hypotheses(len(sub), params.floor_iterations))
        if not len(normals):
            break
        offsets = -np.einsum('ij,ij->i', normals, p0)
        tol_sub = params.floor_distance + _WALL_NOISE_Z2 * sub[:, 2:3] ** 2
        on_sub = np.abs(sub @ normals.T + offsets) < tol_sub
        best = int(np.argmax(np.count_nonzero(on_sub, axis=0)))
        # The sample's estimate of the plane's area (each sample point stands for
        # len(pts) / len(sub) points): far below the threshold, no full pass is needed.
        estimate = (_footprints(sub[on_sub[:, best]], normals[best], pixel_area).sum()
                    * len(pts) / len(sub))
        if estimate < _WALL_SAMPLE_SHARE * params.wall_min_area:
            break
        tol = params.floor_distance + _WALL_NOISE_Z2 * pts[:, 2] ** 2
        on = np.abs(pts @ normals[best] + offsets[best]) < tol
        if np.count_nonzero(on) < 3:
            break
        normal, offset = _refine_plane(pts[on], normals[best])
        on = np.flatnonzero(np.abs(pts @ normal + offset) < tol)
        # Only connected stretches of the plane that are large themselves: a slab at a
        # person's depth also holds their torso and whatever stands beside them.
        pixels = pixel_of[left[on]]
        image = np.zeros(valid.shape, dtype=np.uint8)
        image.reshape(-1)[pixels] = 1
        _, labels = cv2.connectedComponents(image, connectivity=8, ltype=cv2.CV_32S)
        part = labels.reshape(-1)[pixels]
        inliers = pts[on]
        area = np.bincount(part, weights=_footprints(inliers, normal, pixel_area))
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
                         keep: npt.NDArray[np.bool_], valid: npt.NDArray[np.bool_],
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
    depth noise's ``0.005 z^2`` of it, per 8-connected stretch of their pixels (``valid``,
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
    axes = _plane_axes(up) / _WALL_CELL
    pixel_of = np.flatnonzero(valid)[idx]
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
        image = np.zeros(valid.shape, dtype=np.uint8)
        image.reshape(-1)[pixel_of[on]] = 1
        n, labels = cv2.connectedComponents(image, connectivity=8, ltype=cv2.CV_32S)
        part = labels.reshape(-1)[pixel_of[on]]
        for label in np.flatnonzero(np.bincount(part, minlength=n) >= min_cells):
            mine = np.flatnonzero(part == label)
            inside, at = _cells_inside(cells[mine])
            if np.count_nonzero(inside) >= min_cells:
                near = cv2.dilate(inside, _CELL_KERNEL)[at] > 0  # in or beside the inside
                out[idx[on[mine[near]]]] = True
    return out


def _cells_inside(cells: npt.NDArray[np.int64]
                  ) -> tuple[npt.NDArray[np.uint8], tuple[npt.NDArray[np.int64], ...]]:
    """The occupancy grid of ``cells`` (K, 2) integer cell coordinates, eroded by one cell
    (what lies inside a one-cell rim), and each cell's index into it."""
    at = tuple(cells[:, k] - cells[:, k].min() + 1 for k in range(2))
    grid = np.zeros((int(at[0].max()) + 2, int(at[1].max()) + 2), np.uint8)
    grid[at] = 1
    return cv2.erode(grid, _CELL_KERNEL), at


def _plane_axes(normal: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(3, 2): two orthonormal directions in the plane with unit ``normal`` (columns)."""
    a, b, c = normal
    # normal x (1, 0, 0), or x (0, 1, 0) when the normal is close to the x axis.
    e1 = np.array([0.0, c, -b]) if abs(a) < 0.9 else np.array([-c, 0.0, a])
    e1 /= math.sqrt(e1 @ e1)
    e2 = np.array([b * e1[2] - c * e1[1], c * e1[0] - a * e1[2], a * e1[1] - b * e1[0]])
    return np.stack([e1, e2], axis=1)


#: One cell around a cell (:func:`_cells_inside`).
_CELL_KERNEL = np.ones((3, 3), np.uint8)


def _footprints(points: npt.NDArray[np.float64], normal: npt.NDArray[np.float64],
                pixel_area: float) -> npt.NDArray[np.float64]:
    """Area (m^2) of the plane with ``normal`` that each of ``points`` (N, 3) stands for: the
    strided pixel's footprint ``pixel_area * z^2`` over the cosine between its viewing ray and
    the normal, at most 1/0.2 (grazing views)."""
    cos = np.abs(points @ normal) / np.linalg.norm(points, axis=1)
    return pixel_area * points[:, 2] ** 2 / np.maximum(cos, 0.2)


def _occupied_area(points: npt.NDArray[np.float64], normal: npt.NDArray[np.float64],
                   part: npt.NDArray[np.int64], n: int) -> npt.NDArray[np.float64]:
    """Per label 0..n-1 of ``part`` (N,), the area (m^2) of the ``_WALL_CELL`` cells of the
    plane with ``normal`` that its ``points`` (N, 3), projected onto the plane, occupy.

    The footprints of :func:`_footprints` measure a surface that lies in the plane; a slab
    through a body seen edge-on (a bending person's side) holds the body's front surface
    across its thickness, each pixel at a grazing angle, and their footprints add up to a
    wall's. Projected onto the plane those points cover a thin curve."""
    axes = _plane_axes(normal) / _WALL_CELL
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

#: Pixels this close to the floor (metres) do not connect the static background's
#: components: the floor's noisy remnants would join a person's feet to a chair's legs.
FLOOR_BAND = 0.1

#: Points the floor is fitted on (see :func:`fit_floor`).
_FLOOR_SAMPLE = 512
