"""Short animated scenes for the tracker tests (Section 5 situations of the paper).

Built with :mod:`endeff_ros.synth.scenes` (the suites' person model and ray caster): a person
whose right arm is posed frame by frame (a hand touching the torso, clapping hands, a folded
arm that extends, a hand pressed to the side), a star whose limb disappears, two people side by
side. Frames carry no colour, so the tracker's predict phase is zero motion; the animations
move each hand by a few centimetres per frame (well below the tracker's similarity scale).
People and stars float on no floor (the tracker's cases, not floor removal, are tested here),
except the two people, who stand on one.

Body frame of a person as in ``endeff_ros.synth.body``: x its left (the camera's right), y up,
z its front (towards the camera), metres, floor at y = 0. Ground truth (the parts' centres):
head, left hand, right hand, left foot, right foot; the right hand (x < 0) is the one that moves.
"""

from __future__ import annotations

import numpy as np

from endeff_ros.synth import scenes
from endeff_ros.synth.body import PersonModel, PersonPose, merge
from endeff_ros.synth.scenes import Shot

MODEL = PersonModel()
SHOULDER_L, SHOULDER_R = MODEL.shoulders(np.zeros(3))
ANKLES = MODEL.standing_ankles(0.12)
#: How far (m) the chest (at 1.30 m) reaches in front of the body axis, and the hand's half
#: thickness there (its palm faces the body): a hand at the sum touches it.
CHEST_FRONT, HAND_HALF = 0.105, 0.055
#: Frame period (ns) of the animations: 30 Hz.
PERIOD_NS = 33_333_334

# A right arm is (hand centre, elbow pole direction) in the body frame (``body.PersonPose``);
# ``mirror`` gives the left one.
Arm = tuple[np.ndarray, np.ndarray]


def arm(hand, pole) -> Arm:
    return (np.asarray(hand, float), np.asarray(pole, float))


def mirror(a: Arm) -> Arm:
    """The same arm on the other side (x -> -x)."""
    flip = np.array([-1.0, 1.0, 1.0])
    return (a[0] * flip, a[1] * flip)


def _raised(abduction_deg: float, frac: float) -> Arm:
    hand = MODEL.arm_target(SHOULDER_R, -1, np.deg2rad(abduction_deg), 0.0, frac)
    return arm(hand, [-0.3, -0.2, -1.0])


#: Right arm hanging down and out at 45 degrees, hand well clear of the body.
ARM_OUT = _raised(45.0, 0.95)
#: Right arm hanging down, hand clear of the hip (``scenes.person``'s 'arms_down').
ARM_DOWN = _raised(14.0, 0.99)
#: Right arm straight out sideways (T pose).
ARM_T = _raised(90.0, 0.99)
#: Right arm hanging straight down (at 0.99 of its reach), the hand pressed against the side of
#: the thigh (the arm attaches tightly to the body: the hand is no extreme of it).
ARM_AT_SIDE = arm([-0.205, 0.79, 0.0], [0.0, 0.0, -1.0])
#: Right arm folded: elbow out to the side, hand on the chest (the elbow is the extreme).
ARM_FOLDED = arm([-0.07, 1.30, CHEST_FRONT + HAND_HALF - 0.005], [-1.0, 0.0, 0.0])


#: Where the clapping hands meet: height (m), distance in front of the body axis (m), and the
#: elbows' pole (elbows out sideways, a little down and back).
CLAP = (1.20, 0.35, (-1.0, -0.2, -0.2))


def clap_arm(gap: float, clap: tuple = CLAP) -> Arm:
    """Right arm of a clap in front of the chest (``clap`` as ``CLAP``): the hands touch at
    ``gap`` = 0 (palms 0.05 m from the midline, as in the 'clapping' sequence) and are ``gap``
    m further apart."""
    height, front, pole = clap
    return arm([-(0.05 + gap / 2), height, front], pole)


def person(right: Arm, left: Arm | None = None, *, x: float = 0.0, z: float = -2.8):
    """The person with the given right arm (``left`` defaults to its mirror), ``z`` m from
    the camera, standing at ``x``."""
    left = mirror(right) if left is None else left
    pose = PersonPose(hand_l=left[0], hand_r=right[0], ankle_l=ANKLES[0], ankle_r=ANKLES[1],
                      elbow_l=left[1], elbow_r=right[1])
    return scenes.person(pose, x=x, z=z, model=MODEL)


def shoot(entity, index: int, *, floor: bool = False, label: str = '') -> Shot:
    return scenes.shoot(entity, floor=floor, stamp_ns=index * PERIOD_NS, label=label)


def blend(a: Arm, b: Arm, u: float) -> Arm:
    """Linear blend of two arm poses (u = 0: a, u = 1: b), smoothstep-eased."""
    u = float(np.clip(u, 0.0, 1.0))
    u = u * u * (3 - 2 * u)
    return ((1 - u) * a[0] + u * b[0], (1 - u) * a[1] + u * b[1])


def ramp(a: Arm, b: Arm, n: int) -> list[Arm]:
    """``n`` poses strictly after ``a`` up to and including ``b``."""
    return [blend(a, b, (k + 1) / n) for k in range(n)]


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
    return [shoot(person(p, mirror(ARM_OUT)), i, label=lab) for i, (p, lab) in enumerate(poses)]


def clap(n_move: int = 8, n_contact: int = 3, n_hold: int = 2, open_gap: float = 0.5,
         clap: tuple = CLAP) -> list[Shot]:
    """Both hands come together in front of the chest (``clap_arm``), touch for ``n_contact``
    frames, and separate again. Labels: 'open', 'closing', 'contact', 'opening'."""
    gaps = [(open_gap, 'open')] * n_hold
    gaps += [(open_gap * (1 - (k + 1) / n_move), 'closing') for k in range(n_move - 1)]
    gaps += [(0.0, 'contact')] * n_contact
    gaps += [(open_gap * (k + 1) / n_move, 'opening') for k in range(n_move - 1)]
    gaps += [(open_gap, 'open')] * n_hold
    return [shoot(person(clap_arm(g, clap)), i, label=lab) for i, (g, lab) in enumerate(gaps)]


def unfold(n_folded: int = 1, n_move: int = 4, n_hold: int = 8) -> list[Shot]:
    """The right arm starts folded (hand on the chest, elbow out), extends to the T pose and
    stays there. The left arm hangs out. Labels: 'folded', 'moving', 'extended'."""
    poses = [(ARM_FOLDED, 'folded')] * n_folded
    poses += [(p, 'moving') for p in ramp(ARM_FOLDED, ARM_T, n_move)][:-1]
    poses += [(ARM_T, 'extended')] * n_hold
    return [shoot(person(p, mirror(ARM_OUT)), i, label=lab) for i, (p, lab) in enumerate(poses)]


#: The tracker tests' star: 0.45 m from the hub centre to a limb's end cap, so a vanished
#: limb's old end lies 0.31 m from the hub's surface.
STAR_LENGTH = 0.45


def star_limb_vanishes(n_before: int = 3, n_after: int = 8, n_limbs: int = 5,
                       gone: int = 0) -> list[Shot]:
    """A star with ``n_limbs`` limbs; limb ``gone`` is removed from frame ``n_before`` on."""
    keep = tuple(i for i in range(n_limbs) if i != gone)
    shots = [shoot(scenes.star(n_limbs, length=STAR_LENGTH), i, label='all')
             for i in range(n_before)]
    shots += [shoot(scenes.star(n_limbs, keep=keep, length=STAR_LENGTH), i, label='gone')
              for i in range(n_before, n_before + n_after)]
    return shots


def star_tip(n_limbs: int, limb: int) -> np.ndarray:
    """Optical-frame ground truth of limb ``limb``'s end of :func:`star_limb_vanishes`."""
    return shoot(scenes.star(n_limbs, length=STAR_LENGTH), 0).gt[limb]


def two_people(n: int = 4, spacing: float = 1.0) -> list[Shot]:
    """Two people ``spacing`` apart (x = -spacing/2 and +spacing/2), arms hanging down, still,
    on the floor. Ground truth: the left person's five, then the right person's five."""
    a = person(ARM_DOWN, x=-spacing / 2)
    b = person(ARM_DOWN, x=spacing / 2)
    b.gt_ids = b.gt_ids + 5
    both = merge([a, b])
    return [shoot(both, i, floor=True) for i in range(n)]


def hand_to_side(n_before: int = 3, n_after: int = 8) -> list[Shot]:
    """The right hand hangs clear of the body (``ARM_DOWN``) for ``n_before`` frames, then is
    pressed against the side of the thigh (``ARM_AT_SIDE``, 13 cm inwards in one frame) and
    stays there. Labels: 'free', 'pressed'."""
    poses = [(ARM_DOWN, 'free')] * n_before + [(ARM_AT_SIDE, 'pressed')] * n_after
    return [shoot(person(p, mirror(ARM_OUT)), i, label=lab) for i, (p, lab) in enumerate(poses)]


def still(right: Arm = ARM_T, n: int = 6) -> list[Shot]:
    """A person standing still (``right`` arm, mirrored left): the same depth image in every
    frame."""
    return [shoot(person(right), i, label='still') for i in range(n)]
