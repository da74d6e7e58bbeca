"""Solid primitives (capsule, ellipsoid, box), rotation helpers and surface distances.

A primitive is posed by a centre (3,) and a rotation (3, 3) whose columns are its local axes,
both in metres in whatever frame it was built in (the scene frame of ``body.py`` or the camera's
optical frame after ``Primitive.transformed``). ``size`` (3,) holds, per kind:

- ``capsule``: (radius, half length of the axis segment, radius); the axis is local y;
- ``ellipsoid``: the three semi-axes along local x, y, z;
- ``box``: the three half extents along local x, y, z.

The local frame also carries the surface texture, so the texture moves with the part.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

Vec = npt.NDArray[np.float64]


def rot_x(a: float) -> Vec:
    """Rotation (3, 3) by ``a`` rad about x (right-handed)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> Vec:
    """Rotation (3, 3) by ``a`` rad about y (right-handed)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> Vec:
    """Rotation (3, 3) by ``a`` rad about z (right-handed)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def unit(v: npt.ArrayLike) -> Vec:
    """``v`` (3,) scaled to length 1."""
    v = np.asarray(v, dtype=np.float64)
    return v / max(float(np.linalg.norm(v)), 1e-12)


def frame_from_axis(axis: npt.ArrayLike, hint: npt.ArrayLike) -> Vec:
    """Proper rotation (3, 3) whose column 1 is ``axis`` and column 0 lies towards ``hint``."""
    e1 = unit(axis)
    h = np.asarray(hint, dtype=np.float64)
    e0 = h - np.dot(h, e1) * e1
    if np.linalg.norm(e0) < 1e-6:
        alt = np.array([1.0, 0.0, 0.0]) if abs(e1[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
        e0 = alt - np.dot(alt, e1) * e1
    e0 = unit(e0)
    return np.stack([e0, e1, np.cross(e0, e1)], axis=1)


@dataclass(frozen=True)
class Primitive:
    """One rigid solid of an entity (see the module docstring for ``kind`` and ``size``).

    ``color`` is the base RGB in [0, 1]; ``texture`` selects the procedural pattern variant;
    ``part`` names the body part (e.g. ``'l_hand'``).
    """

    kind: str
    center: Vec
    rot: Vec
    size: Vec
    color: tuple[float, float, float]
    texture: int
    part: str

    def transformed(self, rot: Vec, trans: Vec) -> Primitive:
        """This primitive moved by ``p -> rot @ p + trans``."""
        return Primitive(self.kind, rot @ self.center + trans, rot @ self.rot, self.size,
                         self.color, self.texture, self.part)

    @property
    def bound_radius(self) -> float:
        """Radius (m) of a sphere about ``center`` that contains the solid."""
        if self.kind == 'capsule':
            return float(self.size[0] + self.size[1])
        if self.kind == 'ellipsoid':
            return float(np.max(self.size))
        return float(np.linalg.norm(self.size))

    def surface_points(self, n: int = 400) -> Vec:
        """About ``n`` points (K, 3) spread over the surface, for distance checks."""
        rng = np.random.default_rng(12345)
        d = _sphere_dirs(n)
        if self.kind == 'ellipsoid':
            local = d * self.size
        elif self.kind == 'capsule':
            r, h = float(self.size[0]), float(self.size[1])
            local = d * r
            local[:, 1] += np.where(d[:, 1] >= 0, h, -h)
            m = n // 2
            ang = rng.uniform(0, 2 * np.pi, m)
            side = np.stack([r * np.cos(ang), rng.uniform(-h, h, m), r * np.sin(ang)], 1)
            local = np.concatenate([local, side])
        else:
            # Project random directions onto the box surface (max-norm scaling).
            s = d / self.size
            local = d / np.max(np.abs(s), axis=1, keepdims=True)
        return local @ self.rot.T + self.center


@lru_cache(maxsize=8)
def _sphere_dirs(n: int) -> Vec:
    """``n`` unit vectors (n, 3) spread evenly (Fibonacci sphere)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5**0.5) * k
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


def surface_distance(a: Primitive, b: Primitive, n: int = 600) -> float:
    """Approximate gap (m) between the surfaces of ``a`` and ``b`` (0 when they overlap).

    Sampled: accurate to about a centimetre for the body-part sizes used here.
    """
    from scipy.spatial import cKDTree

    pa, pb = a.surface_points(n), b.surface_points(n)
    if _inside(b, pa).any() or _inside(a, pb).any():
        return 0.0
    return float(cKDTree(pb).query(pa, k=1)[0].min())


def _inside(p: Primitive, pts: Vec) -> npt.NDArray[np.bool_]:
    """Which of ``pts`` (K, 3) lie inside the solid ``p``."""
    q = (pts - p.center) @ p.rot
    if p.kind == 'ellipsoid':
        return ((q / p.size) ** 2).sum(1) < 1.0
    if p.kind == 'box':
        return (np.abs(q) < p.size).all(1)
    r, h = p.size[0], p.size[1]
    y = np.clip(q[:, 1], -h, h)
    return (q[:, 0] ** 2 + (q[:, 1] - y) ** 2 + q[:, 2] ** 2) < r * r


def capsule(a: npt.ArrayLike, b: npt.ArrayLike, radius: float, hint: npt.ArrayLike,
            color: tuple[float, float, float], texture: int, part: str) -> Primitive:
    """Capsule from ``a`` to ``b`` (3,) of ``radius`` m; ``hint`` orients the texture."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    axis = b - a
    half = 0.5 * float(np.linalg.norm(axis))
    rot = frame_from_axis(axis if half > 1e-9 else [0.0, 1.0, 0.0], hint)
    return Primitive('capsule', 0.5 * (a + b), rot, np.array([radius, half, radius]), color,
                     texture, part)


def ellipsoid(center: npt.ArrayLike, rot: Vec, radii: npt.ArrayLike,
              color: tuple[float, float, float], texture: int, part: str) -> Primitive:
    """Ellipsoid with semi-axes ``radii`` (3,) m along the columns of ``rot``."""
    return Primitive('ellipsoid', np.asarray(center, dtype=np.float64), np.asarray(rot),
                     np.asarray(radii, dtype=np.float64), color, texture, part)


def box(center: npt.ArrayLike, rot: Vec, half: npt.ArrayLike,
        color: tuple[float, float, float], texture: int, part: str) -> Primitive:
    """Box with half extents ``half`` (3,) m along the columns of ``rot``."""
    return Primitive('box', np.asarray(center, dtype=np.float64), np.asarray(rot),
                     np.asarray(half, dtype=np.float64), color, texture, part)
