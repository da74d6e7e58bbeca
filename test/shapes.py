"""Synthetic shapes with known end-effectors for core tests, rendered to depth by a z-buffer.

Each shape is a list of primitives (capsules, boxes) in a *world* frame (x right, y up, z away
from the camera, metres, floor at y = 0). ``render`` samples their surfaces densely, moves
them into the optical frame of a camera at ``camera_height`` looking along +z, and keeps the
nearest sample per pixel, which gives a depth image with self-occlusion.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from endeff_ros.core.types import KINECT_640 as K640


@dataclass
class Scene:
    """Surface samples (world frame) with their outward unit normals, and the known tips."""

    samples: list[np.ndarray]
    tips: list[np.ndarray]
    normals: list[np.ndarray] = field(default_factory=list)  # one array per samples array

    def _add(self, points, normals):
        self.samples.append(points)
        self.normals.append(normals)

    def add_capsule(self, a, b, r, rng, density=2.5e5):
        """Surface samples of a capsule (segment ``a``-``b``, radius ``r``), uniform by area:
        the cylinder gets its share 2πrL and the two hemispherical caps theirs 4πr² (a short
        wide capsule such as the head is mostly caps)."""
        a, b = np.asarray(a, float), np.asarray(b, float)
        axis = b - a
        length = np.linalg.norm(axis)
        side, caps = 2 * np.pi * r * length, 4 * np.pi * r * r
        n = int((side + caps) * density)
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        if length == 0:
            self._add(a + r * d, d)
            return
        u = axis / length
        on_side = rng.random(n) < side / (side + caps)
        along = d @ u
        # Cylinder: any point of the segment, direction perpendicular to the axis; caps: the
        # hemisphere at a (directions pointing back along u) or at b.
        t = np.where(on_side, rng.random(n), (along > 0).astype(float))
        d[on_side] -= along[on_side, None] * u
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        self._add(a + t[:, None] * axis + r * d, d)

    def add_box(self, lo, hi, rng, density=2.5e5):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        size = hi - lo
        area = 2 * (size[0] * size[1] + size[1] * size[2] + size[0] * size[2])
        n = int(area * density)
        p = lo + rng.random((n, 3)) * size
        face = rng.integers(0, 6, n)
        axis = face % 3
        p[np.arange(n), axis] = np.where(face < 3, lo[axis], hi[axis])
        normals = np.zeros((n, 3))
        normals[np.arange(n), axis] = np.where(face < 3, -1.0, 1.0)
        self._add(p, normals)

    def add_floor(self, rng, density=6e4, z=(0.5, 4.5), x=(-2.5, 2.5)):
        n = int((z[1] - z[0]) * (x[1] - x[0]) * density)
        p = np.stack([rng.uniform(*x, n), np.zeros(n), rng.uniform(*z, n)], axis=1)
        self._add(p, np.tile([0.0, 1.0, 0.0], (n, 1)))

    def __add__(self, other):
        return Scene(self.samples + other.samples, self.tips + other.tips,
                     self.normals + other.normals)


def rotate_about_camera(scene, rotation, camera_height):
    """The scene moved by ``rotation`` about the optical centre (optical frame), i.e. the
    same scene seen by a camera turned by the inverse rotation."""

    def move(p):
        return to_optical(to_optical(p, camera_height) @ rotation.T, camera_height)

    def turn(n):  # directions: the y flip of to_optical without the offset
        return to_optical(to_optical(n, 0.0) @ rotation.T, 0.0)

    return Scene([move(s) for s in scene.samples], [move(t)[0] for t in scene.tips],
                 [turn(n) for n in scene.normals])


def to_optical(p_world, camera_height):
    """World (y up, floor y=0) -> optical frame (y down) of a camera at ``camera_height``."""
    p = np.asarray(p_world, float).reshape(-1, 3)
    return np.stack([p[:, 0], camera_height - p[:, 1], p[:, 2]], axis=1)


def render(scene: Scene, *, camera_height=1.1, intrinsics=K640, noise=0.0, seed=0):
    """Z-buffer the scene samples into a float32 depth image (NaN = no reading). Samples on
    surfaces facing away from the camera are dropped first (back-face culling), so a sparse
    front never lets the back of a body show through."""
    rng = np.random.default_rng(seed)
    pts = to_optical(np.concatenate(scene.samples), camera_height)
    normals = to_optical(np.concatenate(scene.normals), 0.0)
    pts = pts[(pts[:, 2] > 0.1) & (np.einsum('ij,ij->i', pts, normals) < 0)]
    u = np.round(intrinsics.fx * pts[:, 0] / pts[:, 2] + intrinsics.cx).astype(int)
    v = np.round(intrinsics.fy * pts[:, 1] / pts[:, 2] + intrinsics.cy).astype(int)
    ok = (u >= 0) & (u < intrinsics.width) & (v >= 0) & (v < intrinsics.height)
    u, v, z = u[ok], v[ok], pts[ok, 2]
    depth = np.full(intrinsics.height * intrinsics.width, np.inf)
    np.minimum.at(depth, v * intrinsics.width + u, z)
    depth = depth.reshape(intrinsics.height, intrinsics.width)
    depth[~np.isfinite(depth)] = np.nan
    if noise:
        depth = depth + rng.normal(0, noise, depth.shape) * depth**2
    tips = to_optical(np.array(scene.tips), camera_height)
    return depth.astype(np.float32), tips


def person(pose='t_pose', *, x=0.0, z=2.8, yaw=0.0, seed=0, floor=True) -> Scene:
    """A capsule person standing on the floor; tips: head, hands, feet (part centres)."""
    rng = np.random.default_rng(seed)
    s = Scene([], [])
    c, sn = np.cos(yaw), np.sin(yaw)

    def w(p):  # body frame (x right, y up, z back) -> world
        p = np.asarray(p, float)
        return np.array([x + c * p[0] + sn * p[2], p[1], z - sn * p[0] + c * p[2]])

    def cap(a, b, r):
        s.add_capsule(w(a), w(b), r, rng)

    cap([0, 0.95, 0], [0, 1.40, 0], 0.15)           # torso
    cap([-0.08, 0.98, 0], [0.08, 0.98, 0], 0.13)     # pelvis
    cap([0, 1.45, 0], [0, 1.52, 0], 0.05)            # neck
    s.add_capsule(w([0, 1.63, 0]), w([0, 1.65, 0]), 0.10, rng)  # head
    head = w([0, 1.64, 0])
    for side in (-1, 1):
        sh = [0.19 * side, 1.42, 0]
        if pose == 't_pose':
            el, wr, hand = [0.47 * side, 1.42, 0], [0.72 * side, 1.42, 0], [0.80 * side, 1.42, 0]
        else:  # arms down, hands clear of the body
            el, wr, hand = [0.30 * side, 1.16, 0], [0.38 * side, 0.92, 0], [0.40 * side, 0.84, 0]
        cap(sh, el, 0.045)
        cap(el, wr, 0.038)
        cap(wr, hand, 0.045)
        hip, knee, ankle = [0.10 * side, 0.92, 0], [0.13 * side, 0.50, 0], [0.15 * side, 0.09, 0]
        cap(hip, knee, 0.07)
        cap(knee, ankle, 0.05)
        foot_a, foot_b = [0.15 * side, 0.05, 0.02], [0.15 * side, 0.05, -0.15]
        cap(foot_a, foot_b, 0.045)
        s.tips.append(w(hand))
    s.tips.insert(0, head)
    for side in (-1, 1):
        s.tips.append(w([0.15 * side, 0.05, -0.15]))  # the toe end, as a hand's tip is its end
    if floor:
        s.add_floor(rng)
    return s


def star(n_limbs=5, *, z=2.5, length=0.45, seed=0) -> Scene:
    """A ball with ``n_limbs`` capsule limbs in the image plane, floating at 1.2 m."""
    rng = np.random.default_rng(seed)
    s = Scene([], [])
    centre = np.array([0.0, 1.2, z])
    s.add_capsule(centre, centre, 0.14, rng)
    for i in range(n_limbs):
        ang = 2 * np.pi * i / n_limbs + 0.3
        d = np.array([np.cos(ang), np.sin(ang), 0.0])
        tip = centre + d * length
        s.add_capsule(centre, tip, 0.045, rng)
        s.tips.append(tip)
    return s


def chair(*, z=2.4, yaw=0.5, seed=0) -> Scene:
    """Four legs, a seat and a backrest of two posts, standing on the floor; tips: leg feet,
    post tops. Render it from a low camera (0.6 m) so the seat does not hide the back legs."""
    rng = np.random.default_rng(seed)
    s = Scene([], [])
    c, sn = np.cos(yaw), np.sin(yaw)

    def w(p):
        p = np.asarray(p, float)
        return np.array([c * p[0] + sn * p[2], p[1], z - sn * p[0] + c * p[2]])

    for dx in (-0.2, 0.2):
        for dz in (-0.2, 0.2):
            s.add_capsule(w([dx, 0.03, dz]), w([dx, 0.5, dz]), 0.035, rng)
            s.tips.append(w([dx, 0.06, dz]))
    corners = [w([dx, 0.95, 0.2]) for dx in (-0.2, 0.2)]
    ring = [w([-0.2, 0.5, -0.2]), w([0.2, 0.5, -0.2]), w([0.2, 0.5, 0.2]), w([-0.2, 0.5, 0.2])]
    for k in range(4):  # seat frame and a cross of slats
        s.add_capsule(ring[k], ring[(k + 1) % 4], 0.035, rng)
    s.add_capsule(ring[0], ring[2], 0.035, rng)
    s.add_capsule(ring[1], ring[3], 0.035, rng)
    for dx in (-0.2, 0.2):  # backrest posts
        s.add_capsule(w([dx, 0.5, 0.2]), w([dx, 0.95, 0.2]), 0.03, rng)
    s.add_capsule(w([-0.2, 0.58, 0.2]), w([0.2, 0.58, 0.2]), 0.03, rng)
    s.tips.extend(corners)
    s.add_floor(rng)
    return s


def robot_arm(*, z=2.4, seed=0) -> Scene:
    """A bent chain on a pedestal standing on the floor; tips: pedestal foot and gripper."""
    rng = np.random.default_rng(seed)
    s = Scene([], [])
    base = np.array([-0.3, 0.0, z])
    joints = [base + [0, 0.03, 0], base + [0, 0.6, 0], base + [0.35, 0.95, 0],
              base + [0.75, 0.85, 0], base + [0.95, 0.55, 0]]
    s.add_capsule(joints[0], joints[1], 0.08, rng)
    for a, b in zip(joints[1:-1], joints[2:]):
        s.add_capsule(a, b, 0.055, rng)
    s.tips.extend([base + [0, 0.1, 0], joints[-1]])
    s.add_floor(rng)
    return s
