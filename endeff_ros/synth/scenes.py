"""Single scenes with known end-effectors, ray-cast into one ideal depth frame, for the core's
tests and examples (the benchmark suites build theirs in ``sequences.py`` and ``suite.py``).

The entities are the suites' own (``body.PersonModel``, ``body.chair``, ``body.robot_arm``) plus
a flat star with any number of limbs; ``shoot`` renders one with ``render.render`` (the same
ray caster as the bags) and returns the depth as an ``RGBDFrame`` with the entity's ground
truth in the optical frame: the CENTRE of each terminal part (head, palm, shoe, the cap of a
star limb, a chair leg's foot, the gripper), as in ``docs/benchmark-bags.md``. The depth is the
ideal one (no sensor model): what the core does with a surface, not with a sensor's noise.

Scene frame as in ``body.py``: x to the camera's right, y up, z towards the camera, floor at
y = 0, metres; an entity placed at ``z = -2.8`` stands 2.8 m in front of the camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from ..core.types import KINECT_640, RGBDFrame
from .body import Entity, PersonModel, PersonPose, Placement, chair, robot_arm, star_limb
from .render import NOTHING, Background, Camera, Rendered, background, render
from .shapes import Primitive, Vec, ellipsoid, rot_x

#: A level camera 1.1 m above the floor (optical axis horizontal): the floor plane is then
#: y = 1.1 in the optical frame and its normal (0, -1, 0).
LEVEL = Camera(KINECT_640, height=1.1, pitch=0.0, frame_id='camera')

#: Person poses of :func:`person`: hands by abduction (deg, 0 = hanging) and fraction of reach.
POSES = {'t_pose': (90.0, 0.99), 'arms_down': (14.0, 0.99)}


@dataclass(frozen=True)
class Shot:
    """One rendered scene: ``frame`` (depth only, NaN = no surface), ``gt`` (M, 3) ground truth
    in the optical frame (m), ``gt_visible`` (M,) whether each end-effector's own part is what
    the camera sees at (or 1 px around) its projection, ``gt_prims`` (M,) the index in
    ``prims`` of each end-effector's terminal part, ``prims`` the entity's primitives in the
    optical frame, ``label`` free text (an animation step's name)."""

    frame: RGBDFrame
    gt: Vec
    gt_visible: npt.NDArray[np.bool_]
    gt_prims: npt.NDArray[np.int64]
    prims: tuple[Primitive, ...]
    camera: Camera
    label: str = ''

    def part(self, k: int) -> Primitive:
        """The terminal part (optical frame) of end-effector ``k``."""
        return self.prims[int(self.gt_prims[k])]


@lru_cache(maxsize=4)
def no_background(cam: Camera) -> Background:
    """A view with neither floor nor wall: an entity floating in empty space."""
    bg = background(cam)
    shape = bg.z.shape
    out = Background(np.full(shape, np.inf), np.full(shape, NOTHING, np.int16),
                     np.zeros(shape + (3,), np.float32), np.zeros(shape + (3,), np.float32),
                     bg.view, bg.light)
    for a in (out.z, out.owner, out.normal, out.color):
        a.flags.writeable = False
    return out


def shoot(entity: Entity, cam: Camera = LEVEL, *, floor: bool = True, stamp_ns: int = 0,
          label: str = '') -> Shot:
    """``entity`` (scene frame) ray-cast by ``cam``, with floor and back wall or (``floor``
    False) on nothing."""
    ren: Rendered = render(entity, cam, None if floor else no_background(cam))
    depth = np.where(np.isfinite(ren.z), ren.z, np.nan).astype(np.float32)
    frame = RGBDFrame(stamp_ns, cam.frame_id, depth, cam.intrinsics)
    return Shot(frame, ren.gt, ren.gt_visible, np.asarray(entity.gt_prims, np.int64),
                tuple(ren.prims), cam, label)


def person_pose(model: PersonModel, pose: str) -> PersonPose:
    """A standing person of ``model`` in one of ``POSES``, feet 0.24 m apart."""
    if pose not in POSES:
        msg = f'pose must be one of {sorted(POSES)}, got {pose!r}'
        raise ValueError(msg)
    abduction, reach = POSES[pose]
    sl, sr = model.shoulders(np.zeros(3))
    al, ar = model.standing_ankles(0.12)
    return PersonPose(hand_l=model.arm_target(sl, 1, np.deg2rad(abduction), 0.0, reach),
                      hand_r=model.arm_target(sr, -1, np.deg2rad(abduction), 0.0, reach),
                      ankle_l=al, ankle_r=ar)


def person(pose: str | PersonPose = 't_pose', *, x: float = 0.0, z: float = -2.8,
           yaw: float = 0.0, model: PersonModel | None = None) -> Entity:
    """A person (``body.PersonModel``, 1.75 m) facing the camera from ``z`` m, standing at
    ``x``. Ground truth ids: head, left hand, right hand, left foot, right foot; the person's
    left is the camera's right (x > 0) when ``yaw`` is 0."""
    model = model or PersonModel()
    built = model.build(person_pose(model, pose) if isinstance(pose, str) else pose)
    return Placement(x, z, yaw).apply(built)


def star(n_limbs: int = 5, *, z: float = -2.5, keep: tuple[int, ...] | None = None,
         height: float = 1.2, spin: float = 0.3, length: float = 0.55) -> Entity:
    """A flat star facing the camera: a hub (ellipsoid 0.14 x 0.14 x 0.10 m) ``height`` m up
    with ``n_limbs`` straight limbs in the image plane, limb i at ``spin + 2 pi i / n_limbs``
    rad from the camera's right (counter-clockwise as seen). A limb is built by
    ``body.star_limb``, straight: segments from 0.10 m out, a sphere of radius 0.065 ``length``
    m from the hub centre whose centre is the end-effector (id i; ``length`` 0.55 is
    ``body.star``'s reach). Only the limbs in ``keep`` are built (all by default)."""
    hub = np.array([0.0, height, z])
    color, tex = (0.85, 0.55, 0.15), 40
    prims = [ellipsoid(hub, rot_x(0.0), [0.14, 0.14, 0.10], color, tex, 'hub')]
    gt, ids, gp = [], [], []
    for k in range(n_limbs):
        if keep is not None and k not in keep:
            continue
        a = spin + 2 * np.pi * k / n_limbs
        d = np.array([np.cos(a), np.sin(a), 0.0])
        limb, cap = star_limb(hub, d, d, k, color, tex, outer=length - 0.35)
        gp.append(len(prims) + 2)
        prims.extend(limb)
        gt.append(cap)
        ids.append(k)
    return Entity(prims, np.array(gt).reshape(-1, 3), np.array(ids, np.uint32),
                  np.array(gp, np.int64), np.full(len(gt), 0.065))


def placed_chair(yaw: float = 0.5, *, x: float = 0.0, z: float = -2.4) -> Entity:
    """``body.chair`` standing at (``x``, ``z``), turned by ``yaw`` (0: its front faces the
    camera). Ground truth: the four legs' feet (3 cm up), the backrest's top corners."""
    return Placement(x, z, yaw).apply(chair())


def placed_robot_arm(q: npt.ArrayLike = (0.6, 0.7, 1.2, 0.3), *, x: float = -0.3,
                     z: float = -2.6, yaw: float = 0.0) -> Entity:
    """``body.robot_arm`` at joint angles ``q`` on its pedestal at (``x``, ``z``). Ground
    truth: the pedestal's bottom centre (on the floor), the gripper's centre."""
    return Placement(x, z, yaw).apply(robot_arm(q))


def distance_to_part(part: Primitive, points: npt.ArrayLike) -> Vec:
    """Distance (K,) m from ``points`` (K, 3) to the solid ``part`` (0 inside it), in the
    frame both are given in. Exact for boxes and capsules; for an ellipsoid the distance along
    the line to its centre (an upper bound, exact for a sphere)."""
    q = (np.asarray(points, np.float64).reshape(-1, 3) - part.center) @ part.rot
    if part.kind == 'box':
        return np.linalg.norm(np.maximum(np.abs(q) - part.size, 0.0), axis=1)
    if part.kind == 'capsule':
        r, h = part.size[0], part.size[1]
        q[:, 1] -= np.clip(q[:, 1], -h, h)
        return np.maximum(np.linalg.norm(q, axis=1) - r, 0.0)
    scaled = np.linalg.norm(q / part.size, axis=1)
    return np.maximum(np.linalg.norm(q, axis=1) * (1.0 - 1.0 / np.maximum(scaled, 1e-12)), 0.0)
