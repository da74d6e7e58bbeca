"""Kinect-like sensor model: turns an ideal render into a realistic depth and colour image.

Depth (all vectorised over the image):

- missing pixels where the surface is grazing (angle between normal and view ray above
  ``GRAZING_HARD``; randomly, increasingly, from ``GRAZING_SOFT``), in a 1 px band along depth
  silhouettes (mostly on the far side, as the projector's shadow) and in small random holes;
- flying pixels (depth interpolated between the near and far surface) at depth discontinuities;
- Gaussian noise with sigma = ``NOISE_K`` * z^2 and disparity quantisation (1/z in steps of
  ``QUANT_K``, i.e. a depth step of ``QUANT_K`` * z^2);
- readings only between ``Z_MIN`` and ``Z_MAX``.

Colour: mild blur and Gaussian noise (sigma 2 levels) on the shaded, textured render.

Gaussian noise comes from a fixed bank of normal samples read at a random offset per frame
(cheap, and still deterministic from the frame's random generator).
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

from .render import Rendered, background

NOISE_K = 1.5e-3  # sigma_z = NOISE_K * z^2 (m)
QUANT_K = 2.85e-3  # depth step = QUANT_K * z^2 (m)
GRAZING_SOFT = np.deg2rad(72.0)
GRAZING_HARD = np.deg2rad(82.0)
FLYING_RATE = 0.22  # fraction of silhouette pixels that become flying pixels
HOLE_RATE = 4e-4  # random 3x3 holes per pixel
Z_MIN, Z_MAX = 0.4, 8.0
_BANK_PAD = 64


@lru_cache(maxsize=8)
def _normal_bank(shape: tuple[int, ...]) -> npt.NDArray[np.float32]:
    """Standard normal samples of ``shape`` plus a margin in the first two axes."""
    rng = np.random.default_rng(20160529)
    full = (shape[0] + _BANK_PAD, shape[1] + _BANK_PAD) + shape[2:]
    bank = rng.standard_normal(full, dtype=np.float32)
    bank.flags.writeable = False
    return bank


def _noise(shape: tuple[int, ...], rng: np.random.Generator) -> npt.NDArray[np.float32]:
    bank = _normal_bank(shape)
    dy, dx = (int(v) for v in rng.integers(0, _BANK_PAD, 2))
    sign = np.float32(1.0 if rng.random() < 0.5 else -1.0)
    return bank[dy:dy + shape[0], dx:dx + shape[1]] * sign


def depth_image(ren: Rendered, rng: np.random.Generator) -> npt.NDArray[np.float32]:
    """Noisy depth (H, W) float32 in metres, NaN = no reading, from an ideal render."""
    z = ren.z.astype(np.float32)
    h, w = z.shape
    finite = np.isfinite(z)
    z_f = np.where(finite, z, np.float32(50.0))
    kernel = np.ones((3, 3), np.uint8)
    zmax = cv2.dilate(z_f, kernel)
    zmin = cv2.erode(z_f, kernel)
    thr = np.maximum(np.float32(0.08), np.float32(0.04) * zmin)
    far_side = (z_f - zmin) > thr   # has a much nearer neighbour: background at a silhouette
    near_side = (zmax - z_f) > thr  # foreground at a silhouette
    ev, eu = np.nonzero(far_side | near_side)
    r = rng.random(len(ev))
    fly = r < FLYING_RATE
    mix = rng.uniform(0.15, 0.85, size=int(fly.sum())).astype(np.float32)
    out = z_f.copy()
    fv, fu = ev[fly], eu[fly]
    out[fv, fu] = zmin[fv, fu] + mix * (zmax[fv, fu] - zmin[fv, fu])
    # Silhouette band: far side (projector shadow) mostly, near side sometimes.
    keep = ~fly
    ev, eu, r2 = ev[keep], eu[keep], rng.random(int(keep.sum()))
    drop_edge = np.where(far_side[ev, eu], r2 < 0.85, r2 < 0.3)

    # Noise, then disparity quantisation.
    out += _noise((h, w), rng) * (np.float32(NOISE_K) * out * out)
    step = np.float32(QUANT_K)
    out = np.float32(1.0) / (np.round((np.float32(1.0) / np.maximum(out, 1e-3)) / step) * step)

    # Missing readings: no surface, grazing angles, silhouettes, random holes, range.
    view = background(ren.camera).view
    cos_inc = np.abs((ren.normal * view).sum(2))
    missing = ~finite | (cos_inc < np.float32(np.cos(GRAZING_HARD)))
    gv, gu = np.nonzero((cos_inc < np.float32(np.cos(GRAZING_SOFT))) & ~missing)
    ang = np.arccos(np.clip(cos_inc[gv, gu], 0.0, 1.0))
    p = (ang - GRAZING_SOFT) / (GRAZING_HARD - GRAZING_SOFT) * 0.6
    g = rng.random(len(gv)) < p
    missing[gv[g], gu[g]] = True
    missing[ev[drop_edge], eu[drop_edge]] = True
    n_holes = rng.poisson(HOLE_RATE * h * w)
    hv, hu = rng.integers(0, h, n_holes), rng.integers(0, w, n_holes)
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            missing[np.clip(hv + dv, 0, h - 1), np.clip(hu + du, 0, w - 1)] = True
    missing |= (out < Z_MIN) | (out > Z_MAX)
    out[missing] = np.nan
    return out


def color_image(ren: Rendered, rng: np.random.Generator) -> npt.NDArray[np.uint8]:
    """Colour (H, W, 3) uint8 RGB: the render slightly blurred plus Gaussian noise."""
    c = cv2.GaussianBlur(ren.color, (3, 3), 0.6)
    c = c * np.float32(255.0) + _noise(c.shape, rng) * np.float32(2.0) + np.float32(0.5)
    return np.clip(c, 0, 255).astype(np.uint8)


def depth_to_mm(depth: npt.NDArray[np.float32]) -> npt.NDArray[np.uint16]:
    """Metres with NaN -> 16UC1 millimetres with 0 = no reading."""
    mm = np.where(np.isfinite(depth), np.round(depth * np.float32(1000.0)), np.float32(0.0))
    return np.clip(mm, 0, 65535).astype(np.uint16)
