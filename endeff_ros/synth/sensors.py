"""Depth sensor models for the ``mocap`` suite: structured light, time of flight, active stereo.

Every model turns an ideal render (``render.Rendered``) into the depth image a driver would
publish registered to the colour image (same size and intrinsics, as the drivers' aligned
topics), NaN = no reading. All operations are whole-image numpy/OpenCV; the only Python loops
run over a few kernel offsets or disparity shifts, never over pixels.

- Structured light (Kinect v1, Xtion): ``sensor.depth_image``, the paper suite's model.
- Time of flight (Azure Kinect NFOV, Kinect v2): a pixel at a depth edge integrates light from
  both surfaces, so its phase gives a depth between them (flying pixels, on both sides of the
  edge, 1-2 px wide); indirect light adds path length in concave regions (multipath: pixels
  farther than their surroundings read farther still); the return amplitude falls with
  albedo, incidence and 1/z^2, so dark surfaces (hair, dark shoes) drop out and the noise
  grows as the amplitude falls (sigma = sigma0 * (z / 1 m) / sqrt(amplitude)).
- Active stereo (RealSense D435, D455): depth from disparity d = f B / z with sub-pixel
  disparity noise (sigma_z = z^2 sigma_d / (f B), hence growing with z^2), spatially
  correlated "speckle" disparity noise, no reading where the second imager cannot see the
  surface (left of a near edge, width f B (1/z_far - 1/z_near) px), foreground fattening of
  block matching at edges, small invalid blobs, and a minimum distance.

Registered depth also has *dead margins*: parts of the colour image that the depth camera does
not see once its image is mapped onto the colour camera's, where the driver publishes no
reading (``DeadMargin``, the field ``SensorModel.margin``; ``None`` renders the whole image, as
the paper suite's sensor does). A body cut by such a margin looks cut at the image border, so
a benchmark that leaves them out never shows the false ends a real camera gives there. Colour
is full-frame: only depth is dead.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

from ..core.types import KINECT_640, Intrinsics
from . import sensor as structured_light
from .render import Rendered, background

KINDS = ('structured_light', 'tof', 'stereo')


@dataclass(frozen=True)
class DeadMargin:
    """Where registered depth has no reading, as fractions of the image's width and height
    (so that one model serves every resolution of a camera): bands along the four borders,
    and ``corner`` (of the width) cut off each corner along a line from that far in on the top
    or bottom row to the middle of the side (a hexagon, Azure Kinect NFOV). Sizes at the
    models' resolutions are in docs/mocap-suite.md."""

    top: float = 0.0
    bottom: float = 0.0
    left: float = 0.0
    right: float = 0.0
    corner: float = 0.0

    def __post_init__(self) -> None:
        sides = (self.top, self.bottom, self.left, self.right, self.corner)
        if not all(0.0 <= f < 0.5 for f in sides):
            msg = f'dead margins must be fractions in [0, 0.5), got {sides}'
            raise ValueError(msg)

    def mask(self, width: int, height: int) -> npt.NDArray[np.bool_]:
        """(height, width) bool, True where depth has no reading."""
        return _margin_mask(self, width, height).copy()


@lru_cache(maxsize=32)
def _margin_mask(margin: DeadMargin, width: int, height: int) -> npt.NDArray[np.bool_]:
    u = np.arange(width) + 0.5
    v = (np.arange(height) + 0.5)[:, None]
    dead = ((v < margin.top * height) | (v > height - margin.bottom * height)
            | (u < margin.left * width) | (u > width - margin.right * width))
    if margin.corner > 0:
        cut = margin.corner * width * np.abs(v - 0.5 * height) / (0.5 * height)
        dead = dead | (u < cut) | (width - u < cut)
    dead = np.broadcast_to(dead, (height, width)).copy()
    dead.flags.writeable = False
    return dead


# Kinect v1 and Xtion (structured light, registered by the driver): no reading in rows 0-33 and
# 464-479 and columns 0-40 and 605-639 of a 640x480 image (measured on a real sequence).
_PRIMESENSE_MARGIN = DeadMargin(top=34 / 480, bottom=16 / 480, left=41 / 640, right=35 / 640)
# RealSense D4xx aligned to colour: the left band that only the left imager sees, 75 px of 848
# on a D435 (60-90 px reported), the same fraction on a D455.
_REALSENSE_MARGIN = DeadMargin(left=75 / 848)
# Azure Kinect NFOV unbinned: a hexagon-like valid area, the corners cut off.
_AZURE_NFOV_MARGIN = DeadMargin(corner=0.2)
# Kinect v2 registered to colour: the colour camera's 84 degrees across against the depth
# camera's 70.6 leave a band on either side (about 10 % of the width each).
_KINECT_V2_MARGIN = DeadMargin(left=0.105, right=0.105)


@dataclass(frozen=True)
class SensorModel:
    """One camera model: registered depth intrinsics and the depth noise parameters.

    ``z_min``/``z_max`` (m) bound the readings; ``baseline_m`` and ``disparity_sigma_px`` are
    for stereo (the depth imager's focal length in the colour image's pixels is used, since
    depth is registered to colour); ``tof_sigma_m`` is the ToF noise at 1 m and full amplitude.
    ``color_encoding`` is what the vendor's ROS driver publishes on its colour topic.
    ``margin``: the registered depth's dead margins (``None``: a reading can come from any
    pixel; ``dataclasses.replace(model, margin=None)`` renders a bag's twin without them).
    """

    name: str
    kind: str
    intrinsics: Intrinsics
    z_min: float
    z_max: float
    color_encoding: str = 'rgb8'
    baseline_m: float = 0.0
    disparity_sigma_px: float = 0.0
    tof_sigma_m: float = 0.0
    margin: DeadMargin | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            msg = f'sensor kind must be one of {KINDS}, got {self.kind!r}'
            raise ValueError(msg)


SENSORS: dict[str, SensorModel] = {m.name: m for m in (
    SensorModel('kinect_v1', 'structured_light', KINECT_640, 0.4, 8.0,
                margin=_PRIMESENSE_MARGIN),
    SensorModel('xtion', 'structured_light', Intrinsics(570.3, 570.3, 319.5, 239.5, 640, 480),
                0.4, 8.0, color_encoding='bgr8', margin=_PRIMESENSE_MARGIN),
    SensorModel('azure_nfov', 'tof', Intrinsics(504.0, 504.0, 319.5, 287.5, 640, 576), 0.5,
                3.86, color_encoding='bgr8', tof_sigma_m=0.0012, margin=_AZURE_NFOV_MARGIN),
    SensorModel('kinect_v2', 'tof', Intrinsics(365.5, 365.5, 255.5, 211.5, 512, 424), 0.5,
                4.5, color_encoding='bgr8', tof_sigma_m=0.0015, margin=_KINECT_V2_MARGIN),
    SensorModel('d435', 'stereo', Intrinsics(606.0, 606.0, 423.5, 239.5, 848, 480), 0.3, 8.0,
                baseline_m=0.050, disparity_sigma_px=0.08, margin=_REALSENSE_MARGIN),
    SensorModel('d455', 'stereo', Intrinsics(640.0, 640.0, 639.5, 359.5, 1280, 720), 0.4,
                8.0, baseline_m=0.095, disparity_sigma_px=0.08, margin=_REALSENSE_MARGIN),
)}


def without_margin(model: SensorModel) -> SensorModel:
    """``model`` rendering every pixel (the twin of a bag without dead margins)."""
    return replace(model, margin=None)


def sensor_depth(ren: Rendered, model: SensorModel,
                 rng: np.random.Generator) -> npt.NDArray[np.float32]:
    """Noisy registered depth (H, W) float32 m, NaN = no reading, of ``ren`` seen by ``model``,
    its dead margins included. The margins are applied last and draw nothing, so a twin
    without them (``without_margin``) has the same readings everywhere else."""
    if (ren.z.shape[1], ren.z.shape[0]) != (model.intrinsics.width, model.intrinsics.height):
        msg = (f'render is {ren.z.shape[1]}x{ren.z.shape[0]} but sensor {model.name!r} is '
               f'{model.intrinsics.width}x{model.intrinsics.height}')
        raise ValueError(msg)
    if model.kind == 'structured_light':
        out = structured_light.depth_image(ren, rng)
        out[(out < model.z_min) | (out > model.z_max)] = np.nan
    elif model.kind == 'tof':
        out = tof_depth(ren, model, rng)
    else:
        out = stereo_depth(ren, model, rng)
    if model.margin is not None:
        out[_margin_mask(model.margin, model.intrinsics.width, model.intrinsics.height)] = np.nan
    return out


def _edges(z: npt.NDArray[np.float32], rel: float = 0.04, floor: float = 0.08
           ) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """3x3 neighbourhood (min, max) of ``z`` and the masks of pixels with a much nearer
    neighbour (far side of a depth edge) and a much farther one (near side)."""
    kernel = np.ones((3, 3), np.uint8)
    zmin, zmax = cv2.erode(z, kernel), cv2.dilate(z, kernel)
    thr = np.maximum(np.float32(floor), np.float32(rel) * zmin)
    return zmin, zmax, (z - zmin) > thr, (zmax - z) > thr


def _cos_incidence(ren: Rendered) -> npt.NDArray[np.float32]:
    view = background(ren.camera).view
    return np.abs(np.einsum('ijk,ijk->ij', ren.normal, view)).astype(np.float32, copy=False)


def tof_depth(ren: Rendered, model: SensorModel,
              rng: np.random.Generator) -> npt.NDArray[np.float32]:
    """Time-of-flight depth (see the module docstring)."""
    finite = np.isfinite(ren.z)
    z = np.where(finite, ren.z, 50.0).astype(np.float32)
    h, w = z.shape
    # Multipath: concave neighbourhoods (the pixel is farther than its 15x15 surroundings, e.g.
    # the floor next to a foot, a wall corner) read up to 3 cm farther.
    blur = cv2.blur(np.minimum(z, np.float32(model.z_max + 1.0)), (15, 15))
    out = z + np.clip(np.float32(0.35) * (z - blur), 0.0, 0.03).astype(np.float32)
    # Flying pixels: edge pixels on both sides mix the near and far returns; a second ring
    # outside the first on the far side mixes with a lower weight.
    zmin, zmax, far, near = _edges(z)
    ev, eu = np.nonzero(far | near)
    fly = rng.random(len(ev)) < 0.75
    mix = rng.uniform(0.1, 0.9, int(fly.sum())).astype(np.float32)
    out[ev[fly], eu[fly]] = zmin[ev[fly], eu[fly]] + mix * (zmax - zmin)[ev[fly], eu[fly]]
    ring = cv2.dilate(far.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & ~(far | near)
    zmin5 = cv2.erode(z, np.ones((5, 5), np.uint8))
    rv, ru = np.nonzero(ring & ((z - zmin5) > np.maximum(0.08, 0.04 * zmin5)))
    pick = rng.random(len(rv)) < 0.3
    rv, ru = rv[pick], ru[pick]
    out[rv, ru] = z[rv, ru] - rng.uniform(0.05, 0.35, len(rv)).astype(np.float32) * (
        z[rv, ru] - zmin5[rv, ru])
    # Amplitude: albedo (luminance of the shaded colour) x incidence / z^2.
    lum = ren.color @ np.array([0.3, 0.55, 0.15], np.float32)
    cos_inc = _cos_incidence(ren)
    amp = lum * np.maximum(cos_inc, 0.05) / np.maximum(z, 0.3) ** 2 * np.float32(4.0)
    sigma = np.float32(model.tof_sigma_m) * z / np.sqrt(np.maximum(amp, 0.02))
    out += structured_light._noise((h, w), rng) * sigma
    p_drop = np.clip((0.08 - amp) / 0.06, 0.0, 1.0)  # weak returns: dark, far or grazing
    missing = ~finite | (rng.random((h, w), dtype=np.float32) < p_drop)
    missing |= cos_inc < np.float32(np.cos(np.deg2rad(85.0)))
    missing |= (out < model.z_min) | (out > model.z_max)
    out[missing] = np.nan
    return out


def stereo_depth(ren: Rendered, model: SensorModel,
                 rng: np.random.Generator) -> npt.NDArray[np.float32]:
    """Active-stereo depth (see the module docstring)."""
    finite = np.isfinite(ren.z)
    h, w = ren.z.shape
    fb = np.float32(model.intrinsics.fx * model.baseline_m)
    disp = np.where(finite, fb / np.maximum(ren.z, 1e-3), 0.0).astype(np.float32)
    # Second imager to the right: a pixel is hidden from it when a nearer surface within the
    # next pixels to the right has a disparity that exceeds the pixel's own by more than its
    # distance (the occlusion shadow left of every near edge).
    # reach_m(u) = max over k = 1..m of disp(u + k) - k, doubled in log2(span) steps:
    # reach_2m(u) = max(reach_m(u), reach_m(u + m) - m).
    reach = np.full((h, w), -np.inf, np.float32)
    reach[:, :-1] = disp[:, 1:] - np.float32(1.0)
    span = int(min(np.ceil(disp.max() - disp[finite].min()), 128)) if finite.any() else 0
    m = 1
    while m < span:  # numpy buffers the overlapping operands of the in-place maximum
        np.maximum(reach[:, :-m], reach[:, m:] - np.float32(m), out=reach[:, :-m])
        m *= 2
    occluded = reach > disp + np.float32(0.5)
    # Block matching fattens the foreground: background pixels next to a much nearer one take
    # its disparity (half of them, within 2 px).
    dil = cv2.dilate(disp, np.ones((5, 5), np.uint8))
    coin = rng.random((h, w), dtype=np.float32)
    fat = (dil > disp * np.float32(1.08) + np.float32(0.5)) & (coin < 0.5)
    d = np.where(fat, dil, disp)
    # Sub-pixel noise, independent plus correlated (speckle pattern of the projector).
    small = structured_light._noise((h // 8 + 2, w // 8 + 2), rng)
    corr = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    d = d + np.float32(model.disparity_sigma_px) * (
        structured_light._noise((h, w), rng) + np.float32(0.8) * corr)
    out = (fb / np.maximum(d, np.float32(1e-3))).astype(np.float32)
    # Invalid: no surface, occluded, grazing, low texture on weak returns, small blobs.
    cos_inc = _cos_incidence(ren)
    lum = ren.color @ np.array([0.3, 0.55, 0.15], np.float32)
    weak = (lum < 0.12) & (coin >= 0.5)  # the other half of the same draw as ``fat``
    missing = ~finite | occluded | (cos_inc < np.float32(np.cos(np.deg2rad(80.0)))) | weak
    n_blobs = rng.poisson(3e-4 * h * w)
    bv, bu = rng.integers(0, h, n_blobs), rng.integers(0, w, n_blobs)
    for dv in (0, 1):
        for du in (0, 1):
            missing[np.minimum(bv + dv, h - 1), np.minimum(bu + du, w - 1)] = True
    missing |= (out < model.z_min) | (out > model.z_max)
    out[missing] = np.nan
    return out
