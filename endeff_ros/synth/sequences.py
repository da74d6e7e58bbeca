"""The named synthetic sequences and their animation.

Seven person sequences follow the MHAD actions the paper scores (two repetitions each, about
30 fps); four generic ones show a star, a chair, a robot arm and two people. ``scene(name, u,
seed)`` poses a sequence at animation time ``u`` (repetitions, 0 <= u < ``REPS``) and returns
one ``body.Entity`` in the scene frame (see ``body.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .body import Entity, PersonModel, PersonPose, PersonStyle, Placement, chair, merge, robot_arm
from .body import star as star_entity
from .shapes import Vec

GROUPS: dict[str, list[str]] = {
    'no_occlusion': ['jumping_in_place', 'jumping_jacks', 'waving_two_hands', 'waving_one_hand'],
    'occlusion': ['bending', 'punching', 'clapping'],
    'generic': ['star', 'chair', 'robot_arm', 'two_people'],
}
SEQUENCES: tuple[str, ...] = tuple(n for g in GROUPS.values() for n in g)
PERSON_SEQUENCES: tuple[str, ...] = tuple(GROUPS['no_occlusion'] + GROUPS['occlusion'])
REPS = 2.0
FULL_FRAMES = 76
QUICK_FRAMES = 12


@dataclass(frozen=True)
class SequenceSpec:
    """How a sequence is written: frame count and encodings.

    ``info_every``: camera info is published on every n-th frame.
    """

    name: str
    frames: int = FULL_FRAMES
    depth_encoding: str = '16UC1'
    color_encoding: str = 'rgb8'
    info_every: int = 1


SPECS: dict[str, SequenceSpec] = {
    'jumping_in_place': SequenceSpec('jumping_in_place'),
    'jumping_jacks': SequenceSpec('jumping_jacks', frames=80),
    'waving_two_hands': SequenceSpec('waving_two_hands'),
    'waving_one_hand': SequenceSpec('waving_one_hand', info_every=10),
    'bending': SequenceSpec('bending', frames=84),
    'punching': SequenceSpec('punching', color_encoding='bgr8'),
    'clapping': SequenceSpec('clapping'),
    'star': SequenceSpec('star', frames=72, depth_encoding='32FC1'),
    'chair': SequenceSpec('chair', frames=72, color_encoding='bgr8'),
    'robot_arm': SequenceSpec('robot_arm', frames=72, info_every=10),
    'two_people': SequenceSpec('two_people', frames=72, depth_encoding='32FC1'),
}


def n_frames(name: str, quick: bool = False) -> int:
    """Number of frames of sequence ``name``."""
    return QUICK_FRAMES if quick else SPECS[name].frames


def frame_time(name: str, index: int, quick: bool = False) -> float:
    """Animation time (repetitions) of frame ``index``; quick runs sample the whole motion."""
    full = SPECS[name].frames
    if quick:
        index = index * (full - 1) / (QUICK_FRAMES - 1)
    return REPS * index / full


def _smooth(x: float) -> float:
    """0..1 -> 0..1 with zero slope at both ends."""
    x = float(np.clip(x, 0.0, 1.0))
    return x * x * (3 - 2 * x)


def _bump(phi: float) -> float:
    """0 -> 1 -> 0 over one period."""
    return 0.5 - 0.5 * np.cos(2 * np.pi * phi)


def _v(*xs: float) -> Vec:
    return np.array(xs, dtype=np.float64)


# --- person actions: each maps (model, u) to a PersonPose in the body frame -------------------

def jumping_in_place(m: PersonModel, u: float) -> PersonPose:
    """Crouch, jump about 16 cm, land; arms held a little away from the body."""
    phi = u % 1.0
    if phi < 0.2:
        h = -0.07 * np.sin(np.pi * phi / 0.2)
    elif phi < 0.8:
        h = 0.16 * np.sin(np.pi * (phi - 0.2) / 0.6)
    else:
        h = -0.07 * np.sin(np.pi * (phi - 0.8) / 0.2)
    flight = max(h, 0.0) / 0.16
    pel = _v(0, h * m.s, 0)
    sl, sr = m.shoulders(pel)
    abd = np.deg2rad(24 + 12 * flight)
    flex = np.deg2rad(12 + 20 * flight)
    al, ar = m.standing_ankles(0.11)
    lift = _v(0, 0.85 * max(h, 0.0) * m.s, 0)
    return PersonPose(hand_l=m.arm_target(sl, 1, abd, flex, 0.94),
                      hand_r=m.arm_target(sr, -1, abd, flex, 0.94), ankle_l=al + lift,
                      ankle_r=ar + lift, pelvis=pel)


def jumping_jacks(m: PersonModel, u: float) -> PersonPose:
    """Arms from the sides to above the head while the feet jump apart, and back."""
    phi = u % 1.0
    s = _bump(phi)
    hop = 0.06 * max(0.0, np.sin(4 * np.pi * phi))
    pel = _v(0, (hop - 0.05 * s) * m.s, 0)
    sl, sr = m.shoulders(pel)
    abd = np.deg2rad(22 + 143 * s)
    al, ar = m.standing_ankles(0.11 + 0.2 * s)
    lift = _v(0, hop * m.s, 0)
    return PersonPose(hand_l=m.arm_target(sl, 1, abd, np.deg2rad(6), 0.95),
                      hand_r=m.arm_target(sr, -1, abd, np.deg2rad(6), 0.95), ankle_l=al + lift,
                      ankle_r=ar + lift, pelvis=pel, elbow_l=_v(0.2, -0.3, -1),
                      elbow_r=_v(-0.2, -0.3, -1))


def _wave(m: PersonModel, shoulder: Vec, side: int, u: float, centre: float, amp: float,
          phase: float = 0.0) -> tuple[Vec, Vec]:
    """Hand target and elbow direction of a raised arm waving sideways."""
    a = np.deg2rad(centre + amp * np.sin(2 * np.pi * u + phase))
    return m.arm_target(shoulder, side, a, np.deg2rad(10), 0.88), _v(side * 1.0, -0.4, -0.5)


def waving_two_hands(m: PersonModel, u: float) -> PersonPose:
    """Both arms raised above the head, waving side to side (mirrored)."""
    sl, sr = m.shoulders(_v(0, 0, 0))
    hl, el = _wave(m, sl, 1, u, 138, 24)
    hr, er = _wave(m, sr, -1, u, 138, 24)
    al, ar = m.standing_ankles(0.12)
    return PersonPose(hand_l=hl, hand_r=hr, ankle_l=al, ankle_r=ar, elbow_l=el, elbow_r=er)


def waving_one_hand(m: PersonModel, u: float, centre: float = 125, amp: float = 30) -> PersonPose:
    """Right arm raised and waving; left arm hanging a little away from the body."""
    sl, sr = m.shoulders(_v(0, 0, 0))
    hr, er = _wave(m, sr, -1, u, centre, amp)
    al, ar = m.standing_ankles(0.12)
    return PersonPose(hand_l=m.arm_target(sl, 1, np.deg2rad(17), np.deg2rad(8), 0.96), hand_r=hr,
                      ankle_l=al, ankle_r=ar, elbow_r=er)


def bending(m: PersonModel, u: float) -> PersonPose:
    """Bend forward about 85 degrees, hands reaching down together in front of the shins."""
    s = _bump(u % 1.0)
    bend = np.deg2rad(85) * s
    pel = _v(0, -0.03 * s * m.s, -0.12 * s * m.s)
    sl, sr = m.shoulders(pel, bend)
    w = _smooth((s - 0.25) / 0.55)
    hands = []
    for side, sh in ((1, sl), (-1, sr)):
        hang = m.arm_target(sh, side, np.deg2rad(9), np.deg2rad(8), 0.96)
        low = _v(side * 0.052 * m.s, 0.36 * m.s, 0.24 * m.s)
        hands.append((1 - w) * hang + w * low)
    al, ar = m.standing_ankles(0.12)
    pole = m.torso_rot(bend, 0.0) @ _v(0.0, 0.0, -1.0)
    return PersonPose(hand_l=hands[0], hand_r=hands[1], ankle_l=al, ankle_r=ar, pelvis=pel,
                      bend=bend, nod=0.3 * s, elbow_l=pole + _v(0.4, 0, 0),
                      elbow_r=pole + _v(-0.4, 0, 0))


def punching(m: PersonModel, u: float) -> PersonPose:
    """Boxing guard (fists against the chest) with alternating straight punches forwards."""
    phi = u % 1.0
    ext_l = np.sin(np.pi * min(phi / 0.45, 1.0)) ** 2 if phi < 0.45 else 0.0
    ext_r = np.sin(np.pi * (phi - 0.5) / 0.45) ** 2 if 0.5 <= phi < 0.95 else 0.0
    twist = np.deg2rad(14) * (ext_r - ext_l)
    pel = _v(0, -0.02 * m.s, 0)
    t = m.torso_rot(0.0, twist)
    sl, sr = m.shoulders(pel, 0.0, twist)
    p = m.pelvis(pel)
    hands = []
    for side, sh, ext in ((1, sl, ext_l), (-1, sr, ext_r)):
        guard = p + t @ (_v(side * 0.085, 0.40, 0.165) * m.s)
        hit = sh + _v(-side * 0.06, 0.0, 0.58) * m.s
        hands.append((1 - ext) * guard + ext * hit)
    al = _v(0.13, m.ankle_h, 0.12) * _v(m.s, 1, m.s)
    ar = _v(-0.13, m.ankle_h, -0.10) * _v(m.s, 1, m.s)
    return PersonPose(hand_l=hands[0], hand_r=hands[1], ankle_l=al, ankle_r=ar, pelvis=pel,
                      twist=twist, elbow_l=_v(1.0, -1.2, -0.3), elbow_r=_v(-1.0, -1.2, -0.3))


def clapping(m: PersonModel, u: float) -> PersonPose:
    """Clapping in front of the chest, two claps per repetition."""
    phi = u % 1.0
    open_ = _bump(2 * phi)
    sl, sr = m.shoulders(_v(0, 0, 0))
    y = m.pelvis_y + 0.30 * m.s
    hands = [_v(side * (0.05 + 0.2 * open_) * m.s, y, 0.30 * m.s) for side in (1, -1)]
    al, ar = m.standing_ankles(0.12)
    return PersonPose(hand_l=hands[0], hand_r=hands[1], ankle_l=al, ankle_r=ar,
                      elbow_l=_v(1.0, -1.0, -0.2), elbow_r=_v(-1.0, -1.0, -0.2))


ACTIONS: dict[str, Callable[[PersonModel, float], PersonPose]] = {
    'jumping_in_place': jumping_in_place,
    'jumping_jacks': jumping_jacks,
    'waving_two_hands': waving_two_hands,
    'waving_one_hand': waving_one_hand,
    'bending': bending,
    'punching': punching,
    'clapping': clapping,
}


def _style(rng: np.random.Generator, scale: float | None = None) -> PersonStyle:
    shirts = [(0.20, 0.35, 0.70), (0.70, 0.20, 0.20), (0.20, 0.55, 0.30), (0.60, 0.55, 0.20)]
    trousers = [(0.22, 0.22, 0.30), (0.35, 0.30, 0.25), (0.15, 0.20, 0.35)]
    skins = [(0.85, 0.65, 0.52), (0.62, 0.44, 0.32), (0.92, 0.76, 0.64)]
    return PersonStyle(scale=float(rng.uniform(0.96, 1.04)) if scale is None else scale,
                       shirt=shirts[rng.integers(len(shirts))],
                       trousers=trousers[rng.integers(len(trousers))],
                       skin=skins[rng.integers(len(skins))])


def _seq_rng(name: str, seed: int, salt: int = 0) -> np.random.Generator:
    return np.random.default_rng([seed, SEQUENCES.index(name), salt])


def scene(name: str, u: float, seed: int = 0) -> Entity:
    """Sequence ``name`` posed at animation time ``u`` (repetitions), in the scene frame."""
    rng = _seq_rng(name, seed, 1)
    if name in ACTIONS:
        model = PersonModel(_style(rng), texture_base=int(rng.integers(1000)))
        place = Placement(float(rng.uniform(-0.12, 0.12)), -float(rng.uniform(2.85, 3.15)),
                          float(np.deg2rad(rng.uniform(-8, 8))))
        return place.apply(model.build(ACTIONS[name](model, u)))
    if name == 'star':
        e = star_entity(u / REPS * 1.5, 0.5 * np.sin(np.pi * u / REPS),
                        tex=int(rng.integers(1000)))
        return Placement(float(rng.uniform(-0.1, 0.1)), -2.9 + 0.15 * np.sin(np.pi * u),
                         0.15 * np.sin(np.pi * u)).apply(e)
    if name == 'chair':
        yaw = float(rng.uniform(0, 2 * np.pi)) + np.pi * u
        return Placement(0.05, -2.8, yaw).apply(chair(tex=int(rng.integers(1000))))
    if name == 'robot_arm':
        w = 2 * np.pi * u
        q = (0.8 * np.sin(w / 2), 0.6 + 0.5 * np.sin(w), 1.0 + 0.6 * np.sin(w + 1.0),
             0.5 * np.sin(w + 2.0))
        return Placement(-0.35, -2.9, float(rng.uniform(-0.2, 0.2))).apply(
            robot_arm(q, tex=int(rng.integers(1000))))
    if name == 'two_people':
        ma = PersonModel(_style(rng, 1.0), texture_base=int(rng.integers(1000)))
        mb = PersonModel(_style(rng, 0.93), texture_base=int(rng.integers(1000)))
        a = Placement(-0.72, -3.3, np.deg2rad(12)).apply(
            ma.build(waving_one_hand(ma, u, 135, 25)))
        b = Placement(0.68, -2.75, np.deg2rad(-15)).apply(mb.build(clapping(mb, u)))
        b.gt_ids = b.gt_ids + 5
        return merge([a, b])
    msg = f'unknown sequence {name!r}; known: {", ".join(SEQUENCES)}'
    raise KeyError(msg)


def contact_distances(e: Entity) -> dict[str, float]:
    """Gaps (m) of a single person's hands to the torso and to each other (body model)."""
    from .shapes import surface_distance

    p, parts = e.prims, e.parts
    torso = [p[parts[k]] for k in ('chest', 'abdomen', 'pelvis')]
    out = {}
    for side in ('l', 'r'):
        out[f'{side}_hand_torso'] = min(surface_distance(p[parts[f'{side}_hand']], t)
                                        for t in torso)
    out['hand_hand'] = surface_distance(p[parts['l_hand']], p[parts['r_hand']])
    return out
