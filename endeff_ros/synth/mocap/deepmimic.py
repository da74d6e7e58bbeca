"""Reader of DeepMimic ``humanoid3d`` motions (the format pybullet_data ships under data/motions).

A motion file is JSON: ``{"Loop": ..., "Frames": [[...], ...]}``; each frame row holds 44
numbers: the frame's duration (s), the root position (m, y up), the root orientation as a
quaternion (w, x, y, z), then the local rotation of every joint of ``JOINTS`` below, a
quaternion (w, x, y, z) for a spherical joint and one angle (rad, about the joint's z axis) for
a revolute one (knees, elbows). The wrists are fixed joints and have no column.

The skeleton is the humanoid3d character (DeepMimic's ``humanoid3d.txt``; pybullet's
``humanoid/humanoid.urdf`` holds the same tree at 4x scale and loads it with
``globalScaling=0.25``). ``OFFSETS`` are its joint origins in the parent's frame in metres;
the character faces +x, y is up, its left side is -z.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .kin import F64, MocapError, forward, quat_matrix

#: (joint, parent, kind) in file-column order; kind: 'root', 'sphere' (4 columns), 'revolute'
#: (1 column) or 'fixed' (no column).
JOINTS: tuple[tuple[str, str, str], ...] = (
    ('root', '', 'root'),
    ('chest', 'root', 'sphere'),
    ('neck', 'chest', 'sphere'),
    ('right_hip', 'root', 'sphere'),
    ('right_knee', 'right_hip', 'revolute'),
    ('right_ankle', 'right_knee', 'sphere'),
    ('right_shoulder', 'chest', 'sphere'),
    ('right_elbow', 'right_shoulder', 'revolute'),
    ('right_wrist', 'right_elbow', 'fixed'),
    ('left_hip', 'root', 'sphere'),
    ('left_knee', 'left_hip', 'revolute'),
    ('left_ankle', 'left_knee', 'sphere'),
    ('left_shoulder', 'chest', 'sphere'),
    ('left_elbow', 'left_shoulder', 'revolute'),
    ('left_wrist', 'left_elbow', 'fixed'),
)

#: Joint origins in the parent joint's frame (m): humanoid3d's AttachX/Y/Z, equal to the URDF
#: joint origins divided by its scale of 4.
OFFSETS: dict[str, tuple[float, float, float]] = {
    'root': (0.0, 0.0, 0.0),
    'chest': (0.0, 0.236151, 0.0),
    'neck': (0.0, 0.223894, 0.0),
    'right_hip': (0.0, 0.0, 0.084887),
    'right_knee': (0.0, -0.421546, 0.0),
    'right_ankle': (0.0, -0.40987, 0.0),
    'right_shoulder': (-0.02405, 0.2435, 0.18311),
    'right_elbow': (0.0, -0.274788, 0.0),
    'right_wrist': (0.0, -0.258947, 0.0),
    'left_hip': (0.0, 0.0, -0.084887),
    'left_knee': (0.0, -0.421546, 0.0),
    'left_ankle': (0.0, -0.40987, 0.0),
    'left_shoulder': (-0.02405, 0.2435, -0.18311),
    'left_elbow': (0.0, -0.274788, 0.0),
    'left_wrist': (0.0, -0.258947, 0.0),
}

NAMES: tuple[str, ...] = tuple(j[0] for j in JOINTS)


class Motion(NamedTuple):
    """A parsed motion: frame ``times`` (T,) s; per joint of ``NAMES`` the global rotations
    ``rot`` (T, J, 3, 3) and positions ``pos`` (T, J, 3) m (DeepMimic axes: y up, the character
    facing +x); ``wrap`` if the file says the motion loops (its last frame ends a cycle that
    the first frame starts again, moved along)."""

    times: F64
    rot: F64
    pos: F64
    wrap: bool
N_COLUMNS = 1 + 3 + 4 + sum({'sphere': 4, 'revolute': 1}.get(k, 0) for _, _, k in JOINTS[1:])


def parse_deepmimic(text: str, *, name: str = 'motion') -> Motion:
    """Parse a humanoid3d motion (JSON text) and run its forward kinematics."""
    try:
        data = json.loads(text)
        frames = np.asarray(data['Frames'], dtype=np.float64)
    except (ValueError, KeyError, TypeError) as e:
        msg = f'{name}: not a DeepMimic motion (JSON with a "Frames" list of rows): {e}'
        raise MocapError(msg) from None
    if frames.ndim != 2 or frames.shape[1] != N_COLUMNS or len(frames) < 2:
        msg = (f'{name}: frames must be rows of {N_COLUMNS} numbers (humanoid3d), '
               f'got shape {frames.shape}')
        raise MocapError(msg)
    if not np.all(np.isfinite(frames)) or np.any(frames[:-1, 0] <= 0):
        msg = f'{name}: non-finite values or non-positive frame durations'
        raise MocapError(msg)
    n = len(frames)
    times = np.concatenate([[0.0], np.cumsum(frames[:-1, 0])])
    rot = np.broadcast_to(np.eye(3), (n, len(JOINTS), 3, 3)).copy()
    trans = np.broadcast_to(np.array([OFFSETS[j] for j in NAMES]), (n, len(JOINTS), 3)).copy()
    trans[:, 0] = frames[:, 1:4]
    rot[:, 0] = quat_matrix(frames[:, 4:8])
    col = 8
    for j, (_, _, kind) in enumerate(JOINTS[1:], start=1):
        if kind == 'sphere':
            rot[:, j] = quat_matrix(frames[:, col:col + 4])
            col += 4
        elif kind == 'revolute':
            c, s = np.cos(frames[:, col]), np.sin(frames[:, col])
            rot[:, j, 0, 0], rot[:, j, 0, 1], rot[:, j, 1, 0], rot[:, j, 1, 1] = c, -s, s, c
            col += 1
    parents = [NAMES.index(p) if p else -1 for _, p, _ in JOINTS]
    grot, gpos = forward(parents, rot, trans)
    return Motion(times, grot, gpos, str(data.get('Loop', '')).lower() == 'wrap')


def read_deepmimic(path: str | Path) -> Motion:
    """``parse_deepmimic`` of a file."""
    p = Path(path)
    try:
        text = p.read_text(encoding='utf-8')
    except OSError as e:
        msg = f'cannot read DeepMimic motion {p}: {e.strerror}'
        raise MocapError(msg) from None
    return parse_deepmimic(text, name=p.name)
