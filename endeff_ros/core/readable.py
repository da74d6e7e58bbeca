"""Where the sensor can read: the dead margins of registered depth, found from the readings.

Depth registered to a colour image reads nothing along bands of the image border where the
colour camera sees more than the depth camera (Kinect v1 / Xtion: rows 0-33 and 464-479,
columns 0-40 and 605-639 at 640x480; RealSense aligned depth: a band on the left; Kinect v2:
a band on either side; Azure Kinect NFOV: a hexagon, the corners cut off). A body cut by such
a margin ends on its edge, and its farthest sub-band there is no end-effector; the image
border's rule (``cut_margin_px``, :func:`.single_frame.cut_nodes`) must count from that edge.

**Each side's edge is a straight line, or it is not a margin.** Per row (left and right) and
per column (top and bottom) the readings stop at the *edge*: the first pixel read from that
side. Over a margin those edges lie on one line, the same in every row, whatever is in the
scene: ``e(t) = a + b |t - mid| + c (t - mid)`` fits a band (b = c = 0), a slanted band (c)
and the hexagon's two diagonals meeting at the side's middle (b). Fitted robustly (least
squares, then again on the rows within ``FIT_TOL_PX``), the fit is taken when at least
``MIN_INLIERS`` of the rows that read anything agree with it and the line lies inside the
image (more than the cut margin itself in at least one row). Where the readings stop for the
scene's sake (a time-of-flight sensor reading nothing beyond its range above a person's head,
a window, a black object), the edges follow the scene's shapes and no line fits them.

A point is on the edge only where the readings of its own row (column) do reach the fitted
line, within ``FIT_TOL_PX``: a head under a band beyond range, whose top is lower than the
band's line, is not cut by it even when the line was fitted. Nor where the band is thinner
than :data:`MIN_CUT_DEPTH`: what ends in a thin band is only clipped.

**Learnt from the stream** (:class:`ReadableArea`): a pixel that read once is readable, so
the edges come from every frame seen since the start (at the stride the cloud is built at):
a margin never reads, while a person who passes uncovers what a single frame hides. A single
frame (no stream, the single-frame estimator without a tracker) uses its own readings.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

#: Edges within this many pixels (of the strided image) of the fitted line agree with it.
FIT_TOL_PX = 1.5
#: A side's line lies at most this fraction of the side's length inside the image (the
#: deepest real margin: the Azure Kinect NFOV's corners, a fifth of the width).
MAX_DEPTH = 0.3
#: A side's line is taken when at least this fraction of its rows (columns) agree with it.
MIN_INLIERS = 0.75
#: A margin cuts ends only where it is at least this fraction of the image deep (of its height
#: for the top and bottom, of its width for the sides). A thin band (Kinect v1's and the
#: Xtion's bottom 16 rows of 480: 3 %) hides a few centimetres of a part that ends in it, so
#: the end found at its edge is the part's end, seen a little short: a clipped foot. Deeper
#: bands hide whole parts (a forearm, a torso) and their edge makes false ends. Dev subset
#: (37 bags), temporal recall / FPR: every margin cuts 0.571 / 0.336, not those under 5 %
#: 0.583 / 0.340, none 0.607 / 0.385 (docs/design.md, "Dead margins").
MIN_CUT_DEPTH = 0.05


class SideFit(NamedTuple):
    """The fitted edge of one side: ``line[t]`` (pixels in from that side, strided image) per
    row or column ``t``, and ``on[t]``, whether the readings of that row reach the line."""

    line: npt.NDArray[np.float64]
    on: npt.NDArray[np.bool_]


class Edges(NamedTuple):
    """The readable area's edges, fitted per side (None: that side is the image border),
    on an image of ``shape`` at ``stride``."""

    shape: tuple[int, int]
    stride: int
    left: SideFit | None
    right: SideFit | None
    top: SideFit | None
    bottom: SideFit | None

    def near(self, u: npt.NDArray[np.float64], v: npt.NDArray[np.float64],
             margin_px: float) -> npt.NDArray[np.bool_]:
        """Per full-resolution pixel (u, v), whether it lies within ``margin_px`` of a fitted
        edge (only in rows or columns whose readings reach it, and where the margin is at
        least :data:`MIN_CUT_DEPTH` deep)."""
        s = self.stride
        h, w = self.shape
        us, vs, m = u / s, v / s, margin_px / s
        row = np.clip(np.round(vs).astype(np.int64), 0, h - 1)
        col = np.clip(np.round(us).astype(np.int64), 0, w - 1)
        out = np.zeros(len(us), bool)
        for fit, t, dist, extent in ((self.left, row, us, w), (self.right, row, w - 1 - us, w),
                                     (self.top, col, vs, h), (self.bottom, col, h - 1 - vs, h)):
            if fit is not None:
                deep = fit.line[t] >= MIN_CUT_DEPTH * extent
                out |= fit.on[t] & deep & (dist < fit.line[t] + m)
        return out


def _edge_profile(read: npt.NDArray[np.bool_]) -> npt.NDArray[np.float64]:
    """Per row of ``read`` (H, W), the first column read from the left (NaN: none read)."""
    first = np.argmax(read, axis=1).astype(np.float64)
    first[~read.any(axis=1)] = np.nan
    return first


def _fit_side(edge: npt.NDArray[np.float64], margin_px: float, across: int) -> SideFit | None:
    """The line through ``edge`` (one side's per-row edges, NaN where nothing read, on rows
    ``across`` pixels long), or None when no line fits most of them or the line lies on the
    image border."""
    t = np.arange(len(edge), dtype=np.float64)
    have = np.isfinite(edge)
    if np.count_nonzero(have) < max(8, 0.2 * len(edge)):
        return None
    mid = 0.5 * (len(edge) - 1)
    basis = np.stack([np.ones_like(t), np.abs(t - mid), t - mid], axis=1)
    use = have
    coef = None
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(basis[use], edge[use], rcond=None)
        resid = np.abs(basis @ coef - edge)
        use = have & (resid <= FIT_TOL_PX)
        if np.count_nonzero(use) < 3:
            return None
    line = basis @ coef
    if np.count_nonzero(use) < MIN_INLIERS * np.count_nonzero(have):
        return None
    if (np.max(line) <= margin_px or np.min(line) < -FIT_TOL_PX
            or np.max(line) > MAX_DEPTH * across):
        return None  # the image border itself, a line outside the image, or too deep
    return SideFit(line=np.maximum(line, 0.0), on=use)


def edge_profiles(read: npt.NDArray[np.bool_]) -> tuple[npt.NDArray[np.float64], ...]:
    """The left, right, top and bottom edge profiles of ``read`` (:func:`_edge_profile`):
    all that :func:`fit_edges` fits."""
    return (_edge_profile(read), _edge_profile(read[:, ::-1]), _edge_profile(read.T),
            _edge_profile(read[::-1].T))


def fit_edges(read: npt.NDArray[np.bool_], stride: int, margin_px: float,
              profiles: tuple[npt.NDArray[np.float64], ...] | None = None) -> Edges:
    """The readable area's edges from ``read`` (H, W) of the strided image: True where a
    reading was seen (or from its ``profiles``, :func:`edge_profiles`, when known).
    ``margin_px`` (full resolution): the cut margin, below which a line is the image border
    anyway."""
    m = margin_px / stride
    h, w = read.shape
    left, right, top, bottom = edge_profiles(read) if profiles is None else profiles
    return Edges(read.shape, stride, left=_fit_side(left, m, w), right=_fit_side(right, m, w),
                 top=_fit_side(top, m, h), bottom=_fit_side(bottom, m, h))


def strided_read(depth: npt.NDArray[np.floating], stride: int) -> npt.NDArray[np.bool_]:
    """Where the (full-resolution) depth image reads, at ``stride``."""
    d = depth[::stride, ::stride]
    return np.isfinite(d) & (d > 0)


class ReadableArea:
    """The readable area of one camera's stream: every pixel that has read since the start
    (or since the image size or stride changed), and its fitted edges."""

    def __init__(self) -> None:
        self._ever: npt.NDArray[np.bool_] | None = None
        self._stride = 0
        self._edges: Edges | None = None
        self._profiles: tuple[npt.NDArray[np.float64], ...] = ()
        self._margin_px = -1.0

    def update(self, depth: npt.NDArray[np.floating], stride: int,
               margin_px: float) -> Edges:
        """Learn the readings of ``depth`` (full resolution) and return the edges, fitted
        again only when a side's edge profile moved. A still camera's readable area stops
        growing at its borders within seconds; inside it, pixels beyond the sensor's range
        read for the first time whenever a person walks in front of them, which changes no
        profile and so no fit (on a furnished mocap bag that was a refit in 82 of 87 frames)."""
        read = strided_read(depth, stride)
        if self._ever is None or self._ever.shape != read.shape or self._stride != stride:
            self._ever, self._stride, self._edges = read.copy(), stride, None
            self._profiles = edge_profiles(self._ever)
        elif (read & ~self._ever).any():
            self._ever |= read
            profiles = edge_profiles(self._ever)
            if not all(np.array_equal(a, b, equal_nan=True)
                       for a, b in zip(profiles, self._profiles)):
                self._profiles, self._edges = profiles, None
        if self._edges is None or self._margin_px != margin_px:
            self._edges = fit_edges(self._ever, stride, margin_px, self._profiles)
            self._margin_px = margin_px
        return self._edges
