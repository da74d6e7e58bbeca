"""Dense optical flow and 3D scene flow for the predict phase (Section 5.1).

The paper propagates the end-effectors E_t of frame t to frame t+1 with forward optical flow
between the colour images I_color^t and I_color^{t+1}, back-projected to 3D scene flow with the
depth images and the camera parameters (the dynamic model Dnc(E_t, θ_t)). The paper used Large
Displacement Optical Flow (LDOF), which is not in OpenCV; :class:`FlowEstimator` offers
OpenCV's DIS (Kroeger et al., 2016) and Farneback (2003) instead, and :func:`propagate_points`
turns the flow into the predicted 3D positions E_{t+1}^{pr}.

Why DIS ULTRAFAST at half resolution (the default): the flow budget in the full pipeline is
about 3 ms per frame on one core. Farneback costs several times that and loses large motions;
DIS MEDIUM is the most accurate and the slowest; of the presets that fit the budget, DIS
ULTRAFAST at scale 0.5 is the fastest and the most accurate at a moving limb. Its error grows
with the displacement (a few pixels for fast punches), which stays inside the tracker's
rectification distance, and the update phase prefers a current detection to a prediction
whenever one exists. The measured table (``python -m tools.flow_eval``) is in
docs/design.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from .errors import InputError, ParameterError

if TYPE_CHECKING:
    import numpy.typing as npt

    from .types import Intrinsics

#: Methods accepted by :class:`FlowEstimator`. ``'dis'`` is the measured default (ULTRAFAST).
METHODS: tuple[str, ...] = ('dis', 'dis_ultrafast', 'dis_fast', 'dis_medium', 'farneback')

_DIS_PRESETS = {
    'dis': cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    'dis_ultrafast': cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    'dis_fast': cv2.DISOPTICAL_FLOW_PRESET_FAST,
    'dis_medium': cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
}

#: Farneback parameters (pyr_scale, levels, winsize, iterations, poly_n, poly_sigma, flags):
#: OpenCV's sample values with one more pyramid level for displacements up to ~25 px.
FARNEBACK_PARAMS: tuple[float, int, int, int, int, float, int] = (0.5, 4, 15, 3, 5, 1.2, 0)


class FlowEstimator:
    """Forward dense optical flow between consecutive colour frames (Section 5.1, θ_t).

    Parameters
    ----------
    method:
        One of :data:`METHODS`. ``'dis'`` is DIS with the ULTRAFAST preset (chosen by
        measurement, see the module docstring); ``'dis_fast'`` and ``'dis_medium'`` are the
        slower presets; ``'farneback'`` is Farneback's polynomial expansion.
    scale:
        The flow is computed on grayscale images resized by this factor (0 < scale <= 1) and
        the vectors are rescaled to full resolution. 0.5 is 2-4x faster than 1.0 but loses
        accuracy on large motions of small objects (measured in the module docstring).

    The estimator holds one OpenCV algorithm object; it is not thread-safe. Thread count is
    the caller's choice (``cv2.setNumThreads``). A bad ``method`` or ``scale`` raises
    :class:`.ParameterError`; unusable images raise :class:`.InputError`.
    """

    def __init__(self, method: str = 'dis', *, scale: float = 0.5) -> None:
        if method not in METHODS:
            msg = f'unknown optical flow method {method!r}; choose one of {", ".join(METHODS)}'
            raise ParameterError(msg)
        if isinstance(scale, bool) or not (isinstance(scale, (int, float))
                                           and 0.0 < float(scale) <= 1.0):
            msg = f'flow scale must be in (0, 1], got {scale!r}'
            raise ParameterError(msg)
        self.method = method
        self.scale = float(scale)
        self._dis: Any = None
        if method in _DIS_PRESETS:
            self._dis = cv2.DISOpticalFlow.create(_DIS_PRESETS[method])

    def __repr__(self) -> str:
        return f'FlowEstimator(method={self.method!r}, scale={self.scale})'

    @staticmethod
    def _gray(image: npt.NDArray[Any], name: str) -> npt.NDArray[np.uint8]:
        image = np.asarray(image)
        if image.dtype != np.uint8:
            msg = f'{name} must be uint8, got {image.dtype}'
            raise InputError(msg)
        if image.ndim == 2:
            return np.ascontiguousarray(image)
        if image.ndim == 3 and image.shape[2] == 3:
            return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)  # OpenCV reads crops in place
        if image.ndim == 3 and image.shape[2] == 1:
            return np.ascontiguousarray(image[:, :, 0])
        msg = f'{name} must be (H, W, 3) RGB or (H, W) grayscale, got shape {image.shape}'
        raise InputError(msg)

    def flow(self, prev_rgb: npt.NDArray[np.uint8], cur_rgb: npt.NDArray[np.uint8], *,
             upsample: bool = True) -> npt.NDArray[np.float32]:
        """Forward flow from ``prev_rgb`` (frame t) to ``cur_rgb`` (frame t+1).

        Both images are (H, W, 3) uint8 RGB (or (H, W) grayscale) of the same size. Returns
        (H, W, 2) float32: the displacement (du, dv) in full-resolution pixels of every pixel
        of the previous frame, so that ``prev[v, u] ~ cur[v + dv, u + du]``. With
        ``upsample=False`` the field stays at the working resolution (``scale`` times the
        size; vectors still in full-resolution pixels): :func:`propagate_points` reads it
        with ``flow_scale``, which saves the upsampling.
        """
        prev = self._gray(prev_rgb, 'previous colour image')
        cur = self._gray(cur_rgb, 'current colour image')
        if prev.shape != cur.shape:
            msg = (f'colour images differ in size: previous {prev.shape[1]}x{prev.shape[0]}, '
                   f'current {cur.shape[1]}x{cur.shape[0]}')
            raise InputError(msg)
        h, w = prev.shape
        if h < 8 or w < 8:
            msg = f'colour images of {w}x{h} are too small for optical flow (need >= 8x8)'
            raise InputError(msg)
        sw, sh = w, h
        if self.scale < 1.0:
            sw, sh = max(8, round(w * self.scale)), max(8, round(h * self.scale))
            prev = cv2.resize(prev, (sw, sh), interpolation=cv2.INTER_AREA)
            cur = cv2.resize(cur, (sw, sh), interpolation=cv2.INTER_AREA)
        if self._dis is not None:
            small = self._dis.calc(prev, cur, None)
        else:
            small = cv2.calcOpticalFlowFarneback(prev, cur, None, *FARNEBACK_PARAMS)
        if (sw, sh) == (w, h):
            return np.ascontiguousarray(small, dtype=np.float32)
        # Scale the vectors to full-resolution pixels before upsampling (4x fewer pixels;
        # bilinear upsampling is linear, so the order does not matter).
        small[:, :, 0] *= np.float32(w / sw)
        small[:, :, 1] *= np.float32(h / sh)
        if not upsample:
            return small
        return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)



# --- 3D scene flow: propagate points (Section 5.1, E_{t+1}^{pr} = Dnc(E_t, θ_t)) -------------

def _offsets(window: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Row and column offsets of a square ``window`` (odd side, pixels), each (K,)."""
    half = window // 2
    d = np.arange(-half, half + 1)
    dr, dc = np.meshgrid(d, d, indexing='ij')
    return dr.ravel(), dc.ravel()


def _gather(image: npt.NDArray[Any], rows: npt.NDArray[Any],
            cols: npt.NDArray[Any]) -> npt.NDArray[np.float64]:
    """``image[rows, cols]`` as float64 for (N, K) float pixel indices; outside -> NaN."""
    h, w = image.shape[:2]
    if h == 0 or w == 0:
        return np.full(rows.shape + image.shape[2:], np.nan)
    with np.errstate(invalid='ignore'):
        inside = (rows >= 0) & (rows <= h - 1) & (cols >= 0) & (cols <= w - 1)  # NaN: False
    r = np.where(inside, rows, 0).astype(np.intp)
    c = np.where(inside, cols, 0).astype(np.intp)
    values = image[r, c].astype(np.float64)
    values[~inside] = np.nan
    return values


def _masked_median(values: npt.NDArray[np.float64],
                   valid: npt.NDArray[np.bool_]) -> tuple[npt.NDArray[np.float64],
                                                           npt.NDArray[np.int64]]:
    """Row-wise median of ``values`` (N, K) over ``valid``; (N,) medians (NaN if none), counts."""
    n = values.shape[0]
    count = valid.sum(axis=1)
    if values.shape[1] == 0:
        return np.full(n, np.nan), count
    ordered = np.sort(np.where(valid, values, np.inf), axis=1)
    rows = np.arange(n)
    lo = np.maximum((count - 1) // 2, 0)
    hi = np.minimum(count // 2, values.shape[1] - 1)
    with np.errstate(invalid='ignore'):
        median = 0.5 * (ordered[rows, lo] + ordered[rows, hi])
    median[count == 0] = np.nan
    return median, count


def _check_image(name: str, image: Any, shape: tuple[int, ...]) -> npt.NDArray[Any]:
    array = np.asarray(image)
    if array.shape != shape:
        got = 'x'.join(str(s) for s in array.shape)
        want = 'x'.join(str(s) for s in shape)
        msg = f'{name} has shape {got} but the camera info implies {want} (H x W[ x 2])'
        raise InputError(msg)
    return array


def propagate_points(points: npt.ArrayLike, flow: npt.NDArray[np.float32],
                     prev_depth: npt.NDArray[np.float32], cur_depth: npt.NDArray[np.float32],
                     intrinsics: Intrinsics, *, window: int = 7, depth_tolerance: float = 0.1,
                     flow_origin: tuple[int, int] | None = None,
                     flow_scale: tuple[float, float] = (1.0, 1.0),
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Move 3D points of frame t to frame t+1 with optical flow and depth (3D scene flow).

    Parameters
    ----------
    points:
        (N, 3) float64 end-effector positions E_t in the optical frame of frame t, metres.
    flow:
        (H, W, 2) forward optical flow t -> t+1 in pixels (:meth:`FlowEstimator.flow`).
    prev_depth, cur_depth:
        (H, W) float32 depth of frames t and t+1 in metres, NaN (or <= 0) where invalid,
        registered to the colour images.
    intrinsics:
        Pinhole K of the depth images (same for both frames), image size H x W.
    window:
        Side of the square pixel window (odd, >= 1) for the robust reads; the fallback window is
        ``max(3 * window, 21)``.
    depth_tolerance:
        Metres. A pixel of the window belongs to the point's surface if its depth is within this
        of the point's depth (frame t) or of the expected depth (frame t+1).
    flow_origin:
        ``None``: ``flow`` covers the image. ``(u0, v0)``: ``flow`` covers only a region of
        interest (any size inside the image, possibly empty) whose top-left pixel is
        (u0, v0); pixels outside it have no flow.
    flow_scale:
        ``(sx, sy)``: ``flow`` is sampled at this fraction of the image resolution (a field
        from ``FlowEstimator.flow(..., upsample=False)``): pixel (u, v) reads
        ``flow[floor((v - v0) * sy), floor((u - u0) * sx)]``. The region then covers
        ``flow.shape / scale`` pixels.

    Returns
    -------
    (N, 3) float64 predicted points E_{t+1}^{pr} (always finite) and (N,) bool ``reliable``.

    Method: project each point into frame t; the flow is the median over the window of the
    pixels whose flow is finite and whose previous depth is within ``depth_tolerance`` of the
    point's z (so a hand in front of the torso takes the hand's motion, not the torso's). The
    neighbourhood's depth change Δz is the median of ``cur_depth(p + flow(p)) - prev_depth(p)``
    over those pixels, ignoring jumps above ``2 * depth_tolerance`` (occlusions). At the moved
    pixel the new depth is the median of the current depths within ``depth_tolerance`` of
    z + Δz; the point is back-projected with it. A point that becomes occluded (e.g. the torso
    behind a moving hand) thus keeps its own depth instead of jumping onto the occluder.

    Fallbacks (``reliable`` False): too few valid pixels -> the larger window; still none ->
    zero motion (flow) or z + Δz (depth). Points that do not project into frame t (outside the
    image or z <= 0) are returned unchanged.

    Lost surface (``reliable`` False, zero motion): a point whose new depth lies more than
    ``depth_tolerance`` *behind* its old one. The flow then slipped off a part that moved
    across a farther surface (a hand hanging in front of the legs, whose pixels now see the
    legs; the flow of a small fast part is underestimated): its window reads the farther
    surface as a depth change, and the point would be carried onto the legs and stay there.
    Receding more than the tolerance in one frame (3 m/s at 30 Hz with 0.1 m) is rare for
    a body part, approaching faster is kept (the neighbourhood Δz rule above). Its effect on
    the benchmark is in docs/design.md.

    Vectorised over points (window gathers by fancy indexing; the large window only for the
    points that need it): about 0.5 ms for 20 points on one core.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        msg = f'points must be an (N, 3) array, got shape {pts.shape}'
        raise InputError(msg)
    if not np.isfinite(pts).all():
        msg = 'points must be finite (got NaN or inf coordinates)'
        raise InputError(msg)
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1 \
            or window % 2 == 0:
        msg = f'window must be an odd integer >= 1, got {window!r}'
        raise InputError(msg)
    if not (np.isfinite(depth_tolerance) and depth_tolerance > 0):
        msg = f'depth_tolerance must be a positive number of metres, got {depth_tolerance!r}'
        raise InputError(msg)
    h, w = intrinsics.height, intrinsics.width
    if not (len(flow_scale) == 2 and all(0.0 < float(f) <= 1.0 for f in flow_scale)):
        msg = f'flow_scale must be two factors in (0, 1], got {flow_scale!r}'
        raise InputError(msg)
    if flow_origin is None:
        flow, u0, v0 = _check_image('flow', flow, (h, w, 2)), 0, 0
    else:
        flow, (u0, v0) = np.asarray(flow), flow_origin
        if not (flow.ndim == 3 and flow.shape[2] == 2 and 0 <= u0 and 0 <= v0
                and u0 + flow.shape[1] / flow_scale[0] <= w + 1
                and v0 + flow.shape[0] / flow_scale[1] <= h + 1):
            msg = (f'flow region of shape {flow.shape} at (u, v) = ({u0}, {v0}) does not fit '
                   f'the {w}x{h} image of the camera info')
            raise InputError(msg)
    prev_depth = _check_image('previous depth', prev_depth, (h, w))
    cur_depth = _check_image('current depth', cur_depth, (h, w))
    n = pts.shape[0]
    if n == 0:
        return pts.copy(), np.zeros(0, dtype=bool)

    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    front = z > 1e-6
    zs = np.where(front, z, 1.0)
    u = intrinsics.fx * x / zs + intrinsics.cx
    v = intrinsics.fy * y / zs + intrinsics.cy
    inside = front & (u > -0.5) & (u < w - 0.5) & (v > -0.5) & (v < h - 0.5)
    ur, vr = np.rint(np.where(inside, u, 0.0)), np.rint(np.where(inside, v, 0.0))

    small, large = window, max(3 * window, 21) | 1
    min_valid = {small: min(3, small * small), large: 3}

    def flow_read(win: int, sel: npt.NDArray[np.intp]) -> tuple[npt.NDArray[Any], ...]:
        """Median flow (du, dv), neighbourhood Δz and enough-valid flag of points ``sel``."""
        dr, dc = _offsets(win)
        rows, cols = vr[sel, None] + dr, ur[sel, None] + dc
        f = _gather(flow, (rows - v0) * flow_scale[1], (cols - u0) * flow_scale[0])
        d0 = _gather(prev_depth, rows, cols)
        with np.errstate(invalid='ignore'):
            ok = (np.isfinite(f).all(axis=2) & (d0 > 0)
                  & (np.abs(d0 - z[sel, None]) <= depth_tolerance))
        m = len(sel)
        med, count = _masked_median(np.concatenate([f[:, :, 0], f[:, :, 1]]),
                                    np.concatenate([ok, ok]))
        d1 = _gather(cur_depth, np.where(ok, np.rint(rows + f[:, :, 1]), -1.0),
                     np.where(ok, np.rint(cols + f[:, :, 0]), -1.0))
        with np.errstate(invalid='ignore'):
            # A jump of more than 2 tolerances in one frame is an occlusion (the pixel now
            # sees another surface), not motion of this one.
            dz_ok = ok & (d1 > 0) & (np.abs(d1 - d0) <= 2.0 * depth_tolerance)
        dz, _ = _masked_median(d1 - d0, dz_ok)
        return med[:m], med[m:], dz, count[:m] >= min_valid[win]

    # Flow: the small window, then the large one for the points that need it, then no motion.
    du, dv, dz = np.zeros(n), np.zeros(n), np.full(n, np.nan)
    flow_ok = np.zeros(n, dtype=bool)
    sel = np.flatnonzero(inside)
    for win in (small, large):
        sel = np.flatnonzero(inside & ~flow_ok) if win == large else np.flatnonzero(inside)
        if sel.size == 0:
            continue
        med_u, med_v, med_dz, ok = flow_read(win, sel)
        du[sel[ok]], dv[sel[ok]], dz[sel[ok]] = med_u[ok], med_v[ok], med_dz[ok]
        if win == small:
            flow_ok[sel] = ok
    dz = np.where(np.isfinite(dz), dz, 0.0)

    tu, tv = u + du, v + dv
    target_inside = (tu > -0.5) & (tu < w - 0.5) & (tv > -0.5) & (tv < h - 0.5)
    z_expected = z + dz
    tr, tc = np.rint(np.where(inside, tv, 0.0)), np.rint(np.where(inside, tu, 0.0))

    def depth_read(win: int, sel: npt.NDArray[np.intp]) -> tuple[npt.NDArray[Any], ...]:
        dr, dc = _offsets(win)
        d = _gather(cur_depth, tr[sel, None] + dr, tc[sel, None] + dc)
        with np.errstate(invalid='ignore'):
            ok = (d > 0) & (np.abs(d - z_expected[sel, None]) <= depth_tolerance)
        med, count = _masked_median(d, ok)
        return med, count >= min_valid[win]

    # Depth at the target: small window, large window, then z + Δz.
    z_new = z_expected.copy()
    depth_ok = np.zeros(n, dtype=bool)
    sel = np.flatnonzero(inside)
    if sel.size:
        med, ok = depth_read(small, sel)
        z_new[sel[ok]], depth_ok[sel] = med[ok], ok
    sel = np.flatnonzero(inside & ~depth_ok)
    if sel.size:
        med, ok = depth_read(large, sel)
        z_new[sel[ok]] = med[ok]
    z_new = np.where(np.isfinite(z_new) & (z_new > 1e-6), z_new, z)
    lost = inside & (z_new - z > depth_tolerance)  # it slipped onto a surface behind
    if lost.any():
        tu, tv, z_new = np.where(lost, u, tu), np.where(lost, v, tv), np.where(lost, z, z_new)
        depth_ok &= ~lost

    out = pts.copy()
    out[:, 0] = np.where(inside, (tu - intrinsics.cx) * z_new / intrinsics.fx, x)
    out[:, 1] = np.where(inside, (tv - intrinsics.cy) * z_new / intrinsics.fy, y)
    out[:, 2] = np.where(inside, z_new, z)
    bad = ~np.isfinite(out).all(axis=1)
    out[bad] = pts[bad]
    reliable = inside & flow_ok & target_inside & depth_ok & ~bad
    return out, reliable
