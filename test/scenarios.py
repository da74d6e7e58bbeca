"""Short animated capsule scenes for the tracker tests (Section 5 situations of the paper).

Built on :mod:`shapes` (same capsule person, same z-buffer renderer), but with free arm joints so
a pose can be animated frame by frame: a hand touching the torso, clapping hands, a folded arm
that extends, a star whose limb disappears, two people side by side. Frames carry no colour,
so the tracker's predict phase is zero motion; the animations move each hand by a few
centimetres per frame (well below the tracker's similarity scale).

Body frame of a person: x right, y up, z back (away from the camera), metres, floor at y = 0.
The camera looks along +z from ``camera_height``; optical coordinates come from
:func:`shapes.to_optical`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from shapes import K640, Scene, render

from endeff_ros.core.types import RGBDFrame

SHOULDER_Y = 1.42
SHOULDER_X = 0.19
TORSO_R = 0.15
HAND_R = 0.045
#: Surface samples per m^2 (shapes uses 2.5e5; 1.2e5 halves the rendering time and leaves
#: about 1.4 % of a standing person's pixels as isolated holes at full resolution, which the
#: renderer's back-face culling keeps empty rather than showing the back of the body).
DENSITY = 1.2e5

# Arm joints (elbow, wrist, hand centre) in the body frame for the right arm (x > 0); the left
# arm mirrors x. ``arm(...)`` builds one.
Arm = tuple[np.ndarray, np.ndarray, np.ndarray]


def arm(elbow, wrist, hand) -> Arm:
    return (np.asarray(elbow, float), np.asarray(wrist, float), np.asarray(hand, float))


def mirror(a: Arm) -> Arm:
    """The same arm on the other side (x -> -x)."""
    flip = np.array([-1.0, 1.0, 1.0])
    return tuple(j * flip for j in a)  # type: ignore[return-value]


#: Right arm hanging down and out at ~45 degrees, hand well clear of the body.
ARM_OUT = arm([0.38, 1.22, 0.0], [0.55, 1.04, 0.0], [0.60, 0.99, 0.0])
#: Right arm hanging down, hand clear of the hip (shapes.person 'arms_down' pulled in).
ARM_DOWN = arm([0.27, 1.16, 0.0], [0.31, 0.92, 0.0], [0.32, 0.84, 0.0])
#: Right arm straight out sideways (T pose).
ARM_T = arm([0.47, 1.42, 0.0], [0.72, 1.42, 0.0], [0.80, 1.42, 0.0])
#: Right hand flat on the belly, in front of the torso (hand touches the torso surface).
ARM_ON_BELLY = arm([0.33, 1.17, -0.06], [0.14, 1.10, -0.19], [0.05, 1.10, -TORSO_R - HAND_R])
#: Right arm hanging straight down, pressed against the side of the torso and hip (the arm
#: attaches tightly to the torso: the hand is no extreme of the body).
ARM_AT_SIDE = arm([0.21, 1.16, 0.0], [0.205, 0.92, 0.0], [0.205, 0.84, 0.0])
#: Right arm folded: elbow out to the side, hand on the chest (the elbow is the extreme).
ARM_FOLDED = arm([0.42, 1.30, -0.05], [0.16, 1.30, -0.18], [0.07, 1.30, -TORSO_R - HAND_R])


def clap_arm(gap: float) -> Arm:
    """Right arm of a clap in front of the chest: the hand centre is ``gap / 2 + HAND_R`` to
    the right of the midline (``gap`` = distance between the two hand surfaces)."""
    x = gap / 2 + HAND_R
    hand = np.array([x, 1.20, -0.40])
    return arm([0.30, 1.18, -0.12], hand + [0.08, 0.0, 0.02], hand)


def person(right: Arm, left: Arm | None = None, *, x: float = 0.0, z: float = 2.8,
           seed: int = 0, floor: bool = False) -> Scene:
    """A capsule person (as :func:`shapes.person`) with the given arm joints.

    ``left`` defaults to the mirror of ``right``. Tips: head, left hand, right hand, left foot,
    right foot (as :func:`shapes.person`: index 1 is the hand at x < 0).
    """
    left = mirror(right) if left is None else left
    rng = np.random.default_rng(seed)
    s = Scene([], [])

    def w(p):
        p = np.asarray(p, float)
        return np.array([x + p[0], p[1], z + p[2]])

    def cap(a, b, r):
        s.add_capsule(w(a), w(b), r, rng, density=DENSITY)

    cap([0, 0.95, 0], [0, 1.40, 0], TORSO_R)         # torso
    cap([-0.08, 0.98, 0], [0.08, 0.98, 0], 0.13)     # pelvis
    cap([0, 1.45, 0], [0, 1.52, 0], 0.05)            # neck
    cap([0, 1.63, 0], [0, 1.65, 0], 0.10)            # head
    s.tips.append(w([0, 1.64, 0]))
    for side, (el, wr, hand) in ((-1, left), (1, right)):
        sh = [SHOULDER_X * side, SHOULDER_Y, 0]
        cap(sh, el, 0.045)
        cap(el, wr, 0.038)
        cap(wr, hand, HAND_R)
        s.tips.append(w(hand))
    for side in (-1, 1):
        hip, knee, ankle = [0.10 * side, 0.92, 0], [0.13 * side, 0.50, 0], [0.15 * side, 0.09, 0]
        cap(hip, knee, 0.07)
        cap(knee, ankle, 0.05)
        cap([0.15 * side, 0.05, 0.02], [0.15 * side, 0.05, -0.15], 0.045)
    for side in (-1, 1):
        s.tips.append(w([0.15 * side, 0.05, -0.15]))  # the toe end, as a hand's tip is its end
    if floor:
        s.add_floor(rng, density=DENSITY / 4)
    return s


def blend(a: Arm, b: Arm, u: float) -> Arm:
    """Joint-wise linear blend of two arm poses (u = 0: a, u = 1: b), smoothstep-eased."""
    u = float(np.clip(u, 0.0, 1.0))
    u = u * u * (3 - 2 * u)
    return tuple((1 - u) * ja + u * jb for ja, jb in zip(a, b))  # type: ignore[return-value]


def ramp(a: Arm, b: Arm, n: int) -> list[Arm]:
    """``n`` poses strictly after ``a`` up to and including ``b``."""
    return [blend(a, b, (k + 1) / n) for k in range(n)]


@dataclass(frozen=True)
class Shot:
    """One rendered frame of an animation with its ground-truth tips (optical frame)."""

    frame: RGBDFrame
    tips: np.ndarray
    label: str = ''


def shoot(scene: Scene, index: int, *, camera_height: float = 1.1, label: str = '') -> Shot:
    depth, tips = render(scene, camera_height=camera_height, seed=index)
    frame = RGBDFrame(stamp_ns=index * 33_333_334, frame_id='camera', depth=depth,
                      intrinsics=K640)
    return Shot(frame, tips, label)


def touch_torso(n_move: int = 8, n_contact: int = 3, n_hold: int = 2, contact: Arm = ARM_AT_SIDE
                ) -> list[Shot]:
    """The right arm goes from out (``ARM_OUT``) to the ``contact`` pose in ``n_move`` frames,
    stays ``n_contact`` frames, and goes back.

    Labels: 'out' (arm out), 'in'/'back' (moving), 'contact'.
    """
    poses = [(ARM_OUT, 'out')] * n_hold
    poses += [(p, 'in') for p in ramp(ARM_OUT, contact, n_move)][:-1]
    poses += [(contact, 'contact')] * n_contact
    poses += [(p, 'back') for p in ramp(contact, ARM_OUT, n_move)][:-1]
    poses += [(ARM_OUT, 'out')] * n_hold
    # Only the right arm moves; the left one stays out.
    return [shoot(person(p, mirror(ARM_OUT), seed=i), i, label=lab)
            for i, (p, lab) in enumerate(poses)]


def clap(n_move: int = 8, n_contact: int = 3, n_hold: int = 2, open_gap: float = 0.5
         ) -> list[Shot]:
    """Both hands come together in front of the chest, touch for ``n_contact`` frames, and
    separate again. Labels: 'open', 'closing', 'contact', 'opening'."""
    gaps = [(open_gap, 'open')] * n_hold
    gaps += [(open_gap * (1 - (k + 1) / n_move), 'closing') for k in range(n_move - 1)]
    gaps += [(0.0, 'contact')] * n_contact
    gaps += [(open_gap * (k + 1) / n_move, 'opening') for k in range(n_move - 1)]
    gaps += [(open_gap, 'open')] * n_hold
    return [shoot(person(clap_arm(g), seed=i), i, label=lab) for i, (g, lab) in enumerate(gaps)]


def unfold(n_folded: int = 1, n_move: int = 4, n_hold: int = 8) -> list[Shot]:
    """The right arm starts folded (hand on the chest, elbow out), extends to the T pose and
    stays there. The left arm hangs out. Labels: 'folded', 'moving', 'extended'."""
    poses = [(ARM_FOLDED, 'folded')] * n_folded
    poses += [(p, 'moving') for p in ramp(ARM_FOLDED, ARM_T, n_move)][:-1]
    poses += [(ARM_T, 'extended')] * n_hold
    return [shoot(person(p, mirror(ARM_OUT), seed=i), i, label=lab)
            for i, (p, lab) in enumerate(poses)]


def star(n_limbs: int, *, z: float = 2.5, length: float = 0.45, seed: int = 0,
         keep: tuple[int, ...] | None = None) -> Scene:
    """:func:`shapes.star` with only the limbs in ``keep`` (all by default); ``tips`` lists
    the kept limbs' tips, in limb order."""
    rng = np.random.default_rng(seed)
    s = Scene([], [])
    centre = np.array([0.0, 1.2, z])
    s.add_capsule(centre, centre, 0.14, rng)
    for i in range(n_limbs):
        if keep is not None and i not in keep:
            continue
        ang = 2 * np.pi * i / n_limbs + 0.3
        tip = centre + np.array([np.cos(ang), np.sin(ang), 0.0]) * length
        s.add_capsule(centre, tip, 0.045, rng)
        s.tips.append(tip)
    return s


def star_limb_vanishes(n_before: int = 3, n_after: int = 8, n_limbs: int = 5,
                       gone: int = 0) -> list[Shot]:
    """A star with ``n_limbs`` limbs; limb ``gone`` is removed from frame ``n_before`` on."""
    keep = tuple(i for i in range(n_limbs) if i != gone)
    shots = [shoot(star(n_limbs, seed=i), i, label='all') for i in range(n_before)]
    shots += [shoot(star(n_limbs, seed=i, keep=keep), i, label='gone')
              for i in range(n_before, n_before + n_after)]
    return shots


def star_tip(n_limbs: int, limb: int, *, z: float = 2.5, length: float = 0.45,
             camera_height: float = 1.1) -> np.ndarray:
    """Optical-frame position of limb ``limb``'s tip of :func:`star`."""
    from shapes import to_optical

    ang = 2 * np.pi * limb / n_limbs + 0.3
    tip = np.array([0.0, 1.2, z]) + np.array([np.cos(ang), np.sin(ang), 0.0]) * length
    return to_optical(tip, camera_height)[0]


def two_people(n: int = 4, spacing: float = 1.0) -> list[Shot]:
    """Two people ``spacing`` apart (x = -spacing/2 and +spacing/2), arms hanging down, still
    (facing hands ``spacing - 0.73`` m apart). Tips: the left person's five, then the right
    person's five."""
    shots = []
    for i in range(n):
        a = person(ARM_DOWN, x=-spacing / 2, seed=2 * i)
        b = person(ARM_DOWN, x=spacing / 2, seed=2 * i + 1, floor=False)
        shots.append(shoot(a + b, i))
    return shots


def hand_to_side(n_before: int = 3, n_after: int = 8) -> list[Shot]:
    """The right hand hangs clear of the body (``ARM_DOWN``) for ``n_before`` frames, then is
    pressed against the side of the torso (``ARM_AT_SIDE``, 12 cm inwards in one frame) and
    stays there. Labels: 'free', 'pressed'."""
    poses = [(ARM_DOWN, 'free')] * n_before + [(ARM_AT_SIDE, 'pressed')] * n_after
    return [shoot(person(p, mirror(ARM_OUT), seed=i), i, label=lab)
            for i, (p, lab) in enumerate(poses)]


def still(right: Arm = ARM_T, n: int = 6) -> list[Shot]:
    """A person standing still (``right`` arm, mirrored left); only the surface sampling (and so
    the depth image's fine detail) changes from frame to frame."""
    return [shoot(person(right, seed=i), i, label='still') for i in range(n)]
