"""Procedural ``MotionClip``s (walk, sit down, wave): known skeletons for tests and examples.

They are not motion capture: a sinusoidal gait and simple joint-angle ramps on the 1.75 m
reference skeleton of ``body.PersonModel`` (pelvis 0.95 m, thigh 0.43, shin 0.42, upper arm
0.29, forearm 0.25, hand 0.18, crown at 1.75 m). They let the body builder, the views and the
suite be tested without any third-party data.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .mocap.clip import JOINT_INDEX, JOINTS, MotionClip

_J = JOINT_INDEX
FPS = 30.0


def _limb(root: npt.NDArray, pitch: npt.NDArray, length: float) -> npt.NDArray:
    """End points (T, 3) of segments hanging from ``root`` (T, 3), swung forward by ``pitch``
    (T,) rad about the body's x axis (0 = straight down)."""
    d = np.stack([np.zeros_like(pitch), -np.cos(pitch), np.sin(pitch)], axis=1)
    return root + length * d


def _skeleton(pelvis: npt.NDArray, lean: npt.NDArray, hip: tuple[npt.NDArray, npt.NDArray],
              knee: tuple[npt.NDArray, npt.NDArray], shoulder: tuple[npt.NDArray, npt.NDArray],
              elbow: tuple[npt.NDArray, npt.NDArray], abduct: tuple[npt.NDArray, npt.NDArray]
              ) -> npt.NDArray[np.float64]:
    """Joint positions (T, 22, 3) from pelvis (T, 3), torso lean (T,) and per-side (left,
    right) hip flexion, knee flexion, shoulder flexion, elbow flexion and arm abduction (T,)."""
    t = len(pelvis)
    pos = np.zeros((t, len(JOINTS), 3))
    up = np.stack([np.zeros(t), np.cos(lean), np.sin(lean)], axis=1)
    pos[:, _J['pelvis']] = pelvis
    for name, h in (('spine', 0.12), ('chest', 0.30), ('neck', 0.50), ('head', 0.58),
                    ('head_top', 0.80)):
        pos[:, _J[name]] = pelvis + h * up
    for k, (side, pre) in enumerate(((1.0, 'l_'), (-1.0, 'r_'))):
        hip_p = pelvis + np.array([side * 0.09, -0.05, 0.0])
        knee_p = _limb(hip_p, hip[k], 0.43)
        ankle = _limb(knee_p, hip[k] - knee[k], 0.42)
        foot = np.stack([np.zeros(t), -0.07 * np.ones(t), 0.13 * np.ones(t)], axis=1)
        pos[:, _J[pre + 'hip']], pos[:, _J[pre + 'knee']] = hip_p, knee_p
        pos[:, _J[pre + 'ankle']], pos[:, _J[pre + 'toe']] = ankle, ankle + foot
        sh = pelvis + 0.45 * up + np.array([side * 0.18, 0.0, 0.0])
        a = abduct[k]
        d1 = np.stack([side * np.sin(a), -np.cos(a) * np.cos(shoulder[k]),
                       np.cos(a) * np.sin(shoulder[k])], axis=1)
        el = sh + 0.29 * d1
        f = shoulder[k] + elbow[k]
        d2 = np.stack([side * np.sin(a), -np.cos(a) * np.cos(f), np.cos(a) * np.sin(f)], axis=1)
        wr = el + 0.25 * d2
        pos[:, _J[pre + 'shoulder']], pos[:, _J[pre + 'elbow']] = sh, el
        pos[:, _J[pre + 'wrist']], pos[:, _J[pre + 'hand_end']] = wr, wr + 0.18 * d2
    feet = [_J[n] for n in ('l_ankle', 'l_toe', 'r_ankle', 'r_toe')]
    pos[..., 1] -= pos[:, feet, 1].min()  # lowest foot joint of the clip on the floor
    pos[..., [0, 2]] -= pos[0, _J['pelvis'], [0, 2]]
    return pos


def walk_clip(n: int = 60, speed: float = 1.3, name: str = 'proc_walk',
              split: str = 'dev') -> MotionClip:
    """A straight walk along the body's +z at ``speed`` m/s, 1 gait cycle per 1.1 s."""
    t = np.arange(n) / FPS
    ph = 2 * np.pi * t / 1.1
    pelvis = np.stack([0.02 * np.sin(ph), 0.95 + 0.02 * np.cos(2 * ph), speed * t], axis=1)
    hip = (0.38 * np.sin(ph), -0.38 * np.sin(ph))
    knee = (0.55 * np.clip(np.sin(ph - 1.2), 0, None), 0.55 * np.clip(-np.sin(ph - 1.2), 0, None))
    shoulder = (-0.3 * np.sin(ph), 0.3 * np.sin(ph))
    elbow = (0.35 + 0.1 * np.sin(ph), 0.35 - 0.1 * np.sin(ph))
    abd = (np.full(n, 0.1), np.full(n, 0.1))
    pos = _skeleton(pelvis, np.full(n, 0.05), hip, knee, shoulder, elbow, abd)
    return MotionClip(name, 'procedural', 'walk', split, FPS, pos, 'CC0')


def sit_clip(n: int = 60, name: str = 'proc_sit', split: str = 'dev') -> MotionClip:
    """Standing, then sitting down (thighs horizontal, seat about 0.47 m) over ``n`` frames."""
    s = np.clip(np.arange(n) / max(n - 1, 1) * 1.5 - 0.2, 0, 1)
    s = s * s * (3 - 2 * s)
    flex = s * np.pi / 2
    # The pelvis moves back by the thigh's horizontal reach as it lowers, so the knees stay
    # above the planted feet (shins vertical), and lowers by what the thighs lose in height.
    pelvis = np.stack([np.zeros(n), 0.95 - 0.43 * (1 - np.cos(flex)), -0.43 * np.sin(flex)],
                      axis=1)
    hip = (flex, flex)
    knee = (flex, flex)
    zero = np.zeros(n)
    pos = _skeleton(pelvis, 0.25 * s, hip, knee, (0.5 * s, 0.5 * s), (0.6 * s, 0.6 * s),
                    (zero + 0.1, zero + 0.1))
    return MotionClip(name, 'procedural', 'sit', split, FPS, pos, 'CC0')


def wave_clip(n: int = 60, name: str = 'proc_wave', split: str = 'test') -> MotionClip:
    """Standing, the right arm raised and waving sideways, the left hanging."""
    t = np.arange(n) / FPS
    zero = np.zeros(n)
    pelvis = np.stack([zero, zero + 0.95, zero], axis=1)
    abd = (zero + 0.15, 2.3 + 0.4 * np.sin(2 * np.pi * t / 1.2))
    pos = _skeleton(pelvis, zero, (zero, zero), (zero, zero), (zero + 0.1, zero),
                    (zero + 0.2, zero + 0.3), abd)
    return MotionClip(name, 'procedural', 'wave', split, FPS, pos, 'CC0')
