"""Typed inputs and results shared by the core, the ROS adapter and the offline tools.

Coordinates are in the camera's optical frame (x right, y down, z forward), in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from .errors import InputError

if TYPE_CHECKING:
    import numpy.typing as npt

    #: x, y and z columns of N points (the back-projected pixels of Section 3).
    Columns = tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]


class Pixels(NamedTuple):
    """The pixels of a strided depth image that became points, in the points' order: the
    image's ``shape`` (H, W) and each point's flat (row-major) pixel ``index``. Passed instead
    of an (H, W) mask because numpy gathers and scatters through an index array several
    times faster than through a boolean mask."""

    shape: tuple[int, int]
    index: npt.NDArray[np.intp]

    @classmethod
    def of(cls, valid: npt.NDArray[np.bool_]) -> Pixels:
        """The ``True`` pixels of the (H, W) mask ``valid``."""
        return cls(valid.shape, np.flatnonzero(valid))

    def image(self, values: npt.ArrayLike, fill: float | bool, dtype: npt.DTypeLike,
              ) -> npt.NDArray:
        """An (H, W) image of ``dtype`` holding ``values`` (one per point, or one for all)
        at the pixels and ``fill`` elsewhere."""
        out = np.full(self.shape, fill, dtype=dtype)
        out.reshape(-1)[self.index] = values
        return out

    def read(self, image: npt.NDArray) -> npt.NDArray:
        """The values of an (H, W) or (H, W, C) ``image`` at the pixels (one per point)."""
        return image.reshape((-1, *image.shape[2:]))[self.index]


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of the depth image (registered to colour), in pixels."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        values = (self.fx, self.fy, self.cx, self.cy)
        if not all(math.isfinite(v) for v in values) or self.fx <= 0 or self.fy <= 0:
            msg = (f'camera intrinsics are unusable: fx={self.fx}, fy={self.fy}, cx={self.cx}, '
                   f'cy={self.cy} (need finite fx, fy > 0; is the camera calibrated?)')
            raise InputError(msg)
        if self.width <= 0 or self.height <= 0:
            msg = f'camera info has an empty image size {self.width}x{self.height}'
            raise InputError(msg)

    @classmethod
    def from_k(cls, k: npt.ArrayLike, width: int, height: int) -> Intrinsics:
        """From the row-major 3x3 matrix K of ``sensor_msgs/CameraInfo``."""
        kk = np.asarray(k, dtype=np.float64).reshape(-1)
        if kk.size != 9:
            msg = f'camera matrix K must have 9 elements, got {kk.size}'
            raise InputError(msg)
        return cls(float(kk[0]), float(kk[4]), float(kk[2]), float(kk[5]), int(width),
                   int(height))

    def k_matrix(self) -> npt.NDArray[np.float64]:
        """The 3x3 camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """(N, 3) points -> (N, 2) pixel coordinates (u, v)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        z = p[:, 2]
        return np.stack([self.fx * p[:, 0] / z + self.cx, self.fy * p[:, 1] / z + self.cy], 1)


#: A Kinect/RealSense-class 640x480 depth camera (fx = fy = 525, principal point at the
#: image centre): the synthetic data's camera and the node's warm-up frames.
KINECT_640 = Intrinsics(525.0, 525.0, 319.5, 239.5, 640, 480)


@dataclass(frozen=True)
class RGBDFrame:
    """One synchronised RGB-D frame.

    ``depth`` is (H, W) float32 in metres with NaN where there is no reading; ``color`` is
    (H, W, 3) uint8 RGB (or None when only depth is available).
    """

    stamp_ns: int
    frame_id: str
    depth: npt.NDArray[np.float32]
    intrinsics: Intrinsics
    color: npt.NDArray[np.uint8] | None = None

    def __post_init__(self) -> None:
        if self.depth.ndim != 2:
            msg = f'depth must be a 2-D image, got shape {self.depth.shape}'
            raise InputError(msg)
        h, w = self.depth.shape
        if (w, h) != (self.intrinsics.width, self.intrinsics.height):
            msg = (f'depth image is {w}x{h} but camera info says '
                   f'{self.intrinsics.width}x{self.intrinsics.height}')
            raise InputError(msg)
        if self.color is not None and self.color.shape[:2] != (h, w):
            msg = (f'colour image is {self.color.shape[1]}x{self.color.shape[0]} but depth is '
                   f'{w}x{h} (depth must be registered to colour)')
            raise InputError(msg)


@dataclass(frozen=True)
class Candidate:
    """An end-effector candidate found in one frame by the Section 4 estimator.

    ``geodesic`` is Eq. 6 (sum of edge weights on the shortest path to the root);
    ``geodesic_approx`` is Eq. 7 (through the mid-band of that path); ``path`` holds the
    sub-band centroids from the end-effector to the root, (K, 3); ``protrusion`` is its
    geodesic distance to the root and the earlier end-effectors' paths when the iterated
    Dijkstra found it (compared with g). ``position`` is the centre of the terminal part;
    ``centre_shift`` leads to it along the part's axis from the centre of its rounded end (one
    radius inside the extreme), the point the tracker follows: zero for a round end such as a
    head, up to one part radius for a long one such as a hand. ``extreme`` is the graph node
    the path ended at when that was a sliver and ``node`` lies back along the path (None: the
    node itself); a cut there cuts the candidate too.

    For the candidate scorer (:mod:`.candidates`): ``width`` is the terminal part's visible
    width across its axis (NaN: no axis), ``order`` the rank in which the iterated Dijkstra
    found it in its entity, ``thresholds`` whether the thresholds of Section 4 alone keep it
    (g or the chain rule, not a broad corner, not cut by the view), ``broad`` and ``cut``
    those two verdicts, and ``score`` the scorer's chance that it is an end-effector (NaN:
    not scored).
    """

    position: npt.NDArray[np.float64]
    node: int
    geodesic: float
    geodesic_approx: float
    path: npt.NDArray[np.float64]
    protrusion: float = 0.0
    centre_shift: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    extreme: int | None = None
    width: float = float('nan')
    order: int = 0
    thresholds: bool = True
    broad: bool = False
    cut: bool = False
    score: float = float('nan')

    @property
    def end_centre(self) -> npt.NDArray[np.float64]:
        """The centre of the rounded end: what the tracker follows (``position`` less
        ``centre_shift``)."""
        return self.position - self.centre_shift


@dataclass(frozen=True)
class Track:
    """A tracked end-effector as published (one row of the ``end_effectors`` cloud).

    ``state`` is 0 when a current-frame candidate supports it, 1 when it is predicted only.
    ``velocity`` (m/s, optical frame) is the track's, zero in its first frame; ``kind`` which
    part of a person the end is (``KIND_*``; 0: other or not known). ``position`` is filtered
    along the track when the tracker smooths (``smoothing``); ``raw_position`` is then the
    unfiltered one, for debugging (None: the same as ``position``).
    """

    id: int
    entity: int
    position: npt.NDArray[np.float64]
    geodesic: float
    confidence: float
    state: int
    age: int
    path: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    velocity: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    kind: int = 0
    raw_position: npt.NDArray[np.float64] | None = None

    DETECTED = 0
    PREDICTED = 1
    KIND_OTHER = 0
    KIND_HEAD = 1
    KIND_HAND = 2
    KIND_FOOT = 3
