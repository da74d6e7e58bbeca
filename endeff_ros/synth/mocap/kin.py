"""Rotations and forward kinematics shared by the mocap readers, vectorised over frames.

Every reader turns its file into a joint tree (``parents``, parents listed before children) with
per-frame local rotations ``(T, J, 3, 3)`` and local translations ``(T, J, 3)``. ``forward``
then walks the tree one depth level at a time, so a level of joints is one batched matrix
product over all frames instead of a loop over frames.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]


class MocapError(ValueError):
    """A motion file or a retargeting request is malformed; the message says what and where."""


def axis_rotation(axis: str, angle_rad: F64) -> F64:
    """Rotation matrices ``(..., 3, 3)`` about the coordinate ``axis`` ('x', 'y' or 'z')."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    one, zero = np.ones_like(c), np.zeros_like(c)
    if axis == 'x':
        rows = ((one, zero, zero), (zero, c, -s), (zero, s, c))
    elif axis == 'y':
        rows = ((c, zero, s), (zero, one, zero), (-s, zero, c))
    elif axis == 'z':
        rows = ((c, -s, zero), (s, c, zero), (zero, zero, one))
    else:
        msg = f'rotation axis must be x, y or z, got {axis!r}'
        raise MocapError(msg)
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def euler_matrix(order: str, angles_deg: F64) -> F64:
    """Rotation ``R_a @ R_b @ R_c`` for ``order`` 'abc' and angles ``(..., len(order))`` (deg).

    This is BVH's convention: channels listed as ``Zrotation Xrotation Yrotation`` mean
    ``v_parent = Rz @ Rx @ Ry @ v_child`` (intrinsic rotations in the listed order).
    """
    ang = np.radians(np.asarray(angles_deg, dtype=np.float64))
    out = np.broadcast_to(np.eye(3), (*ang.shape[:-1], 3, 3)).copy()
    for k, axis in enumerate(order):
        out = out @ axis_rotation(axis, ang[..., k])
    return out


def quat_matrix(q_wxyz: F64) -> F64:
    """Rotation matrices ``(..., 3, 3)`` of quaternions ``(..., 4)`` given as (w, x, y, z).

    Quaternions are normalised first: motion files store them rounded.
    """
    q = np.asarray(q_wxyz, dtype=np.float64)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-9):
        msg = 'a quaternion has zero length'
        raise MocapError(msg)
    w, x, y, z = np.moveaxis(q / norm, -1, 0)
    rows = (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def depths(parents: list[int]) -> npt.NDArray[np.int64]:
    """Depth of every joint in the tree (roots have depth 0); parents must precede children."""
    d = np.zeros(len(parents), dtype=np.int64)
    for j, p in enumerate(parents):
        if p >= j:
            msg = f'joint {j} lists parent {p}: parents must come before their children'
            raise MocapError(msg)
        d[j] = 0 if p < 0 else d[p] + 1
    return d


def forward(parents: list[int], local_rot: F64, local_trans: F64) -> tuple[F64, F64]:
    """Global rotations ``(T, J, 3, 3)`` and positions ``(T, J, 3)`` of a joint tree.

    ``local_trans[:, j]`` is joint j's origin in its parent's frame, ``local_rot[:, j]`` the
    rotation of joint j's frame relative to its parent's frame; a root's values are global.
    ``p_j = p_parent + R_parent @ t_j`` and ``R_j = R_parent @ r_j``, one depth level at a time.
    """
    par = np.asarray(parents, dtype=np.int64)
    dep = depths(parents)
    rot = np.array(local_rot, dtype=np.float64, copy=True)
    pos = np.array(local_trans, dtype=np.float64, copy=True)
    for level in range(1, int(dep.max(initial=0)) + 1):
        idx = np.flatnonzero(dep == level)
        pr = rot[:, par[idx]]
        pos[:, idx] = pos[:, par[idx]] + np.einsum('tjab,tjb->tja', pr, local_trans[:, idx])
        rot[:, idx] = pr @ local_rot[:, idx]
    return rot, pos
