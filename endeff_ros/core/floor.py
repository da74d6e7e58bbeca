"""Section 3's floor: fitted by RANSAC among near-horizontal planes, then followed from frame to
frame, and the camera's motion read from where the floor now lies."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .planes import (
    footprints,
    hypothesis_triples,
    local_plane_hypotheses,
    plane_hypotheses,
    refine_plane,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    import numpy.typing as npt

    from .params import EndeffParams
    from .types import Columns


@dataclass(frozen=True)
class FloorPlane:
    """Plane ``normal . x + offset = 0`` with ``normal`` pointing up (towards -y), unit length.

    ``refit``: a known plane that may no longer hold (the camera moved):
    :func:`.cloud.foreground_cloud` fits the floor anew and uses this one only if no floor is
    found, returning it still marked ``refit`` so that the next frame tries again.
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
        idx = hypothesis_triples(len(sub), iterations)
    else:
        idx = rng.integers(0, len(sub), size=(iterations, 3))
    normals, p0 = plane_hypotheses(sub, idx)
    local_normals, local_p0 = local_plane_hypotheses(sub, idx[:, 0])
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
        if footprints(on, normals[best], pixel_area * n / len(sub)).sum() >= min_area:
            break
    else:
        return None
    normal, offset = refine_plane(sub[on_plane[:, best]], normals[best])
    if -normal[1] < cos_tilt or offset < FLOOR_MIN_CLEARANCE_M:
        return None
    return FloorPlane(normal, offset)


#: A floor shows at least this area inside the box (square metres; see :func:`fit_floor`).
FLOOR_MIN_AREA_M2 = 0.5
#: A floor lies at least this far below the camera's centre (metres): a camera looks at a
#: floor from above, and a plane through the camera is the fan of rays along an image border.
FLOOR_MIN_CLEARANCE_M = 0.1
#: Weight of a frame's own least-squares floor when a known floor follows it (see
#: :func:`follow_floor`); the known plane converges to what the frames show in about ten.
FLOOR_FOLLOW = 0.2
#: A floor found anew at more than this angle (degrees) to the known plane, at the same
#: height below the camera within FLOOR_SAME_HEIGHT_M (metres), means the camera turned
#: (see :func:`moved_floor`).
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
    normal, offset = refine_plane(np.stack([c[sample] for c in cols], axis=1), floor.normal)
    if -normal[1] < math.cos(math.radians(params.floor_max_tilt_deg)):
        return floor
    blended = (1 - FLOOR_FOLLOW) * floor.normal + FLOOR_FOLLOW * normal
    norm = float(np.linalg.norm(blended))
    return FloorPlane(blended / norm,
                      ((1 - FLOOR_FOLLOW) * floor.offset + FLOOR_FOLLOW * offset) / norm)


def fit_inside(cols: Columns, keep: npt.NDArray[np.bool_], params: EndeffParams,
               pixel_area: float) -> FloorPlane | None:
    """:func:`fit_floor` on a sample of the points ``keep`` (inside the box); ``pixel_area``:
    the solid angle of one of their pixels."""
    inside = np.flatnonzero(keep)
    step = max(1, len(inside) // FLOOR_SAMPLE)
    return fit_floor(np.stack([c[inside[::step]] for c in cols], axis=1),
                     distance=params.floor_distance, max_tilt_deg=params.floor_max_tilt_deg,
                     min_fraction=params.floor_min_fraction,
                     iterations=params.floor_iterations, sample=FLOOR_SAMPLE,
                     min_area=FLOOR_MIN_AREA_M2, pixel_area=pixel_area * step)


def moved_floor(floor: FloorPlane, cols: Columns, keep: npt.NDArray[np.bool_],
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
    fitted = fit_inside(cols, keep, params, pixel_area)
    if fitted is None:
        return None
    cos = float(np.clip(fitted.normal @ floor.normal, -1.0, 1.0))
    turned = math.degrees(math.acos(cos)) > FLOOR_TURNED_DEG
    if abs(fitted.offset - floor.offset) <= FLOOR_SAME_HEIGHT_M:
        return fitted if turned else None
    if turned or off_background is None:
        return None
    return fitted if off_background(fitted) else None


#: Pixels this close to the floor (metres) do not connect the static background's
#: components: the floor's noisy remnants would join a person's feet to a chair's legs.
FLOOR_BAND = 0.1
#: Points the floor is fitted on (see :func:`fit_floor`).
FLOOR_SAMPLE = 512
