"""A Biovision Hierarchy (BVH) reader with vectorised forward kinematics.

The HIERARCHY part is a tree of joints, each with an ``OFFSET`` (its origin in the parent's
frame at rest) and ``CHANNELS`` (any subset of ``X/Y/Zposition`` and ``X/Y/Zrotation``, in any
order); ``End Site`` blocks become channel-less joints named ``<parent>_End``. The MOTION part
holds one row of channel values per frame (positions in the file's unit, angles in degrees).

Conventions, as exporters (MotionBuilder, Blender, Credo LifeForms) write them: a position
channel REPLACES that component of the joint's offset (exporters that give every joint six
channels repeat the offset there), and the rotation channels compose in the listed order,
``Zrotation Xrotation Yrotation`` meaning ``R = Rz @ Rx @ Ry`` (``kin.euler_matrix``). Units
and the up axis are not stored in BVH; ``retarget`` infers them from the skeleton.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .kin import F64, MocapError, euler_matrix, forward

_POS = {'xposition': 0, 'yposition': 1, 'zposition': 2}
_ROT = {'xrotation': 'x', 'yrotation': 'y', 'zrotation': 'z'}


@dataclass(frozen=True)
class Bvh:
    """One parsed BVH file.

    ``names``/``parents`` (J,) the joints in file order (parents first, end sites included),
    ``offsets`` (J, 3) rest translations in the file's unit, ``channels`` per joint the channel
    names as written (lower-cased), ``motion`` (T, C) the MOTION rows, ``frame_time`` seconds.
    """

    name: str
    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: F64
    channels: tuple[tuple[str, ...], ...]
    frame_time: float
    motion: F64

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    def index(self, joint: str) -> int:
        try:
            return self.names.index(joint)
        except ValueError:
            msg = f'{self.name}: no joint {joint!r}; joints: {", ".join(self.names)}'
            raise MocapError(msg) from None

    def closure(self, joints: list[str] | None) -> list[int]:
        """Indices of ``joints`` and all their ancestors, in file order (all if None)."""
        if joints is None:
            return list(range(len(self.names)))
        keep: set[int] = set()
        for j in (self.index(n) for n in joints):
            while j >= 0 and j not in keep:
                keep.add(j)
                j = self.parents[j]
        return sorted(keep)

    def local(self, idx: list[int]) -> tuple[F64, F64]:
        """Local rotations (T, n, 3, 3) and translations (T, n, 3) of joints ``idx``."""
        n_frames = len(self.motion)
        trans = np.broadcast_to(self.offsets[idx], (n_frames, len(idx), 3)).copy()
        rot = np.broadcast_to(np.eye(3), (n_frames, len(idx), 3, 3)).copy()
        starts = np.cumsum([0] + [len(c) for c in self.channels])
        by_order: dict[str, tuple[list[int], list[list[int]]]] = {}
        for k, j in enumerate(idx):
            order, cols = '', []
            for c, ch in enumerate(self.channels[j]):
                col = int(starts[j]) + c
                if ch in _POS:
                    trans[:, k, _POS[ch]] = self.motion[:, col]
                else:
                    order += _ROT[ch]
                    cols.append(col)
            if order:
                slot = by_order.setdefault(order, ([], []))
                slot[0].append(k)
                slot[1].append(cols)
        for order, (ks, cols) in by_order.items():
            rot[:, ks] = euler_matrix(order, self.motion[:, np.asarray(cols)])
        return rot, trans

    def forward(self, joints: list[str] | None = None) -> dict[str, tuple[F64, F64]]:
        """Global (rotation (T, 3, 3), position (T, 3)) per joint, in the file's unit and axes.

        Only ``joints`` and their ancestors are computed (all joints if None).
        """
        idx = self.closure(joints)
        pos_in = {j: k for k, j in enumerate(idx)}
        parents = [pos_in.get(self.parents[j], -1) for j in idx]
        rot_l, trans_l = self.local(idx)
        rot, pos = forward(parents, rot_l, trans_l)
        return {self.names[j]: (rot[:, k], pos[:, k]) for k, j in enumerate(idx)}


def _floats(tokens: list[str], where: str) -> F64:
    try:
        return np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError:
        msg = f'{where}: expected numbers, got {" ".join(tokens)!r}'
        raise MocapError(msg) from None


def parse_bvh(text: str, *, name: str = 'bvh') -> Bvh:
    """Parse BVH ``text`` (``name`` is used in error messages only)."""
    head, sep, body = text.partition('MOTION')
    if not sep or 'HIERARCHY' not in head:
        msg = f'{name}: not a BVH file (needs HIERARCHY and MOTION sections)'
        raise MocapError(msg)
    tokens = head.split('HIERARCHY', 1)[1].split()
    names: list[str] = []
    parents: list[int] = []
    offsets: list[F64] = []
    channels: list[tuple[str, ...]] = []
    stack: list[int] = []
    pending = -1
    i = 0
    while i < len(tokens):
        tok = tokens[i]
        low = tok.lower()
        if low in ('root', 'joint') or (low == 'end' and i + 1 < len(tokens)):
            parent = stack[-1] if stack else -1
            if low == 'end':
                if parent < 0:
                    msg = f'{name}: End Site outside any joint'
                    raise MocapError(msg)
                jname = f'{names[parent]}_End'
            else:
                if i + 1 >= len(tokens):
                    msg = f'{name}: {tok} without a name'
                    raise MocapError(msg)
                jname = tokens[i + 1]
            names.append(jname)
            parents.append(parent)
            offsets.append(np.zeros(3))
            channels.append(())
            pending = len(names) - 1
            i += 2
        elif tok == '{':
            if pending < 0:
                msg = f'{name}: "{{" without a joint before it'
                raise MocapError(msg)
            stack.append(pending)
            pending = -1
            i += 1
        elif tok == '}':
            if not stack:
                msg = f'{name}: unbalanced "}}" in HIERARCHY'
                raise MocapError(msg)
            stack.pop()
            i += 1
        elif low == 'offset':
            if not stack:
                msg = f'{name}: OFFSET outside a joint'
                raise MocapError(msg)
            offsets[stack[-1]] = _floats(tokens[i + 1:i + 4], f'{name}: OFFSET')
            i += 4
        elif low == 'channels':
            if not stack:
                msg = f'{name}: CHANNELS outside a joint'
                raise MocapError(msg)
            n = int(_floats(tokens[i + 1:i + 2], f'{name}: CHANNELS count')[0])
            chans = tuple(t.lower() for t in tokens[i + 2:i + 2 + n])
            bad = [c for c in chans if c not in _POS and c not in _ROT]
            if bad or len(chans) != n:
                msg = f'{name}: joint {names[stack[-1]]!r} has bad channels {bad or chans}'
                raise MocapError(msg)
            channels[stack[-1]] = chans
            i += 2 + n
        else:
            msg = f'{name}: unexpected token {tok!r} in HIERARCHY'
            raise MocapError(msg)
    if stack or not names:
        msg = f'{name}: HIERARCHY is empty or its braces are unbalanced'
        raise MocapError(msg)
    frames, frame_time, values = _motion(body, name)
    n_ch = sum(len(c) for c in channels)
    if values.size != frames * n_ch:
        msg = (f'{name}: MOTION has {values.size} numbers, expected {frames} frames x '
               f'{n_ch} channels')
        raise MocapError(msg)
    return Bvh(name, tuple(names), tuple(parents), np.array(offsets), tuple(channels),
               frame_time, values.reshape(frames, n_ch))


def _motion(body: str, name: str) -> tuple[int, float, F64]:
    """Frame count, frame time and the flat channel values of the MOTION section."""
    lines = body.strip().split('\n', 2)
    if len(lines) < 2 or not lines[0].lower().startswith('frames:') \
            or not lines[1].lower().startswith('frame time:'):
        msg = f'{name}: MOTION must start with "Frames:" and "Frame Time:" lines'
        raise MocapError(msg)
    try:
        frames = int(lines[0].split(':', 1)[1])
        frame_time = float(lines[1].split(':', 1)[1])
    except ValueError:
        msg = f'{name}: bad Frames / Frame Time line'
        raise MocapError(msg) from None
    if frames < 1 or not frame_time > 0:
        msg = f'{name}: needs >= 1 frame and a positive frame time, got {frames}, {frame_time}'
        raise MocapError(msg)
    rest = lines[2] if len(lines) > 2 else ''
    try:
        values = np.array(rest.split(), dtype=np.float64)
    except ValueError:
        msg = f'{name}: MOTION rows contain something that is not a number'
        raise MocapError(msg) from None
    return frames, frame_time, values


def read_bvh(path: str | Path) -> Bvh:
    """Read a BVH file."""
    p = Path(path)
    try:
        text = p.read_text(encoding='utf-8', errors='replace')
    except OSError as e:
        msg = f'cannot read BVH file {p}: {e.strerror}'
        raise MocapError(msg) from None
    return parse_bvh(text, name=p.name)
