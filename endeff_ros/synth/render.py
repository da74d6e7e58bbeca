"""Ideal (noise-free) rendering: ray casting of capsules, ellipsoids and boxes with a z-buffer,
in front of a textured floor plane and back wall, seen by a pinhole camera.

Each primitive is intersected only with the rays of its projected bounding box, vectorised in
numpy. Rays are (u - cx) / fx, (v - cy) / fy, 1), so a ray parameter is directly the depth z.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from ..core.types import KINECT_640, Intrinsics
from .body import Entity
from .shapes import Primitive, Vec, rot_y

FLOOR, WALL, NOTHING, STATIC = -2, -3, -1, -4
HAIR = np.array([0.25, 0.16, 0.08])


@dataclass(frozen=True)
class Camera:
    """The virtual RGB-D camera: ``height`` (m) above the floor at the scene-frame origin,
    looking along -z of the scene frame turned by ``yaw`` (rad, about the vertical axis through
    the camera; positive turns the view to the left, towards -x), pitched down by ``pitch``
    (rad, any value in (-pi/2, pi/2)) and then rolled by ``roll`` (rad, about the optical axis;
    positive turns the image content clockwise). The back wall is the plane z = ``wall_z`` of
    the scene. ``yaw`` is what a panning camera changes from frame to frame."""

    intrinsics: Intrinsics
    height: float = 1.15
    pitch: float = np.deg2rad(5.0)
    frame_id: str = 'camera_color_optical_frame'
    wall_z: float = -5.5
    roll: float = 0.0
    yaw: float = 0.0

    @property
    def rotation(self) -> Vec:
        """Rotation (3, 3) from scene-frame directions to optical-frame directions."""
        c, s = np.cos(self.pitch), np.sin(self.pitch)
        pitch = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
        rot = pitch @ np.diag([1.0, -1.0, -1.0])
        if self.roll:
            cr, sr = np.cos(self.roll), np.sin(self.roll)
            rot = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]]) @ rot
        if self.yaw:  # scene -> camera body (undo the yaw), then as above
            rot = rot @ rot_y(self.yaw).T
        return rot

    @property
    def position(self) -> Vec:
        return np.array([0.0, self.height, 0.0])

    def to_optical(self, points: npt.ArrayLike) -> Vec:
        """Scene-frame points (N, 3) -> optical-frame points (N, 3), m."""
        return (np.asarray(points, dtype=np.float64) - self.position) @ self.rotation.T


def default_camera() -> Camera:
    """640x480, fx = fy = 525, principal point at the image centre."""
    return Camera(KINECT_640)


@lru_cache(maxsize=8)
def rays(intr: Intrinsics) -> Vec:
    """Per-pixel ray directions (H, W, 3) with z = 1, float64."""
    u = (np.arange(intr.width) - intr.cx) / intr.fx
    v = (np.arange(intr.height) - intr.cy) / intr.fy
    d = np.empty((intr.height, intr.width, 3))
    d[..., 0] = u[None, :]
    d[..., 1] = v[:, None]
    d[..., 2] = 1.0
    d.flags.writeable = False
    return d


@dataclass
class Rendered:
    """An ideal view: ``z`` (H, W) float64 depth in m (inf = no surface), ``normal`` (H, W, 3)
    float32 unit normals (optical frame), ``owner`` (H, W) int16 primitive index or FLOOR/WALL,
    ``color`` (H, W, 3) float32 RGB in [0, 1], ``gt`` (M, 3) ground truth in the optical frame,
    ``gt_visible`` (M,) whether the end-effector's own part is seen at its projection."""

    z: Vec
    normal: npt.NDArray[np.float32]
    owner: npt.NDArray[np.int16]
    color: npt.NDArray[np.float32]
    gt: Vec
    gt_visible: npt.NDArray[np.bool_]
    prims: list[Primitive]
    camera: Camera


def _aabb_half(p: Primitive) -> Vec:
    if p.kind == 'ellipsoid':
        return np.sqrt(((p.rot * p.size) ** 2).sum(1))
    if p.kind == 'box':
        return (np.abs(p.rot) * p.size).sum(1)
    axis = np.abs(p.rot[:, 1]) * p.size[1]
    return axis + p.size[0]


def _bbox(p: Primitive, intr: Intrinsics) -> tuple[int, int, int, int] | None:
    """Pixel box (v0, v1, u0, u1) (exclusive ends) that contains the primitive's image."""
    half = _aabb_half(p)
    lo, hi = p.center - half, p.center + half
    if hi[2] <= 0.05:
        return None
    if lo[2] <= 0.05:
        return 0, intr.height, 0, intr.width
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    u = intr.fx * corners[:, 0] / corners[:, 2] + intr.cx
    v = intr.fy * corners[:, 1] / corners[:, 2] + intr.cy
    u0, u1 = max(0, int(np.floor(u.min()))), min(intr.width, int(np.ceil(u.max())) + 1)
    v0, v1 = max(0, int(np.floor(v.min()))), min(intr.height, int(np.ceil(v.max())) + 1)
    if u0 >= u1 or v0 >= v1:
        return None
    return v0, v1, u0, u1


def intersect(p: Primitive, d: Vec) -> Vec:
    """Depth (N,) of the first hit of rays ``d`` (N, 3) (z = 1, from the origin); inf = miss."""
    t = np.full(d.shape[0], np.inf)
    if p.kind == 'ellipsoid':
        o = (-p.center @ p.rot) / p.size
        dl = (d @ p.rot) / p.size
        a = (dl * dl).sum(1)
        b = dl @ o
        c = o @ o - 1.0
        h = b * b - a * c
        ok = h >= 0
        tt = (-b[ok] - np.sqrt(h[ok])) / a[ok]
        t[ok] = np.where(tt > 0, tt, np.inf)
        return t
    if p.kind == 'box':
        o = -p.center @ p.rot
        dl = d @ p.rot
        dl = np.where(np.abs(dl) < 1e-12, 1e-12, dl)
        inv = 1.0 / dl
        t1 = (-p.size - o) * inv
        t2 = (p.size - o) * inv
        tn = np.minimum(t1, t2).max(1)
        tf = np.maximum(t1, t2).min(1)
        ok = (tn <= tf) & (tn > 0)
        t[ok] = tn[ok]
        return t
    # Capsule (after Inigo Quilez), for non-normalised ray directions.
    r, half = p.size[0], p.size[1]
    axis = p.rot[:, 1]
    pa = p.center - half * axis
    ba = 2 * half * axis
    oa = -pa
    baba = ba @ ba
    rdrd = (d * d).sum(1)
    bard = d @ ba
    baoa = ba @ oa
    rdoa = d @ oa
    oaoa = oa @ oa
    a = baba * rdrd - bard * bard
    b = baba * rdoa - baoa * bard
    c = baba * oaoa - baoa * baoa - r * r * baba
    h = b * b - a * c
    ok = (h >= 0) & (a > 1e-12)
    tc = np.full_like(h, np.inf)
    tc[ok] = (-b[ok] - np.sqrt(h[ok])) / a[ok]
    y = baoa + tc * bard
    body = ok & (y > 0) & (y < baba)
    t[body] = tc[body]
    caps = (h >= 0) & ~body
    if caps.any():
        dc = d[caps]
        oc = np.where((y[caps] <= 0)[:, None], oa, -(pa + ba))
        bb = (dc * oc).sum(1)
        cc = (oc * oc).sum(1) - r * r
        hh = bb * bb - rdrd[caps] * cc
        ts = np.where(hh >= 0, (-bb - np.sqrt(np.maximum(hh, 0))) / rdrd[caps], np.inf)
        t[caps] = np.where(ts > 0, ts, np.inf)
    return t


def normals(p: Primitive, pts: Vec) -> Vec:
    """Outward unit normals (K, 3) of ``p`` at surface points ``pts`` (K, 3)."""
    q = (pts - p.center) @ p.rot
    if p.kind == 'ellipsoid':
        n = (q / (p.size * p.size)) @ p.rot.T
    elif p.kind == 'box':
        k = np.argmax(np.abs(q) / p.size, axis=1)
        nl = np.zeros_like(q)
        nl[np.arange(len(q)), k] = np.sign(q[np.arange(len(q)), k])
        n = nl @ p.rot.T
    else:
        q[:, 1] -= np.clip(q[:, 1], -p.size[1], p.size[1])
        n = q @ p.rot.T
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def _hash(k: Vec) -> Vec:
    return np.modf(np.abs(np.sin(k * 12.9898 + 78.233) * 43758.5453))[0]


@lru_cache(maxsize=4096)
def _texture_params(texture: int, color: tuple[float, float, float]) -> tuple:
    rng = np.random.default_rng(texture)
    base = np.asarray(color)
    alt = np.clip(0.4 * base + rng.uniform(0.15, 0.6, 3), 0, 1)
    cell = rng.uniform(0.035, 0.055)
    k = rng.normal(size=3)
    k /= np.linalg.norm(k) * rng.uniform(0.05, 0.09)
    return base, alt, cell, k, rng.uniform(0, 6)


def _body_texture(p: Primitive, q: Vec) -> Vec:
    """RGB (K, 3) in [0, 1] of part ``p`` at local coordinates ``q`` (K, 3) m: a checker of
    4-5 cm cells and oblique stripes in the part's own frame, so the texture moves with it."""
    base, alt, cell, k, phase = _texture_params(p.texture, tuple(p.color))
    chk = (np.floor(q / cell).sum(1) % 2).astype(np.float64)
    stripe = 0.5 + 0.5 * np.sin(2 * np.pi * (q @ k) + phase)
    mix = (0.45 * stripe)[:, None]
    rgb = (base * (1 - mix) + alt * mix) * (0.68 + 0.32 * chk)[:, None]
    if p.part == 'head':  # hair on the top and back of the head
        hair = (q[:, 1] > 0.045) | ((q[:, 2] < -0.02) & (q[:, 1] > -0.07))
        rgb[hair] = HAIR * (0.8 + 0.4 * stripe[hair, None])
    return rgb


def _floor_texture(pf: Vec) -> Vec:
    x, z = pf[:, 0], pf[:, 2]
    plank = np.floor(x / 0.2)
    grain = 0.9 + 0.1 * np.sin(2 * np.pi * z / 0.13 + plank * 1.7)
    tone = (0.8 + 0.2 * _hash(plank)) * grain
    seam = (np.abs(x - 0.2 * np.round(x / 0.2)) < 0.006) | (
        np.abs(z - 1.2 * np.round((z + 0.6 * plank) / 1.2) + 0.6 * plank) < 0.006)
    tone = np.where(seam, 0.45, tone)
    return np.array([0.60, 0.45, 0.30]) * tone[:, None]


def _wall_texture(pf: Vec) -> Vec:
    x, y = pf[:, 0], pf[:, 1]
    row = np.floor(y / 0.1)
    xs = x + 0.125 * (row % 2)
    col = np.floor(xs / 0.25)
    tone = 0.8 + 0.2 * _hash(row * 31.0 + col)
    mortar = ((y - 0.1 * row) < 0.012) | ((xs - 0.25 * col) < 0.012)
    rgb = np.array([0.78, 0.52, 0.42]) * tone[:, None]
    return np.where(mortar[:, None], np.array([0.85, 0.84, 0.80]), rgb)


@dataclass(frozen=True)
class Background:
    """The static part of every view (floor and wall): ``z`` (H, W) float64 depth,
    ``owner`` (H, W) int16, ``normal`` (H, W, 3) float32, ``color`` (H, W, 3) float32 shaded,
    ``view`` (H, W, 3) float32 unit vectors from the surface to the camera."""

    z: Vec
    owner: npt.NDArray[np.int16]
    normal: npt.NDArray[np.float32]
    color: npt.NDArray[np.float32]
    view: npt.NDArray[np.float32]
    light: Vec


@lru_cache(maxsize=4)
def background(cam: Camera) -> Background:
    """Floor (scene y = 0) and back wall (scene z = ``cam.wall_z``) as seen by ``cam``."""
    intr = cam.intrinsics
    h_img, w_img = intr.height, intr.width
    flat = rays(intr).reshape(-1, 3)
    rc = cam.rotation
    trans = -rc @ cam.position
    n_floor = rc @ np.array([0.0, 1.0, 0.0])
    n_wall = rc @ np.array([0.0, 0.0, 1.0])
    p_wall = rc @ np.array([0.0, 0.0, cam.wall_z]) + trans
    with np.errstate(divide='ignore', invalid='ignore'):
        tf = (trans @ n_floor) / (flat @ n_floor)
        tw = (p_wall @ n_wall) / (flat @ n_wall)
    tf = np.where(tf > 0, tf, np.inf)
    tw = np.where(tw > 0, tw, np.inf)
    z = np.minimum(tf, tw)
    owner = np.where(tf <= tw, FLOOR, WALL).astype(np.int16)
    owner[~np.isfinite(z)] = NOTHING
    nrm = np.where((owner == FLOOR)[:, None], n_floor, n_wall).astype(np.float32)
    albedo = np.zeros((flat.shape[0], 3))
    for code, tex in ((FLOOR, _floor_texture), (WALL, _wall_texture)):
        m = owner == code
        albedo[m] = tex((flat[m] * z[m][:, None]) @ rc + cam.position)
    view = -flat / np.linalg.norm(flat, axis=1, keepdims=True)
    light = rc @ np.array([-0.4, 1.0, 0.7])
    light /= np.linalg.norm(light)
    color = albedo * _shading(nrm, view, light)[:, None]
    shape = (h_img, w_img)
    out = Background(z.reshape(shape), owner.reshape(shape), nrm.reshape(shape + (3,)),
                     color.astype(np.float32).reshape(shape + (3,)),
                     view.astype(np.float32).reshape(shape + (3,)), light)
    for a in (out.z, out.owner, out.normal, out.color, out.view):
        a.flags.writeable = False
    return out


def _shading(nrm: npt.ArrayLike, view: npt.ArrayLike, light: Vec) -> Vec:
    """Ambient + Lambert (directional light) + head-light shading factor (K,)."""
    nrm = np.asarray(nrm)
    lam = np.clip(nrm @ light, 0, None)
    head = np.clip((nrm * np.asarray(view)).sum(-1), 0, None)
    return 0.28 + 0.5 * lam + 0.3 * head


def static_layer(static: Entity, cam: Camera) -> Background:
    """Floor, wall and the static entity ``static`` (furniture) rendered once, for ``render``'s
    ``bg`` argument: a scene whose furniture does not move pays for it once, not per frame.
    Furniture pixels are owned by ``STATIC`` (no primitive index, hence never ground truth)."""
    ren = render(static, cam)
    owner = np.where(ren.owner >= 0, np.int16(STATIC), ren.owner).astype(np.int16)
    bg = background(cam)
    out = Background(ren.z, owner, ren.normal, ren.color, bg.view, bg.light)
    for a in (out.z, out.owner, out.normal, out.color):
        a.flags.writeable = False
    return out


def render(entity: Entity, cam: Camera, bg: Background | None = None) -> Rendered:
    """Ray-cast ``entity`` (scene frame) plus floor and wall into an ideal RGB-D view.

    ``bg``: the static part of the view (default ``background(cam)``; ``static_layer`` adds
    furniture).
    """
    intr = cam.intrinsics
    d_all = rays(intr)
    bg = background(cam) if bg is None else bg
    rc = cam.rotation
    trans = -rc @ cam.position
    prims = [p.transformed(rc, trans) for p in entity.prims]
    zbuf = bg.z.copy()
    owner = bg.owner.copy()
    nrm = bg.normal.copy()

    boxes: list[tuple[int, int, int, int] | None] = []
    for i, p in enumerate(prims):
        bb = _bbox(p, intr)
        boxes.append(bb)
        if bb is None:
            continue
        v0, v1, u0, u1 = bb
        d = d_all[v0:v1, u0:u1].reshape(-1, 3)
        t = intersect(p, d)
        zs = zbuf[v0:v1, u0:u1]
        upd = t.reshape(zs.shape) < zs
        if not upd.any():
            continue
        tu = t.reshape(zs.shape)[upd]
        zs[upd] = tu
        owner[v0:v1, u0:u1][upd] = i
        pts = d.reshape(zs.shape + (3,))[upd] * tu[:, None]
        nrm[v0:v1, u0:u1][upd] = normals(p, pts)

    color = bg.color.copy()
    for i, p in enumerate(prims):
        bb = boxes[i]
        if bb is None:
            continue
        v0, v1, u0, u1 = bb
        m = owner[v0:v1, u0:u1] == i
        if not m.any():
            continue
        pts = d_all[v0:v1, u0:u1][m] * zbuf[v0:v1, u0:u1][m][:, None]
        alb = _body_texture(p, (pts - p.center) @ p.rot)
        sh = _shading(nrm[v0:v1, u0:u1][m], bg.view[v0:v1, u0:u1][m], bg.light)
        color[v0:v1, u0:u1][m] = np.clip(alb * sh[:, None], 0, 1)
    gt_cam = cam.to_optical(entity.gt)
    vis = _visible(gt_cam, entity.gt_prims, owner, intr)
    return Rendered(zbuf, nrm, owner, color, gt_cam, vis, prims, cam)


def _visible(gt_cam: Vec, gt_prims: npt.NDArray[np.int64], owner: npt.NDArray[np.int16],
             intr: Intrinsics) -> npt.NDArray[np.bool_]:
    """Whether the part of each end-effector is what the camera sees at (or 1 px around) its
    projection."""
    vis = np.zeros(len(gt_cam), bool)
    uv = intr.project(gt_cam)
    for k, ((u, v), pi) in enumerate(zip(uv, gt_prims)):
        if gt_cam[k, 2] <= 0:
            continue
        ui, vi = int(round(u)), int(round(v))
        if not (0 <= ui < intr.width and 0 <= vi < intr.height):
            continue
        win = owner[max(0, vi - 1):vi + 2, max(0, ui - 1):ui + 2]
        vis[k] = bool((win == pi).any())
    return vis
