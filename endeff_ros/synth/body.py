"""Kinematic models of the synthetic entities: a person, a star, a chair and a robot arm.

Models are built in the *scene frame*: x to the camera's right, y up, z towards the camera,
origin on the floor straight below the camera, metres. Each entity is posed in its own body
frame (x its left, y up, z its front) and placed by ``Placement`` (floor position and yaw).
Every builder returns an ``Entity``: the primitives (``shapes.Primitive``) and the ground-truth
end-effectors, each the CENTRE of its terminal part (see ``Entity``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .shapes import Primitive, Vec, box, capsule, ellipsoid, frame_from_axis, rot_x, rot_y, unit

Color = tuple[float, float, float]

# Person end-effector ids (the second person of a scene adds 5).
HEAD, LEFT_HAND, RIGHT_HAND, LEFT_FOOT, RIGHT_FOOT = range(5)


@dataclass
class Entity:
    """Primitives of one posed entity plus its ground truth.

    ``gt`` (M, 3) end-effector positions (m, scene frame), ``gt_ids`` (M,) stable ids,
    ``gt_prims`` (M,) index into ``prims`` of the part each end-effector is the centre of, and
    ``gt_radius`` (M,) roughly how far (m) that centre lies behind the part's visible surface.
    """

    prims: list[Primitive]
    gt: Vec
    gt_ids: npt.NDArray[np.uint32]
    gt_prims: npt.NDArray[np.int64]
    gt_radius: Vec
    parts: dict[str, int] = field(default_factory=dict)

    def transformed(self, rot: Vec, trans: Vec) -> Entity:
        """The entity moved by ``p -> rot @ p + trans``."""
        return Entity([p.transformed(rot, trans) for p in self.prims], self.gt @ rot.T + trans,
                      self.gt_ids, self.gt_prims, self.gt_radius, dict(self.parts))


def merge(entities: list[Entity]) -> Entity:
    """One entity holding all primitives and ground truth of ``entities`` (ids kept)."""
    prims: list[Primitive] = []
    gts, ids, gp, rad = [], [], [], []
    parts: dict[str, int] = {}
    for k, e in enumerate(entities):
        off = len(prims)
        prims.extend(e.prims)
        gts.append(e.gt)
        ids.append(e.gt_ids)
        gp.append(e.gt_prims + off)
        rad.append(e.gt_radius)
        parts.update({f'{k}:{name}': i + off for name, i in e.parts.items()})
    return Entity(prims, np.concatenate(gts), np.concatenate(ids).astype(np.uint32),
                  np.concatenate(gp).astype(np.int64), np.concatenate(rad), parts)


@dataclass(frozen=True)
class Placement:
    """Where an entity stands: body origin at (x, 0, z) in the scene frame, turned by ``yaw``.

    ``yaw`` = 0 means the entity's front faces the camera (+z).
    """

    x: float
    z: float
    yaw: float = 0.0

    def apply(self, e: Entity) -> Entity:
        return e.transformed(rot_y(self.yaw), np.array([self.x, 0.0, self.z]))


def two_link(root: Vec, target: Vec, l1: float, l2: float, pole: Vec) -> tuple[Vec, Vec]:
    """Planar two-link IK: (middle joint, end point) reaching from ``root`` towards ``target``.

    The middle joint bends towards ``pole`` (a direction); out-of-reach targets are clamped.
    """
    d = target - root
    dist = float(np.linalg.norm(d))
    u = d / max(dist, 1e-9)
    dist = float(np.clip(dist, abs(l1 - l2) + 1e-3, l1 + l2 - 1e-4))
    cos_a = (l1 * l1 + dist * dist - l2 * l2) / (2 * l1 * dist)
    sin_a = np.sqrt(max(0.0, 1.0 - cos_a * cos_a))
    v = pole - np.dot(pole, u) * u
    if np.linalg.norm(v) < 1e-6:
        v = np.array([0.0, 0.0, -1.0]) - u[2] * u
    v = unit(v)
    mid = root + l1 * (cos_a * u + sin_a * v)
    return mid, root + dist * u


@dataclass(frozen=True)
class PersonStyle:
    """Size and clothing of a person: ``scale`` multiplies every length of the 1.75 m model."""

    scale: float = 1.0
    shirt: Color = (0.20, 0.35, 0.70)
    trousers: Color = (0.22, 0.22, 0.30)
    skin: Color = (0.85, 0.65, 0.52)
    shoes: Color = (0.30, 0.18, 0.10)


@dataclass(frozen=True)
class PersonPose:
    """Joint-space description of a person pose, all in the body frame (m, rad).

    ``pelvis`` is the offset of the pelvis from its standing position; ``bend`` leans the
    torso forward about the pelvis, ``twist`` turns it about its own axis, ``nod`` tilts the head
    forward. Hands are placed by the centre of the hand (``hand_l``, ``hand_r``), feet by the
    ankle (``ankle_l``, ``ankle_r``); elbows bend towards ``elbow_l``/``elbow_r`` (directions).
    """

    hand_l: Vec
    hand_r: Vec
    ankle_l: Vec
    ankle_r: Vec
    pelvis: Vec = field(default_factory=lambda: np.zeros(3))
    bend: float = 0.0
    twist: float = 0.0
    nod: float = 0.0
    elbow_l: Vec = field(default_factory=lambda: np.array([0.3, -0.2, -1.0]))
    elbow_r: Vec = field(default_factory=lambda: np.array([-0.3, -0.2, -1.0]))


class PersonModel:
    """A 1.75 m person of capsules and ellipsoids (times ``style.scale``).

    Dimensions (m, at scale 1): pelvis 0.95 above the floor, shoulders 0.45 above it and 0.18 to
    each side, upper arm 0.29 (radius 0.045), forearm 0.25 (0.035), hand ellipsoid
    0.085 x 0.055 x 0.045 semi-axes, thigh 0.43 (0.07), shin 0.42 (0.05), ankle 0.075 above the
    sole, foot ellipsoid 0.12 long, head ellipsoid 0.078 x 0.11 x 0.095 semi-axes.
    """

    def __init__(self, style: PersonStyle | None = None, texture_base: int = 0) -> None:
        self.style = style or PersonStyle()
        s = self.style.scale
        self.s = s
        self.tex = texture_base
        self.pelvis_y = 0.95 * s
        self.upper, self.fore, self.hand_half = 0.29 * s, 0.25 * s, 0.085 * s
        self.thigh, self.shin, self.ankle_h = 0.43 * s, 0.42 * s, 0.075 * s
        self.arm_reach = self.upper + self.fore + self.hand_half

    def torso_rot(self, bend: float, twist: float) -> Vec:
        """Rotation (3, 3) of the torso for a forward ``bend`` and a ``twist`` (rad)."""
        return rot_x(bend) @ rot_y(twist)

    def pelvis(self, offset: Vec) -> Vec:
        return np.array([0.0, self.pelvis_y, 0.0]) + offset

    def shoulders(self, offset: Vec, bend: float = 0.0, twist: float = 0.0) -> tuple[Vec, Vec]:
        """Left and right shoulder joints (3,) in the body frame."""
        p, t, s = self.pelvis(offset), self.torso_rot(bend, twist), self.s
        return p + t @ np.array([0.18 * s, 0.45 * s, 0.0]), p + t @ np.array([-0.18 * s, 0.45 * s,
                                                                              0.0])

    def standing_ankles(self, half_width: float = 0.11) -> tuple[Vec, Vec]:
        w = half_width * self.s
        return np.array([w, self.ankle_h, 0.0]), np.array([-w, self.ankle_h, 0.0])

    def arm_target(self, shoulder: Vec, side: int, abduction: float, flexion: float,
                   frac: float = 0.97) -> Vec:
        """Hand centre for an arm raised sideways by ``abduction`` and forwards by ``flexion``.

        ``side`` is +1 for the left arm, -1 for the right; ``frac`` of full reach (bent elbow).
        """
        ca, sa = np.cos(abduction), np.sin(abduction)
        d = np.array([side * sa, -ca, 0.0])
        d = rot_x(-flexion) @ d
        return shoulder + frac * self.arm_reach * d

    def build(self, pose: PersonPose) -> Entity:
        """The posed person in its body frame."""
        st, s, tex = self.style, self.s, self.tex
        prims: list[Primitive] = []
        parts: dict[str, int] = {}

        def add(name: str, prim: Primitive) -> None:
            parts[name] = len(prims)
            prims.append(prim)

        p = self.pelvis(pose.pelvis)
        t = self.torso_rot(pose.bend, pose.twist)
        hips_rot = rot_x(0.3 * pose.bend)
        fwd = t @ np.array([0.0, 0.0, 1.0])
        add('pelvis', ellipsoid(p + hips_rot @ np.array([0, 0.02 * s, 0]), hips_rot,
                                np.array([0.16, 0.13, 0.10]) * s, st.trousers, tex + 1, 'pelvis'))
        add('abdomen', ellipsoid(p + t @ np.array([0, 0.17 * s, 0]), t,
                                 np.array([0.15, 0.15, 0.095]) * s, st.shirt, tex + 2, 'abdomen'))
        add('chest', ellipsoid(p + t @ np.array([0, 0.35 * s, 0]), t,
                               np.array([0.17, 0.17, 0.105]) * s, st.shirt, tex + 3, 'chest'))
        sh_l, sh_r = self.shoulders(pose.pelvis, pose.bend, pose.twist)
        add('shoulders', capsule(sh_l, sh_r, 0.055 * s, fwd, st.shirt, tex + 4, 'shoulders'))
        neck = p + t @ np.array([0, 0.50 * s, 0])
        add('neck', capsule(neck - t @ np.array([0, 0.04 * s, 0]),
                            neck + t @ np.array([0, 0.07 * s, 0]), 0.05 * s, fwd, st.skin,
                            tex + 5, 'neck'))
        head_rot = t @ rot_x(pose.nod)
        head_c = neck + head_rot @ np.array([0, 0.17 * s, 0.01 * s])
        add('head', ellipsoid(head_c, head_rot, np.array([0.078, 0.11, 0.095]) * s, st.skin,
                              tex + 6, 'head'))
        for side, name, hand, pole in ((1, 'l', pose.hand_l, pose.elbow_l),
                                       (-1, 'r', pose.hand_r, pose.elbow_r)):
            sh = sh_l if side > 0 else sh_r
            elbow, hc = two_link(sh, np.asarray(hand, float), self.upper,
                                 self.fore + self.hand_half, np.asarray(pole, float))
            along = unit(hc - elbow)
            wrist = hc - self.hand_half * along
            add(f'{name}_upper', capsule(sh, elbow, 0.045 * s, fwd, st.shirt, tex + 8,
                                         f'{name}_upper_arm'))
            add(f'{name}_fore', capsule(elbow, wrist, 0.035 * s, fwd, st.skin, tex + 9,
                                        f'{name}_forearm'))
            # Hand: semi-axes width (x), length (y, along the forearm), thickness (z).
            up = t @ np.array([0.0, 1.0, 0.0])
            hand_rot = frame_from_axis(along, fwd if abs(np.dot(along, fwd)) < 0.7 else up)
            add(f'{name}_hand', ellipsoid(hc, hand_rot, np.array([0.055, 0.085, 0.045]) * s,
                                          st.skin, tex + 10, f'{name}_hand'))

        for side, name, ankle in ((1, 'l', pose.ankle_l), (-1, 'r', pose.ankle_r)):
            hip = p + hips_rot @ np.array([side * 0.09 * s, -0.05 * s, 0.0])
            knee, ank = two_link(hip, np.asarray(ankle, float), self.thigh, self.shin,
                                 np.array([0.0, 0.0, 1.0]))
            add(f'{name}_thigh', capsule(hip, knee, 0.07 * s, [0, 0, 1], st.trousers, tex + 11,
                                         f'{name}_thigh'))
            add(f'{name}_shin', capsule(knee, ank, 0.05 * s, [0, 0, 1], st.trousers, tex + 12,
                                        f'{name}_shin'))
            foot_rot = frame_from_axis([0.0, 0.0, 1.0], [side * 1.0, 0.0, 0.0])
            foot_c = ank + np.array([0.0, -0.035 * s, 0.05 * s])
            add(f'{name}_foot', ellipsoid(foot_c, foot_rot, np.array([0.045, 0.12, 0.04]) * s,
                                          st.shoes, tex + 13, f'{name}_foot'))

        names = ('head', 'l_hand', 'r_hand', 'l_foot', 'r_foot')
        gt = np.array([prims[parts[n]].center for n in names])
        radius = np.array([0.095, 0.045, 0.045, 0.04, 0.04]) * s
        return Entity(prims, gt, np.arange(5, dtype=np.uint32),
                      np.array([parts[n] for n in names]), radius, parts)


def star(phase: float, spin: float, color: Color = (0.85, 0.55, 0.15), tex: int = 40) -> Entity:
    """A five-limbed star (1.2 m across) in its body frame, hub 1.15 m above the floor.

    Each limb has two capsule segments (0.22 m, radius 0.055; 0.20 m, radius 0.045) and an end
    cap sphere (radius 0.065) whose centre is the end-effector (ids 0..4). ``phase`` (cycles)
    drives the articulation; ``spin`` (rad) turns the whole star about its front axis.
    """
    hub = np.array([0.0, 1.15, 0.0])
    prims = [ellipsoid(hub, rot_x(0.0), [0.14, 0.14, 0.10], color, tex, 'hub')]
    gt, gp = [], []
    w = 2 * np.pi * phase
    for k in range(5):
        base = np.pi / 2 + spin + 2 * np.pi * k / 5
        a1 = base + 0.35 * np.sin(w + 1.3 * k)
        a2 = a1 + 0.6 * np.sin(w + 1.3 * k + 1.0)
        e1 = 0.45 * np.sin(w + 2.1 * k + 0.5)
        e2 = e1 + 0.5 * np.sin(w + 2.1 * k + 2.0)
        d1 = np.array([np.cos(a1) * np.cos(e1), np.sin(a1) * np.cos(e1), np.sin(e1)])
        d2 = np.array([np.cos(a2) * np.cos(e2), np.sin(a2) * np.cos(e2), np.sin(e2)])
        limb, cap = star_limb(hub, d1, d2, k, color, tex)
        gp.append(len(prims) + 2)
        prims.extend(limb)
        gt.append(cap)
    return Entity(prims, np.array(gt), np.arange(5, dtype=np.uint32), np.array(gp),
                  np.full(5, 0.065))


def star_limb(hub: Vec, d1: Vec, d2: Vec, k: int, color: Color, tex: int,
              outer: float = 0.20) -> tuple[list[Primitive], Vec]:
    """Limb ``k`` of a star with its hub centre at ``hub``: a segment of radius 0.055 from
    0.10 m out along ``d1`` for 0.22 m, one of radius 0.045 on along ``d2`` for ``outer`` m,
    and an end cap sphere of radius 0.065 0.03 m further, whose centre is the end-effector.
    Returns the three primitives (the cap last) and the cap's centre."""
    j0 = hub + 0.10 * d1
    j1 = j0 + 0.22 * d1
    j2 = j1 + outer * d2
    cap = j2 + 0.03 * d2
    ccol = (color[0] * 0.6, color[1] * 0.9, min(1.0, color[2] + 0.5))
    return [capsule(j0, j1, 0.055, [0, 0, 1], color, tex + 1 + k, f'limb{k}_a'),
            capsule(j1, j2, 0.045, [0, 0, 1], color, tex + 6 + k, f'limb{k}_b'),
            ellipsoid(cap, frame_from_axis(d2, [0, 0, 1]), [0.065] * 3, ccol, tex + 11 + k,
                      f'limb{k}_cap')], cap


def chair(color: Color = (0.55, 0.33, 0.18), tex: int = 60) -> Entity:
    """A chair (seat 0.46 m high, backrest top 0.96 m) in its body frame, front towards +z.

    End-effectors: ids 0..3 the bottom centres of the four legs lifted to 3 cm above the floor,
    ids 4, 5 the left and right top corners of the backrest. Legs are 4.4 cm square.
    """
    eye = np.eye(3)
    prims = [box([0, 0.46, 0], eye, [0.23, 0.025, 0.22], color, tex, 'seat')]
    gt, gp = [], []
    for k, (x, z) in enumerate(((0.2, 0.19), (-0.2, 0.19), (0.2, -0.19), (-0.2, -0.19))):
        gp.append(len(prims))
        prims.append(box([x, 0.2175, z], eye, [0.022, 0.2175, 0.022], color, tex + 1 + k,
                         f'leg{k}'))
        gt.append([x, 0.03, z])
    for x in (0.2, -0.2):
        prims.append(box([x, 0.555, -0.195], eye, [0.025, 0.07, 0.025], color, tex + 5, 'post'))
    back_col = (color[0] * 0.8, color[1] * 0.8, color[2] * 1.4)
    prims.append(box([0, 0.78, -0.195], eye, [0.23, 0.18, 0.025], back_col, tex + 6, 'back'))
    for x in (0.23, -0.23):
        gp.append(len(prims) - 1)
        gt.append([x, 0.96, -0.195])
    return Entity(prims, np.array(gt, dtype=np.float64), np.arange(6, dtype=np.uint32),
                  np.array(gp), np.array([0.022] * 4 + [0.0, 0.0]))


def robot_arm(q: npt.ArrayLike, color: Color = (0.95, 0.45, 0.05), tex: int = 80) -> Entity:
    """A robot arm on a 0.30 m pedestal standing on the floor, in its body frame.

    ``q`` (4,): base yaw, shoulder, elbow and wrist pitch (rad, 0 = pointing up). Links: 0.50 m
    (radius 0.065) and 0.42 m (radius 0.055), gripper 0.11 x 0.11 x 0.07 m plus two fingers.
    End-effectors: id 0 the bottom centre of the pedestal (on the floor), id 1 the gripper centre.
    """
    q0, q1, q2, q3 = (float(v) for v in q)
    grey = (0.55, 0.57, 0.6)
    eye = np.eye(3)
    prims = [box([0, 0.15, 0], rot_y(q0 * 0.0), [0.12, 0.15, 0.12], grey, tex, 'pedestal')]
    up = np.array([0.0, 1.0, 0.0])
    horiz = np.array([np.cos(q0), 0.0, -np.sin(q0)])
    side = np.cross(horiz, up)
    prims.append(capsule([0, 0.30, 0], [0, 0.40, 0], 0.09, horiz, grey, tex + 1, 'turret'))
    sh = np.array([0.0, 0.45, 0.0])
    d1 = np.cos(q1) * up + np.sin(q1) * horiz
    d2 = np.cos(q1 + q2) * up + np.sin(q1 + q2) * horiz
    d3 = np.cos(q1 + q2 + q3) * up + np.sin(q1 + q2 + q3) * horiz
    el = sh + 0.50 * d1
    wr = el + 0.42 * d2
    prims.append(capsule(sh, el, 0.065, side, color, tex + 2, 'link1'))
    prims.append(capsule(el, wr, 0.055, side, color, tex + 3, 'link2'))
    grip_c = wr + 0.085 * d3
    grot = frame_from_axis(d3, side)
    prims.append(box(grip_c, grot, [0.055, 0.055, 0.035], grey, tex + 4, 'gripper'))
    for sgn in (1, -1):
        fc = grip_c + 0.085 * d3 + sgn * 0.035 * grot[:, 0]
        prims.append(box(fc, grot, [0.012, 0.035, 0.025], grey, tex + 5, 'finger'))
    del eye
    gt = np.array([[0.0, 0.0, 0.0], grip_c])
    return Entity(prims, gt, np.arange(2, dtype=np.uint32), np.array([0, 4]),
                  np.array([0.12, 0.035]))
