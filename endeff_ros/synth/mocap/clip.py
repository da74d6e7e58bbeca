"""The motion-capture clip as the rest of the synthetic suite sees it.

Every source format (BVH, DeepMimic text, C3D, ...) is read by its own loader and retargeted onto
one canonical joint set, ``JOINTS``, so that the body model, the views and the renderer never
care where a motion came from. Positions are metres in the project's *body frame* (x the
person's left, y up, z the person's front, floor at y = 0; see ``synth/body.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

#: Canonical joints, in this order along axis 1 of ``MotionClip.positions``. ``head`` is the
#: base of the skull (top of the neck), ``head_top`` the crown; ``*_hand_end`` the end of the
#: longest finger (or the hand's end site); ``*_toe`` the tip of the foot.
JOINTS: tuple[str, ...] = (
    'pelvis', 'spine', 'chest', 'neck', 'head', 'head_top',
    'l_shoulder', 'l_elbow', 'l_wrist', 'l_hand_end',
    'r_shoulder', 'r_elbow', 'r_wrist', 'r_hand_end',
    'l_hip', 'l_knee', 'l_ankle', 'l_toe',
    'r_hip', 'r_knee', 'r_ankle', 'r_toe',
)
JOINT_INDEX: dict[str, int] = {name: k for k, name in enumerate(JOINTS)}

#: Motion families used as evaluation attributes (a clip has exactly one).
FAMILIES: tuple[str, ...] = (
    'walk', 'turn', 'run', 'wave', 'gesture', 'punch', 'kick', 'dance', 'squat', 'kneel',
    'bend', 'sit', 'crawl', 'roll', 'jump', 'acrobatic', 'reach', 'other',
)

#: Dataset splits: parameters are chosen on ``dev`` only; ``test`` is reported.
SPLITS: tuple[str, ...] = ('dev', 'test')


@dataclass(frozen=True)
class MotionClip:
    """One motion of one performer, retargeted onto ``JOINTS``.

    ``positions`` (T, len(JOINTS), 3) float64, metres, body frame: at frame 0 the pelvis stands
    above the origin (x = z = 0) and the performer faces +z (``l_hip - r_hip`` points to +x);
    the lowest foot joint over the clip touches y = 0. ``fps`` is the frame rate of
    ``positions``. ``source`` names the dataset (one licence per source), ``family`` is one of
    ``FAMILIES``, ``split`` one of ``SPLITS`` (fixed per clip, stored in the catalogue code).
    """

    name: str
    source: str
    family: str
    split: str
    fps: float
    positions: npt.NDArray[np.float64]
    licence: str = ''

    def __post_init__(self) -> None:
        pos = self.positions
        if pos.ndim != 3 or pos.shape[1:] != (len(JOINTS), 3) or len(pos) < 2:
            msg = (f'clip {self.name!r}: positions must be (T >= 2, {len(JOINTS)}, 3), '
                   f'got {pos.shape}')
            raise ValueError(msg)
        if not np.all(np.isfinite(pos)):
            msg = f'clip {self.name!r}: positions contain NaN or inf'
            raise ValueError(msg)
        if self.family not in FAMILIES:
            msg = f'clip {self.name!r}: unknown family {self.family!r}; known: {FAMILIES}'
            raise ValueError(msg)
        if self.split not in SPLITS:
            msg = f'clip {self.name!r}: split must be one of {SPLITS}, got {self.split!r}'
            raise ValueError(msg)
        if not self.fps > 0:
            msg = f'clip {self.name!r}: fps must be positive, got {self.fps}'
            raise ValueError(msg)

    @property
    def duration_s(self) -> float:
        """Length of the clip in seconds."""
        return (len(self.positions) - 1) / self.fps

    def joint(self, name: str) -> npt.NDArray[np.float64]:
        """Trajectory (T, 3) of joint ``name``."""
        return self.positions[:, JOINT_INDEX[name]]

    def at(self, t_s: float) -> npt.NDArray[np.float64]:
        """Joint positions (len(JOINTS), 3) at time ``t_s`` (s), linearly interpolated, clamped."""
        x = float(np.clip(t_s * self.fps, 0.0, len(self.positions) - 1))
        i = min(int(x), len(self.positions) - 2)
        w = x - i
        return (1.0 - w) * self.positions[i] + w * self.positions[i + 1]
