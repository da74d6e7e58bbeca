"""Retargeting of a source skeleton onto ``JOINTS`` and the normalisation ``MotionClip`` promises.

A source describes every canonical joint by a ``JointSpec`` entry of its joint map:

- ``('joint', name)``: the source joint's position;
- ``('point', name, (x, y, z))``: a fixed point in the joint's frame, in the source's unit (for
  skeletons whose geometry is known, e.g. DeepMimic's head sphere and foot box);
- ``('extend', name, length_m)``: ``length_m`` metres beyond the joint along its incoming bone
  as the joint's OWN rotation turns it (``p + R_joint @ unit(offset_joint) * length``), for
  joints a source lacks (head top, finger tips, toe tips). Using the joint's rotation, not the
  parent's, lets a bent wrist or a nodding head move the derived point;
- ``('mid', a, b, w)``: ``a + w (b - a)`` between two source joints.

``canonical`` applies the unit (metres, cm or inches, inferred from the pose-invariant length
of the ankle-to-head chain); ``normalise`` then, in this order, the up axis (the dominant axis
of the median ankle-to-head vector), the facing (the hips and shoulders of frame 0 point the
person's left to +x), the 30 Hz resampling (linear interpolation of positions) and the origin
(pelvis of frame 0 above the origin, the lowest foot joint of the resampled clip on y = 0).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .clip import JOINT_INDEX, JOINTS
from .kin import F64, MocapError

JointSpec = tuple
#: Frame rate every clip is resampled to, so that the renderer can assume it.
FPS = 30.0
#: Canonical segments whose summed length measures the skeleton (pose-invariant).
_CHAIN = (('l_ankle', 'l_knee'), ('l_knee', 'l_hip'), ('l_hip', 'pelvis'), ('pelvis', 'spine'),
          ('spine', 'chest'), ('chest', 'neck'), ('neck', 'head'))
_FOOT = ('l_ankle', 'l_toe', 'r_ankle', 'r_toe')


def unit_scale(chain_length: float) -> float:
    """Metres per source unit from the ankle-to-head chain length in source units.

    An adult's chain is about 1.3-1.6 m: below 5 it is metres, below 100 inches (about 50-65),
    else centimetres (about 120-165; a child of 1.2 m still has about 100).
    """
    if not np.isfinite(chain_length) or chain_length <= 0:
        msg = f'skeleton has no extent (ankle-to-head chain length {chain_length})'
        raise MocapError(msg)
    if chain_length < 5.0:
        return 1.0
    if chain_length < 100.0:
        return 0.0254
    return 0.01


def canonical(frames: Mapping[str, tuple[F64, F64]], offsets: Mapping[str, F64],
              joint_map: Mapping[str, JointSpec], *, name: str = 'clip',
              scale: float | None = None) -> tuple[F64, float]:
    """Canonical positions (T, len(JOINTS), 3) in metres, still in the source's axes.

    ``frames`` maps a source joint to its global (rotation (T, 3, 3), position (T, 3));
    ``offsets`` a source joint to its rest offset from its parent (source unit); ``scale``
    metres per source unit (inferred with ``unit_scale`` if None). Returns (positions, scale).
    """
    missing = [j for j in JOINTS if j not in joint_map]
    if missing:
        msg = f'{name}: joint map lacks {missing}'
        raise MocapError(msg)

    def src(joint: str) -> tuple[F64, F64]:
        if joint not in frames:
            msg = f'{name}: source has no joint {joint!r} (needed by its joint map)'
            raise MocapError(msg)
        return frames[joint]

    n = len(next(iter(frames.values()))[1])
    out = np.zeros((n, len(JOINTS), 3))
    deferred = []
    for cj in JOINTS:
        spec = joint_map[cj]
        kind = spec[0]
        if kind == 'joint':
            out[:, JOINT_INDEX[cj]] = src(spec[1])[1]
        elif kind == 'point':
            rot, pos = src(spec[1])
            out[:, JOINT_INDEX[cj]] = pos + rot @ np.asarray(spec[2], dtype=np.float64)
        elif kind == 'mid':
            a, b = src(spec[1])[1], src(spec[2])[1]
            out[:, JOINT_INDEX[cj]] = a + float(spec[3]) * (b - a)
        elif kind == 'extend':
            deferred.append(cj)
        else:
            msg = f'{name}: unknown joint spec {spec!r} for {cj}'
            raise MocapError(msg)
    if scale is None:
        seg = [np.linalg.norm(out[:, JOINT_INDEX[a]] - out[:, JOINT_INDEX[b]], axis=1)
               for a, b in _CHAIN]
        scale = unit_scale(float(np.median(np.sum(seg, axis=0))))
    for cj in deferred:
        _, joint, length_m = joint_map[cj]
        rot, pos = src(joint)
        off = np.asarray(offsets.get(joint, np.zeros(3)), dtype=np.float64)
        norm = float(np.linalg.norm(off))
        if norm < 1e-9:
            msg = f'{name}: cannot extend from {joint!r}: it has a zero offset'
            raise MocapError(msg)
        out[:, JOINT_INDEX[cj]] = pos + rot @ (off / norm * (length_m / scale))
    return out * scale, scale


def _rotation_onto(u: F64, v: F64) -> F64:
    """The smallest rotation taking unit vector ``u`` onto unit vector ``v``."""
    c = float(np.dot(u, v))
    if c < -1.0 + 1e-9:
        axis = np.cross(u, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(u, [0.0, 0.0, 1.0])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    w = np.cross(u, v)
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def up_axis(pos: F64) -> F64:
    """Unit source axis (one of +-x, +-y, +-z) pointing up: the dominant axis of the median
    ankle-to-head vector over the clip (robust to a few lying or crouching frames)."""
    ankles = 0.5 * (pos[:, JOINT_INDEX['l_ankle']] + pos[:, JOINT_INDEX['r_ankle']])
    v = np.median(pos[:, JOINT_INDEX['head']] - ankles, axis=0)
    k = int(np.argmax(np.abs(v)))
    axis = np.zeros(3)
    axis[k] = np.sign(v[k]) if v[k] != 0 else 1.0
    return axis


def resample(pos: F64, times: F64, fps: float = FPS) -> F64:
    """Positions (T, J, 3) at ``times`` (s, increasing) linearly resampled to ``fps``."""
    if len(times) != len(pos) or len(pos) < 2 or np.any(np.diff(times) <= 0):
        msg = 'resample needs >= 2 frames with strictly increasing times'
        raise MocapError(msg)
    t = np.arange(0.0, times[-1] - times[0] + 1e-9, 1.0 / fps) + times[0]
    k = np.clip(np.searchsorted(times, t, side='right') - 1, 0, len(times) - 2)
    w = ((t - times[k]) / (times[k + 1] - times[k]))[:, None, None]
    return (1.0 - w) * pos[k] + w * pos[k + 1]


def loop_cycles(pos: F64, times: F64, min_s: float, *, max_gap: float = 0.1,
                blend_s: float = 0.3) -> tuple[F64, F64]:
    """A cyclic motion repeated until it lasts ``min_s`` seconds; positions (T, J, 3), y up.

    Each repetition is the previous one moved by the rigid motion M (a turn about y and a
    horizontal shift, fitted to all joints) that best takes frame 0 onto the last frame, so
    walks go on and turns keep turning. Motion files marked as loops rarely close exactly:
    the remaining gap ``M(frame 0) - last frame`` is faded in over the last ``blend_s`` seconds
    of the cycle (smoothstep), so that cycle k + 1 = M(cycle k) starts where cycle k ends. A
    motion whose gap exceeds ``max_gap`` metres at some joint is not a clean cycle and is
    returned unchanged, as is one already ``min_s`` long.
    """
    period = float(times[-1] - times[0])
    if period <= 0 or period >= min_s:
        return pos, times
    a = pos[0][:, [0, 2]] - pos[0][:, [0, 2]].mean(axis=0)
    b = pos[-1][:, [0, 2]] - pos[-1][:, [0, 2]].mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    r2 = vt.T @ np.diag([1.0, np.linalg.det(vt.T @ u.T)]) @ u.T
    rot = np.array([[r2[0, 0], 0.0, r2[0, 1]], [0.0, 1.0, 0.0], [r2[1, 0], 0.0, r2[1, 1]]])
    c0 = pos[0].mean(axis=0) * [1.0, 0.0, 1.0]
    c1 = pos[-1].mean(axis=0) * [1.0, 0.0, 1.0]

    def move(p: F64) -> F64:
        return (p - c0) @ rot.T + c1

    gap = move(pos[0]) - pos[-1]
    if np.linalg.norm(gap, axis=-1).max() > max_gap:
        return pos, times
    x = np.clip((times - times[-1] + blend_s) / blend_s, 0.0, 1.0)
    cur = pos + (x * x * (3.0 - 2.0 * x))[:, None, None] * gap
    parts, stamps = [cur], [times]
    for k in range(1, int(np.ceil(min_s / period))):
        cur = move(cur)
        parts.append(cur[1:])
        stamps.append(times[1:] + k * period)
    return np.concatenate(parts), np.concatenate(stamps)


def normalise(pos_m: F64, times: F64, *, up: F64 | None = None, fps: float = FPS) -> F64:
    """Canonical positions in metres (source axes) -> the ``MotionClip`` body frame at ``fps``.

    ``up`` is the source's up axis (detected with ``up_axis`` if None).
    """
    up_v = up_axis(pos_m) if up is None else np.asarray(up, dtype=np.float64)
    pos = pos_m @ _rotation_onto(up_v / np.linalg.norm(up_v), np.array([0.0, 1.0, 0.0])).T
    p0 = pos[0]
    left = (p0[JOINT_INDEX['l_hip']] - p0[JOINT_INDEX['r_hip']]
            + p0[JOINT_INDEX['l_shoulder']] - p0[JOINT_INDEX['r_shoulder']])
    left[1] = 0.0
    if np.linalg.norm(left) < 1e-6:
        msg = 'cannot tell the facing: left and right hips/shoulders coincide at frame 0'
        raise MocapError(msg)
    x = left / np.linalg.norm(left)
    y = np.array([0.0, 1.0, 0.0])
    pos = pos @ np.stack([x, y, np.cross(x, y)]).T
    pos = resample(pos, times, fps)
    pos = pos - np.array([pos[0, JOINT_INDEX['pelvis'], 0], 0.0, pos[0, JOINT_INDEX['pelvis'], 2]])
    pos[..., 1] -= pos[:, [JOINT_INDEX[j] for j in _FOOT], 1].min()
    return pos
