"""The motion sources: their joint maps onto ``JOINTS`` and one loader per file format.

Each source names its skeleton's joints differently and lacks some canonical joints; the maps
below say, per canonical joint, which source joint it is or how it is derived (see
``retarget``). Derived joints, with the reason for each length:

- DeepMimic (humanoid3d): the character has no hand, head or toe joints. ``head`` is the bottom
  and ``head_top`` the top of its head sphere (centre 0.175 m above the neck joint, radius
  0.1025 m); ``*_toe`` the front of its foot box at 4.5 cm below the ankle; ``*_hand_end`` 10
  cm beyond the wrist along the forearm (its hand is a 4 cm sphere at the wrist: a real 18 cm
  hand would sink into the floor when it crawls on its hands); ``chest`` is 12 cm up its chest
  segment, whose joint (our ``spine``) sits at the waist.
- Bandai Namco: end sites have zero length, so ``head_top`` is 20 cm beyond ``Head`` (skull
  base to crown), ``*_hand_end`` 18 cm beyond ``Hand_*`` (a hand's length) and ``*_toe`` 5 cm
  beyond ``Toes_*`` (ball of the foot to the toe tip), each turned by that joint's rotation.
- CMU (the iClone conversion): zero-length end sites too; ``head_top`` 20 cm beyond
  ``CC_Base_Head``, ``*_hand_end`` 2 cm beyond the middle finger's last joint, ``*_toe`` 3 cm
  beyond the middle toe's joint.
- ReActIdle (a Rigify-style skeleton): no hand joint, so ``*_wrist`` is the forearm's end site
  and ``*_hand_end`` 18 cm beyond it; ``head`` is half way from ``neck`` to ``face``;
  ``head_top`` 12 cm beyond ``face`` along the neck; ``spine`` half way up the lower spine.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from . import deepmimic
from .bvh import read_bvh
from .kin import F64, MocapError
from .retarget import JointSpec, canonical, loop_cycles, normalise


def _sided(template: Mapping[str, JointSpec], left: str, right: str) -> dict[str, JointSpec]:
    """Left/right joint specs from one template whose names contain ``{s}``."""
    out: dict[str, JointSpec] = {}
    for side, tag in (('l', left), ('r', right)):
        for cj, spec in template.items():
            out[f'{side}_{cj}'] = tuple(p.format(s=tag) if isinstance(p, str) else p
                                        for p in spec)
    return out


DEEPMIMIC_MAP: dict[str, JointSpec] = {
    'pelvis': ('joint', 'root'),
    'spine': ('joint', 'chest'),
    'chest': ('point', 'chest', (0.0, 0.12, 0.0)),
    'neck': ('joint', 'neck'),
    'head': ('point', 'neck', (0.0, 0.0725, 0.0)),
    'head_top': ('point', 'neck', (0.0, 0.2775, 0.0)),
    **_sided({
        'shoulder': ('joint', '{s}_shoulder'),
        'elbow': ('joint', '{s}_elbow'),
        'wrist': ('joint', '{s}_wrist'),
        'hand_end': ('point', '{s}_wrist', (0.0, -0.10, 0.0)),
        'hip': ('joint', '{s}_hip'),
        'knee': ('joint', '{s}_knee'),
        'ankle': ('joint', '{s}_ankle'),
        'toe': ('point', '{s}_ankle', (0.1335, -0.045, 0.0)),
    }, 'left', 'right'),
}

BANDAI_MAP: dict[str, JointSpec] = {
    'pelvis': ('joint', 'Hips'),
    'spine': ('joint', 'Spine'),
    'chest': ('joint', 'Chest'),
    'neck': ('joint', 'Neck'),
    'head': ('joint', 'Head'),
    'head_top': ('extend', 'Head', 0.20),
    **_sided({
        'shoulder': ('joint', 'UpperArm_{s}'),
        'elbow': ('joint', 'LowerArm_{s}'),
        'wrist': ('joint', 'Hand_{s}'),
        'hand_end': ('extend', 'Hand_{s}', 0.18),
        'hip': ('joint', 'UpperLeg_{s}'),
        'knee': ('joint', 'LowerLeg_{s}'),
        'ankle': ('joint', 'Foot_{s}'),
        'toe': ('extend', 'Toes_{s}', 0.05),
    }, 'L', 'R'),
}

CMU_MAP: dict[str, JointSpec] = {
    'pelvis': ('joint', 'CC_Base_Hip'),
    'spine': ('joint', 'CC_Base_Spine01'),
    'chest': ('joint', 'CC_Base_Spine02'),
    'neck': ('joint', 'CC_Base_NeckTwist01'),
    'head': ('joint', 'CC_Base_Head'),
    'head_top': ('extend', 'CC_Base_Head', 0.20),
    **_sided({
        'shoulder': ('joint', 'CC_Base_{s}_Upperarm'),
        'elbow': ('joint', 'CC_Base_{s}_Forearm'),
        'wrist': ('joint', 'CC_Base_{s}_Hand'),
        'hand_end': ('extend', 'CC_Base_{s}_Mid3', 0.02),
        'hip': ('joint', 'CC_Base_{s}_Thigh'),
        'knee': ('joint', 'CC_Base_{s}_Calf'),
        'ankle': ('joint', 'CC_Base_{s}_Foot'),
        'toe': ('extend', 'CC_Base_{s}_MidToe1', 0.03),
    }, 'L', 'R'),
}

REACTIDLE_MAP: dict[str, JointSpec] = {
    'pelvis': ('joint', 'pelvis'),
    'spine': ('mid', 'spine', 'spine.001', 0.5),
    'chest': ('joint', 'spine.001'),
    'neck': ('joint', 'neck'),
    'head': ('mid', 'neck', 'face', 0.5),
    'head_top': ('extend', 'face', 0.12),
    **_sided({
        'shoulder': ('joint', 'upper_arm.{s}'),
        'elbow': ('joint', 'forearm.{s}'),
        'wrist': ('joint', 'forearm.{s}_End'),
        'hand_end': ('extend', 'forearm.{s}_End', 0.18),
        'hip': ('joint', 'thigh.{s}'),
        'knee': ('joint', 'shin.{s}'),
        'ankle': ('joint', 'foot.{s}'),
        'toe': ('joint', 'foot.{s}_End'),
    }, 'L', 'R'),
}

BVH_MAPS: dict[str, dict[str, JointSpec]] = {
    'bandai': BANDAI_MAP, 'cmu': CMU_MAP, 'reactidle': REACTIDLE_MAP,
}


def _source_joints(joint_map: Mapping[str, JointSpec]) -> list[str]:
    names = []
    for spec in joint_map.values():
        names += [p for p in spec[1:] if isinstance(p, str)]
    return sorted(set(names))


def _trim(times: F64, pos: F64, window: tuple[float, float] | None,
          name: str) -> tuple[F64, F64]:
    if window is None:
        return times, pos
    keep = (times >= times[0] + window[0] - 1e-9) & (times <= times[0] + window[1] + 1e-9)
    if keep.sum() < 2:
        msg = f'{name}: trim window {window} s keeps fewer than 2 frames'
        raise MocapError(msg)
    return times[keep], pos[keep]


def load_bvh_positions(path: str | Path, joint_map: Mapping[str, JointSpec], *,
                       window: tuple[float, float] | None = None, skip: int = 0,
                       up: F64 | None = None) -> F64:
    """A BVH file retargeted and normalised: (T, len(JOINTS), 3) metres, body frame, 30 Hz.

    ``window`` (start, end) s keeps part of the clip, ``skip`` drops leading frames (e.g. a
    T-pose a converter put first), ``up`` overrides the detected up axis.
    """
    bvh = read_bvh(path)
    if skip:
        bvh = type(bvh)(bvh.name, bvh.names, bvh.parents, bvh.offsets, bvh.channels,
                        bvh.frame_time, bvh.motion[skip:])
    frames = bvh.forward(_source_joints(joint_map))
    offsets = {n: bvh.offsets[bvh.index(n)] for n in frames}
    pos, _ = canonical(frames, offsets, joint_map, name=bvh.name)
    times = np.arange(len(pos)) * bvh.frame_time
    times, pos = _trim(times, pos, window, bvh.name)
    return normalise(pos, times, up=up)


def load_deepmimic_positions(path: str | Path, *, window: tuple[float, float] | None = None,
                             loop_s: float | None = None) -> F64:
    """A DeepMimic humanoid3d motion retargeted and normalised (see ``load_bvh_positions``).

    ``loop_s``: a motion the file marks as looping is repeated (``retarget.loop_cycles``)
    until it lasts that long; the others are left as they are.
    """
    motion = deepmimic.read_deepmimic(path)
    frames = {n: (motion.rot[:, k], motion.pos[:, k]) for k, n in enumerate(deepmimic.NAMES)}
    offsets = {n: np.asarray(deepmimic.OFFSETS[n]) for n in deepmimic.NAMES}
    cpos, _ = canonical(frames, offsets, DEEPMIMIC_MAP, name=Path(path).name, scale=1.0)
    times = motion.times
    if loop_s is not None and motion.wrap:
        cpos, times = loop_cycles(cpos, times, loop_s)
    times, cpos = _trim(times, cpos, window, Path(path).name)
    return normalise(cpos, times, up=np.array([0.0, 1.0, 0.0]))
