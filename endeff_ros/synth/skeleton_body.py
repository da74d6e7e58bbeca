"""Bodies built from motion-capture joints: one frame of ``mocap.JOINTS`` -> an ``Entity``.

The procedural ``body.PersonModel`` poses a fixed skeleton by inverse kinematics; here the
skeleton comes from a recorded motion, so every primitive is laid along the joints it spans and
only the radii, clothing and proportions come from a ``BodyStyle``. Joints are taken in whatever
frame they are given (the scene frame in the suite: y up, metres); the builder needs only "up"
(+y) to orient the hands and feet when a joint is degenerate.

Ground truth is as in the paper suite: the CENTRE of each terminal part (ids 0..4: head, left
hand, right hand, left foot, right foot), inside the part, behind its visible surface:

- head: centre of the head ellipsoid (crown at ``head_top``);
- hand: the middle of the hand from wrist to finger tips, inside the palm box (the part that
  decides visibility), at mid-thickness;
- foot: centre of the shoe ellipsoid, which runs from behind the ankle to past the toe joint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .body import Color, Entity
from .mocap.clip import JOINT_INDEX
from .shapes import Primitive, Vec, box, capsule, ellipsoid, frame_from_axis, unit

UP = np.array([0.0, 1.0, 0.0])
REFERENCE_HEIGHT = 1.75  # m: the radii below are for a person of this height
BUILDS = ('slim', 'average', 'heavy')
CLOTHING = ('plain', 'sleeves', 'coat', 'skirt')
# (torso width/depth factor, belly depth factor, limb radius factor) per build.
_GIRTH = {'slim': (0.86, 0.85, 0.85), 'average': (1.0, 1.0, 1.0), 'heavy': (1.22, 1.5, 1.22)}
_J = JOINT_INDEX


@dataclass(frozen=True)
class BodyStyle:
    """Size, build and clothing of one rendered person.

    ``height_m`` is the standing height the clip's joints are scaled to (``scale_to_height``);
    ``child`` keeps the head closer to adult size (a child's head is large for its height).
    ``build`` is one of ``BUILDS`` and scales the radii; ``clothing`` one of ``CLOTHING``:
    ``sleeves`` widens the forearms (loose sleeves down to the wrist), ``coat`` adds a coat
    from the chest to below the knees, ``skirt`` a skirt from the waist to above the knees.
    """

    height_m: float = 1.75
    build: str = 'average'
    clothing: str = 'plain'
    child: bool = False
    shirt: Color = (0.20, 0.35, 0.70)
    trousers: Color = (0.22, 0.22, 0.30)
    skin: Color = (0.85, 0.65, 0.52)
    shoes: Color = (0.30, 0.18, 0.10)
    coat: Color = (0.45, 0.40, 0.32)

    def __post_init__(self) -> None:
        if self.build not in BUILDS:
            msg = f'build must be one of {BUILDS}, got {self.build!r}'
            raise ValueError(msg)
        if self.clothing not in CLOTHING:
            msg = f'clothing must be one of {CLOTHING}, got {self.clothing!r}'
            raise ValueError(msg)
        if not 0.8 <= self.height_m <= 2.3:
            msg = f'height_m must be between 0.8 and 2.3 m, got {self.height_m}'
            raise ValueError(msg)

    @property
    def label(self) -> str:
        """Short text for bag names and attributes, e.g. ``h175-heavy-coat``."""
        kid = '-child' if self.child else ''
        return f'h{round(self.height_m * 100):d}-{self.build}-{self.clothing}{kid}'


def standing_height(positions: npt.ArrayLike) -> float:
    """Standing height (m) of the performer of ``positions`` ((T, 22, 3) or (22, 3)).

    Measured along the skeleton, not from the pose, so that a crouch, a crawl or a sitting
    clip gives the same answer as a walk: median over frames of leg (hip-knee-ankle) + pelvis
    drop (pelvis to hip line) + spine, neck and head segments, plus the ankle's height above
    the sole (4.5 % of the total, as in the 1.75 m reference model).
    """
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim == 2:
        p = p[None]

    def seg(a: str, b: str) -> npt.NDArray[np.float64]:
        return np.linalg.norm(p[:, _J[a]] - p[:, _J[b]], axis=-1)

    leg = 0.5 * (seg('l_hip', 'l_knee') + seg('l_knee', 'l_ankle') + seg('r_hip', 'r_knee')
                 + seg('r_knee', 'r_ankle'))
    hips = 0.5 * (p[:, _J['l_hip']] + p[:, _J['r_hip']])
    drop = np.linalg.norm(p[:, _J['pelvis']] - hips, axis=-1)
    trunk = (seg('pelvis', 'spine') + seg('spine', 'chest') + seg('chest', 'neck')
             + seg('neck', 'head') + seg('head', 'head_top'))
    return float(np.median(leg + drop + trunk)) / 0.955


def scale_to_height(positions: npt.ArrayLike, height_m: float) -> npt.NDArray[np.float64]:
    """``positions`` (..., 22, 3) scaled uniformly about the floor origin to ``height_m``.

    Uniform scaling keeps the motion's proportions and scales its root travel with it (a
    shorter person takes shorter steps), and keeps the feet on the floor (y = 0 stays 0).
    """
    p = np.asarray(positions, dtype=np.float64)
    return p * (height_m / standing_height(p))


def carry_pose(joints: npt.ArrayLike, half_size: npt.ArrayLike) -> tuple[Vec, Primitive]:
    """Arms re-posed to hold a box in front of the belly, and the box (no ground truth).

    ``joints`` (22, 3); ``half_size`` (3,) m: half width, height, depth of the box. The wrists
    are moved to the box's sides (elbows by two-link IK bending down and out, keeping the
    clip's arm lengths), the hands point forward along the box sides. Returns the new joints
    and the box primitive.
    """
    from .body import two_link

    j = np.array(joints, dtype=np.float64)
    hs = np.asarray(half_size, dtype=np.float64)
    left = unit(j[_J['l_shoulder']] - j[_J['r_shoulder']])
    left = unit(left - np.dot(left, UP) * UP)
    fwd = np.cross(left, UP)
    centre = j[_J['pelvis']] + 0.22 * UP + (0.12 + hs[2]) * fwd
    rot = np.stack([left, UP, fwd], axis=1)
    for side, pre in ((1.0, 'l_'), (-1.0, 'r_')):
        sh, el, wr, he = (_J[pre + n] for n in ('shoulder', 'elbow', 'wrist', 'hand_end'))
        l1 = float(np.linalg.norm(j[el] - j[sh]))
        l2 = float(np.linalg.norm(j[wr] - j[el]))
        lh = float(np.linalg.norm(j[he] - j[wr])) or 0.18
        wrist = centre + side * (hs[0] + 0.02) * left - 0.35 * hs[2] * fwd
        elbow, wrist = two_link(j[sh], wrist, l1, l2, side * 0.6 * left - UP)
        j[el], j[wr] = elbow, wrist
        j[he] = wrist + lh * unit(0.9 * fwd - 0.2 * side * left)
    return j, box(centre, rot, hs, (0.62, 0.48, 0.30), 7, 'carried_box')


def _polyline_point(pts: Vec, s: float) -> tuple[Vec, Vec]:
    """Point and unit tangent at arc-length fraction ``s`` along the polyline ``pts`` (K, 3)."""
    seg = np.diff(pts, axis=0)
    lens = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(lens)])
    target = s * cum[-1]
    k = int(np.clip(np.searchsorted(cum, target, side='right') - 1, 0, len(seg) - 1))
    w = (target - cum[k]) / max(lens[k], 1e-9)
    return pts[k] + w * seg[k], unit(seg[k] if lens[k] > 1e-9 else UP)


def build_body(joints: npt.ArrayLike, style: BodyStyle | None = None,
               texture_base: int = 0) -> Entity:
    """The person of one frame: ``joints`` (22, 3) m in ``mocap.JOINTS`` order -> ``Entity``.

    Joints are used as given (scale them with ``scale_to_height`` first); radii are those of
    the 1.75 m reference model times ``style.height_m / 1.75`` and the build's girth factors.
    """
    st = style or BodyStyle()
    j = np.asarray(joints, dtype=np.float64)
    if j.shape != (len(_J), 3) or not np.all(np.isfinite(j)):
        msg = f'joints must be a finite ({len(_J)}, 3) array, got shape {j.shape}'
        raise ValueError(msg)
    k = st.height_m / REFERENCE_HEIGHT
    kh = k ** 0.45 if st.child else k  # head size
    gw, gb, gl = _GIRTH[st.build]
    tex = texture_base
    prims: list[Primitive] = []
    parts: dict[str, int] = {}
    coat = st.clothing == 'coat'
    top = st.coat if coat else st.shirt

    def add(name: str, prim: Primitive) -> None:
        parts[name] = len(prims)
        prims.append(prim)

    def J(name: str) -> Vec:  # noqa: N802
        return j[_J[name]]

    # Torso: pelvis, abdomen and chest ellipsoids along the pelvis-spine-chest-neck polyline,
    # widths across the hips and the shoulders.
    hips_x = J('l_hip') - J('r_hip')
    spine = np.stack([J('pelvis'), J('spine'), J('chest'), J('neck')])
    trunk_len = float(np.linalg.norm(np.diff(spine, axis=0), axis=1).sum())
    pel_c = 0.5 * J('pelvis') + 0.25 * (J('l_hip') + J('r_hip'))
    pel_rot = frame_from_axis(unit(J('spine') - J('pelvis')), hips_x)
    hip_half = max(0.16 * k, 0.5 * float(np.linalg.norm(hips_x)) + 0.07 * k)
    add('pelvis', ellipsoid(pel_c + 0.02 * k * pel_rot[:, 1], pel_rot,
                            np.array([hip_half * gw, 0.13 * k, 0.10 * k * gb]), st.trousers,
                            tex + 1, 'pelvis'))
    sh_x = J('l_shoulder') - J('r_shoulder')
    for name, s, half_y, w, d, t in (('abdomen', 0.36, 0.32, 0.15, 0.095 * gb, 2),
                                     ('chest', 0.72, 0.36, 0.17, 0.105, 3)):
        c, ax = _polyline_point(spine, s)
        rot = frame_from_axis(ax, sh_x if name == 'chest' else hips_x)
        add(name, ellipsoid(c, rot, np.array([w * k * gw, max(half_y * trunk_len, 0.12 * k),
                                              d * k * (gw if name == 'chest' else 1.0)]),
                            top, tex + t, name))
    fwd = unit(np.cross(unit(sh_x), prims[parts['chest']].rot[:, 1]))
    add('shoulders', capsule(J('l_shoulder'), J('r_shoulder'), 0.055 * k * gl, fwd, top,
                             tex + 4, 'shoulders'))

    # Neck and head: the crown at head_top, the ellipsoid's axis from head to head_top.
    head_ax = unit(J('head_top') - J('head'))
    head_rot = frame_from_axis(head_ax, sh_x)
    head_c = J('head_top') - 0.11 * kh * head_ax + 0.012 * kh * head_rot[:, 2]
    add('neck', capsule(J('neck'), head_c - 0.07 * kh * head_ax, 0.05 * k * gl, fwd, st.skin,
                        tex + 5, 'neck'))
    add('head', ellipsoid(head_c, head_rot, np.array([0.078, 0.11, 0.095]) * kh, st.skin,
                          tex + 6, 'head'))

    # Arms and hands.
    hand_c = {}
    sleeve = 0.065 if st.clothing == 'sleeves' else 0.0
    for side, pre in ((1.0, 'l'), (-1.0, 'r')):
        sh, el, wr = J(f'{pre}_shoulder'), J(f'{pre}_elbow'), J(f'{pre}_wrist')
        add(f'{pre}_upper', capsule(sh, el, max(0.045 * gl, sleeve * 0.9) * k, fwd, top,
                                    tex + 8, f'{pre}_upper_arm'))
        fore_r = (sleeve if sleeve else 0.035 * gl) * k
        add(f'{pre}_fore', capsule(el, wr, fore_r, fwd, top if sleeve else st.skin, tex + 9,
                                   f'{pre}_forearm'))
        hand_c[pre] = _hand(add, wr, J(f'{pre}_hand_end'), unit(wr - el), fwd, side, k, gl,
                            st.skin, tex + 10, pre)

    # Legs, clothes over them, shoes.
    foot_c = {}
    for pre in ('l', 'r'):
        hip, knee, ank, toe = (J(f'{pre}_{n}') for n in ('hip', 'knee', 'ankle', 'toe'))
        add(f'{pre}_thigh', capsule(hip, knee, 0.07 * k * gl, fwd, st.trousers, tex + 11,
                                    f'{pre}_thigh'))
        add(f'{pre}_shin', capsule(knee, ank, 0.05 * k * gl, fwd, st.trousers, tex + 12,
                                   f'{pre}_shin'))
        foot_c[pre] = _shoe(add, ank, toe, fwd, k, st.shoes, tex + 13, pre)
    if st.clothing in ('coat', 'skirt'):
        _skirt(add, j, sh_x, k, gw, st.coat if coat else st.shirt, tex + 14, coat)

    names = ('head', 'l_hand', 'r_hand', 'l_foot', 'r_foot')
    gt = np.array([head_c, hand_c['l'], hand_c['r'], foot_c['l'], foot_c['r']])
    radius = np.array([0.095 * kh, 0.016 * k, 0.016 * k, 0.045 * k, 0.045 * k])
    return Entity(prims, gt, np.arange(5, dtype=np.uint32),
                  np.array([parts[n] for n in names]), radius, parts)


def _hand(add, wrist: Vec, hand_end: Vec, fore_dir: Vec, fwd: Vec, side: float, k: float,
          gl: float, skin: Color, tex: int, pre: str) -> Vec:
    """Palm box, finger block and thumb from ``wrist`` towards ``hand_end``; returns the
    hand's centre (the ground truth). The palm's width lies across the body's front
    direction (the thumb forward on a hanging arm); a missing hand end follows the forearm."""
    span = hand_end - wrist
    length = float(np.linalg.norm(span))
    along = unit(span) if length > 0.03 * k else fore_dir
    length = float(np.clip(length, 0.15 * k, 0.21 * k)) if length > 0.03 * k else 0.185 * k
    hint = fwd if abs(np.dot(along, fwd)) < 0.8 else UP
    rot = frame_from_axis(along, hint)  # x: width (thumb side), y: along, z: palm normal
    w = rot[:, 0]
    palm = 0.55 * length
    add(f'{pre}_hand', box(wrist + 0.5 * palm * along, rot,
                           np.array([0.043 * k * gl, 0.5 * palm, 0.016 * k * gl]), skin, tex,
                           f'{pre}_hand'))
    fing = length - palm
    add(f'{pre}_fingers', box(wrist + (palm + 0.5 * fing) * along, rot,
                              np.array([0.039 * k * gl, 0.5 * fing, 0.012 * k * gl]), skin,
                              tex + 20, f'{pre}_fingers'))
    base = wrist + 0.18 * length * along + 0.036 * k * w
    tip = base + 0.36 * length * along + 0.03 * k * w + 0.012 * k * side * rot[:, 2]
    add(f'{pre}_thumb', capsule(base, tip, 0.011 * k * gl, along, skin, tex + 21,
                                f'{pre}_thumb'))
    return wrist + 0.5 * length * along


def _shoe(add, ankle: Vec, toe: Vec, fwd: Vec, k: float, color: Color, tex: int,
          pre: str) -> Vec:
    """Shoe ellipsoid from behind the ankle to past the toe joint, plus a sole box under it;
    returns the shoe's centre (the ground truth)."""
    sole_ank = ankle - 0.06 * k * UP
    d = toe - sole_ank
    f = unit(d) if np.linalg.norm(d) > 0.05 * k else unit(fwd - np.dot(fwd, UP) * UP)
    heel = sole_ank - 0.07 * k * f
    tip = (toe if np.linalg.norm(d) > 0.05 * k else sole_ank + 0.15 * k * f) + 0.025 * k * f
    half = 0.5 * float(np.linalg.norm(tip - heel))
    side = np.cross(UP, f)
    rot = frame_from_axis(f, side if np.linalg.norm(side) > 1e-3 else fwd)
    n = rot[:, 2]  # shoe "up" (perpendicular to its length and width)
    if n @ UP < 0:
        n = -n
    c = 0.5 * (heel + tip) + 0.03 * k * n
    add(f'{pre}_foot', ellipsoid(c, rot, np.array([0.048 * k, half, 0.045 * k]), color, tex,
                                 f'{pre}_foot'))
    dark = tuple(0.45 * v for v in color)
    add(f'{pre}_sole', box(c - 0.035 * k * n, rot, np.array([0.045 * k, 0.95 * half,
                                                            0.012 * k]), dark, tex + 20,
                           f'{pre}_sole'))
    return c


def _skirt(add, j: Vec, sh_x: Vec, k: float, gw: float, color: Color, tex: int,
           coat: bool) -> None:
    """A box hanging from the chest to a little below the knees (coat) or from the waist to
    three quarters of the way to the knees (skirt), following the thighs' mean direction and
    wide and deep enough at its hem to hold both legs' spread there."""
    knees = 0.5 * (j[_J['l_knee']] + j[_J['r_knee']])
    top = j[_J['chest']] if coat else j[_J['pelvis']] + 0.05 * k * UP
    hips = 0.5 * (j[_J['l_hip']] + j[_J['r_hip']])
    frac = 1.2 if coat else 0.75
    hem = hips + frac * (knees - hips)
    rot = frame_from_axis(unit(top - hem), sh_x)
    spread = frac * (j[_J['l_knee']] - j[_J['r_knee']]) + (1 - frac) * (
        j[_J['l_hip']] - j[_J['r_hip']])
    sx = abs(float(spread @ rot[:, 0])) * 0.5
    sz = abs(float(spread @ rot[:, 2])) * 0.5
    half = np.array([max(0.19 * k * gw, sx + 0.09 * k), 0.5 * float(np.linalg.norm(top - hem)),
                     max(0.13 * k * gw, sz + 0.08 * k)])
    add('coat' if coat else 'skirt', box(0.5 * (top + hem), rot, half, color, tex,
                                         'coat' if coat else 'skirt'))

