"""Where the camera sees a motion from: facing yaw, walking direction, distance, camera pose.

A clip's joints are in its body frame (the performer faces +z at frame 0, pelvis above the
origin). ``place`` turns a segment of them into the scene frame of ``render.py`` (camera at the
origin looking along -z, y up) so that the person is seen as the ``View`` asks:

- ``front`` / ``side`` / ``back``: the performer's mean facing over the segment turned towards
  the camera, sideways (``side_sign`` chooses left or right) or away;
- ``across``: the segment's net travel turned to run along the image's x axis, the middle of
  the walk in the middle of the view, so the person enters and leaves the field of view;
- ``towards``: the travel turned to point at the camera (the person approaches).

A segment that travels less than ``MIN_TRAVEL_M`` cannot walk across or towards: its view
becomes ``side`` or ``front`` and ``place`` says so (the bag's attribute is what was rendered).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..core.types import Intrinsics
from .mocap.clip import JOINT_INDEX
from .render import Camera
from .shapes import rot_y

VIEWS = ('front', 'side', 'back', 'across', 'towards')
MIN_TRAVEL_M = 0.4
NEAREST_M = 1.0  # an approaching walk stops this far (horizontally) from the camera
# The activity area a robot user sets the foreground box to: people stay between NEAREST_M and
# FARTHEST_M (horizontal pelvis distance) throughout a segment, so that a box 4.3 m deep (the
# default when the suite was made; 5.25 m now) holds them with their limbs; a person beyond it
# is outside the area by design.
FARTHEST_M = 4.0
_J = JOINT_INDEX


@dataclass(frozen=True)
class View:
    """How one person is seen.

    ``distance_m``: horizontal distance from the camera to the segment's mean pelvis position;
    ``camera_height_m`` above the floor; ``tilt_deg`` is added to the pitch that aims the
    optical axis at the middle of the person (positive looks further down); ``roll_deg``
    rolls the camera about its optical axis; ``offset_x_m`` moves the person sideways (a large
    offset puts part of the body outside the image); ``side_sign`` (+1/-1) picks the side of a
    side view and the direction of a walk across.
    """

    kind: str
    distance_m: float
    camera_height_m: float
    tilt_deg: float = 0.0
    roll_deg: float = 0.0
    offset_x_m: float = 0.0
    side_sign: int = 1

    def __post_init__(self) -> None:
        if self.kind not in VIEWS:
            msg = f'view must be one of {VIEWS}, got {self.kind!r}'
            raise ValueError(msg)
        if not 0.5 <= self.distance_m <= 10.0:
            msg = f'distance_m must be in [0.5, 10] m, got {self.distance_m}'
            raise ValueError(msg)
        if not 0.2 <= self.camera_height_m <= 3.5:
            msg = f'camera_height_m must be in [0.2, 3.5] m, got {self.camera_height_m}'
            raise ValueError(msg)


def facing(positions: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Horizontal unit facing directions (T, 3) of joints (T, 22, 3): the normal of the
    shoulder and hip lines, (left x up) = front."""
    p = np.asarray(positions, dtype=np.float64)
    left = (p[:, _J['l_shoulder']] - p[:, _J['r_shoulder']]
            + p[:, _J['l_hip']] - p[:, _J['r_hip']])
    f = np.cross(left, np.array([0.0, 1.0, 0.0]))
    f[:, 1] = 0.0
    return f / np.maximum(np.linalg.norm(f, axis=1, keepdims=True), 1e-9)


def travel(positions: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Net horizontal pelvis displacement (3,) m from the first to the last frame."""
    p = np.asarray(positions, dtype=np.float64)
    d = p[-1, _J['pelvis']] - p[0, _J['pelvis']]
    d[1] = 0.0
    return d


def effective_kind(positions: npt.ArrayLike, kind: str) -> str:
    """The view that ``place`` will render for ``kind``: a walk view of a segment that does
    not travel ``MIN_TRAVEL_M`` becomes ``side`` (across) or ``front`` (towards)."""
    if kind in ('across', 'towards') and np.linalg.norm(travel(positions)) < MIN_TRAVEL_M:
        return 'side' if kind == 'across' else 'front'
    return kind


def _angle(v: npt.ArrayLike) -> float:
    """Heading (rad) of a horizontal direction: 0 = +z (towards the camera), pi/2 = +x."""
    v = np.asarray(v, dtype=np.float64)
    return float(np.arctan2(v[0], v[2]))


def place(positions: npt.ArrayLike, view: View,
          centre: slice | None = None) -> tuple[npt.NDArray[np.float64], str]:
    """(scene-frame joints (T, 22, 3), rendered view kind) of a body-frame segment.
    ``centre``: the frames whose mean pelvis goes to the view's place (default all; a person
    who stands and then walks off is centred where they stand)."""
    p = np.asarray(positions, dtype=np.float64)
    kind = effective_kind(p, view.kind)
    s = float(view.side_sign)
    if kind in ('across', 'towards'):
        source = _angle(travel(p))
        target = s * np.pi / 2 if kind == 'across' else 0.0
    else:
        f = facing(p).mean(axis=0)
        source = _angle(f)
        target = {'front': 0.0, 'side': s * np.pi / 2, 'back': np.pi}[kind]
    rot = rot_y(target - source)
    pel = p[slice(None) if centre is None else centre, _J['pelvis']]
    mid = np.array([pel[:, 0].mean(), 0.0, pel[:, 2].mean()])
    out = (p - mid) @ rot.T
    anchor = np.array([view.offset_x_m, 0.0, -view.distance_m])
    # Keep the pelvis within [NEAREST_M, FARTHEST_M]: pushed back first (an approaching walk
    # stops before the camera), then forward as far as that allows.
    depth = -(out[:, _J['pelvis'], 2] + anchor[2])
    if depth.min() < NEAREST_M:
        anchor[2] -= NEAREST_M - float(depth.min())
    elif depth.max() > FARTHEST_M:
        anchor[2] += min(float(depth.max()) - FARTHEST_M, float(depth.min()) - NEAREST_M)
    return out + anchor, kind


def aim_camera(scene_joints: npt.ArrayLike, view: View, intrinsics: Intrinsics,
               wall_z: float = -5.5) -> Camera:
    """The camera of ``view`` aimed at the middle of the person: pitch from the camera height
    to half the person's mean head height at the mean distance, plus ``tilt_deg``."""
    p = np.asarray(scene_joints, dtype=np.float64)
    mid_y = 0.5 * float(p[:, _J['head_top'], 1].mean())
    dist = -float(p[:, _J['pelvis'], 2].mean())
    pitch = np.arctan2(view.camera_height_m - mid_y, max(dist, 0.3)) + np.deg2rad(view.tilt_deg)
    return Camera(intrinsics, height=view.camera_height_m, pitch=float(pitch), wall_z=wall_z,
                  roll=float(np.deg2rad(view.roll_deg)))
