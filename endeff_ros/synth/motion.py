"""Still and slow people for the mocap and rooms suites: how a clip becomes a person who keeps
still from the first frame, sits, stands and then leaves, arrives and stays, or moves slowly.

A static background model learns whatever keeps still as background; a person who is in view
from the first frame and hardly moves is what it gets wrong. The suites' ordinary bags never
show one (each is a clip's most active segment), so these cases make them from the same clips:

- ``frozen``: a standing pose from a clip held exactly still (every frame the same joints);
- ``breathing``: the same pose with breathing (chest, shoulders, arms and head rising and
  falling +-``BREATH_M`` at ``BREATH_HZ``) and postural sway (everything above the pelvis
  +-``SWAY_M`` at 0.1-0.3 Hz along two horizontal axes, tapering to nothing at the floor);
- ``seated``: that pose seated procedurally (hips and knees bent 90 degrees, shins vertical
  over the feet, hands on the thighs; a chair under it), breathing;
- ``leaves``: a walk clip's frame held (breathing) for ``hold`` frames, then the walk from that
  frame on, out of the field of view;
- ``arrives``: a walk into the view that stops after ``hold`` frames and holds its last pose
  (breathing);
- ``slowed``: a segment time-stretched ``factor`` times (joints interpolated linearly, still
  30 fps): a segment of m + 1 source frames spans m x factor frames;
- ``idle``: a clip at its own speed from its first frame (ReActIdle's standing idle);
- ``segment``: the clip's segment as it is (the suites' ordinary bags).

``CASES`` gives each case's ``motion`` attribute (``still``, ``slow``, ``active``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .mocap.clip import JOINT_INDEX

MOTIONS = ('still', 'slow', 'active')
CASES: dict[str, str] = {
    'segment': 'active', 'frozen': 'still', 'breathing': 'still', 'seated': 'still',
    'leaves': 'still', 'arrives': 'still', 'slowed': 'slow', 'idle': 'slow',
}
BREATH_M = 0.003
BREATH_HZ = 0.25
SWAY_M = 0.005
SWAY_HZ = (0.1, 0.3)
FPS = 30.0
_J = JOINT_INDEX
_UPPER = [_J[n] for n in ('chest', 'neck', 'head', 'head_top', 'l_shoulder', 'l_elbow',
                          'l_wrist', 'l_hand_end', 'r_shoulder', 'r_elbow', 'r_wrist',
                          'r_hand_end')]
_ENDS = [_J[n] for n in ('l_wrist', 'r_wrist', 'l_ankle', 'r_ankle', 'head_top')]


def standing_score(pos: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Per frame of ``pos`` (T, 22, 3), how far from a quiet standing pose it is (lower is
    better, dimensionless): feet apart, wrists above the hips' height, pelvis lowered, torso
    leaning, and the hands, feet and head moving."""
    from .skeleton_body import standing_height

    h = standing_height(pos)
    pel = pos[:, _J['pelvis'], 1] / h
    feet = np.linalg.norm((pos[:, _J['l_ankle']] - pos[:, _J['r_ankle']])[:, [0, 2]],
                          axis=1) / h
    wrist = np.maximum(pos[:, _J['l_wrist'], 1], pos[:, _J['r_wrist'], 1]) / h
    trunk = pos[:, _J['neck']] - pos[:, _J['pelvis']]
    lean = 1.0 - trunk[:, 1] / np.maximum(np.linalg.norm(trunk, axis=1), 1e-9)
    speed = np.linalg.norm(np.gradient(pos[:, _ENDS], axis=0), axis=2).sum(1) * FPS / h
    return (feet + 2.0 * np.maximum(wrist - 0.52, 0.0) + 3.0 * np.maximum(0.52 - pel, 0.0)
            + 2.0 * lean + 0.05 * speed)


def breathe(joints: npt.NDArray[np.float64], rng: np.random.Generator,
            fps: float = FPS) -> npt.NDArray[np.float64]:
    """``joints`` (T, 22, 3) with breathing and postural sway added (module docstring): the
    chest, head and arms rise and fall, the spine half as much; the body sways about the
    ankles, +-``SWAY_M`` from the pelvis up, less below it."""
    out = np.array(joints, dtype=np.float64)
    t = np.arange(len(out)) / fps
    breath = BREATH_M * np.sin(2 * np.pi * BREATH_HZ * t + rng.uniform(0, 2 * np.pi))
    out[:, _UPPER, 1] += breath[:, None]
    out[:, _J['spine'], 1] += 0.5 * breath
    sway = np.zeros((len(out), 3))
    for axis in (0, 2):
        sway[:, axis] = SWAY_M * np.sin(2 * np.pi * rng.uniform(*SWAY_HZ) * t
                                        + rng.uniform(0, 2 * np.pi))
    pelvis_y = max(float(out[0, _J['pelvis'], 1]), 0.1)
    weight = np.clip(out[..., 1] / pelvis_y, 0.0, 1.0)  # (T, 22): 0 at the floor
    return out + weight[..., None] * sway[:, None, :]


def _unit(v: npt.ArrayLike) -> npt.NDArray[np.float64]:
    v = np.asarray(v, dtype=np.float64)
    return v / max(float(np.linalg.norm(v)), 1e-9)


def _two_bone(root: npt.NDArray, target: npt.NDArray, upper: float, lower: float,
              pole: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
    """(middle joint, end) of a two-bone chain from ``root`` reaching for ``target``, bent
    towards ``pole`` (the end stops short of a target out of reach)."""
    d = target - root
    dist = float(np.clip(np.linalg.norm(d), abs(upper - lower) + 1e-3, upper + lower - 1e-3))
    axis = _unit(d)
    along = (upper ** 2 - lower ** 2 + dist ** 2) / (2 * dist)
    bend = _unit(pole - np.dot(pole, axis) * axis)
    mid = root + along * axis + np.sqrt(max(upper ** 2 - along ** 2, 0.0)) * bend
    return mid, root + dist * axis


def seat(pose: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """A standing ``pose`` (22, 3) seated: thighs horizontal forward from the hips, shins
    vertical over the feet (hips and knees at 90 degrees), the upper body lowered and moved
    back with the hips, hands resting on the thighs. Segment lengths are kept."""
    from .views import facing

    p = np.array(pose, dtype=np.float64)
    fwd = facing(p[None])[0]
    up = np.array([0.0, 1.0, 0.0])
    out = p.copy()
    legs = [('l_hip', 'l_knee', 'l_ankle', 'l_toe'), ('r_hip', 'r_knee', 'r_ankle', 'r_toe')]
    thigh = [np.linalg.norm(p[_J[h]] - p[_J[k]]) for h, k, _, _ in legs]
    shin = [np.linalg.norm(p[_J[k]] - p[_J[a]]) for _, k, a, _ in legs]
    hips = np.mean([p[_J[h]] for h, _, _, _ in legs], axis=0)
    ankles = np.mean([p[_J[a]] for _, _, a, _ in legs], axis=0)
    knee_y = float(ankles[1]) + float(np.mean(shin))
    shift = ankles - float(np.mean(thigh)) * fwd - hips
    shift[1] = knee_y - hips[1]
    lower = {_J[n] for leg in legs for n in leg}
    body = [k for k in range(len(p)) if k not in lower]
    out[body] += shift
    for (h, k, a, t), lt, ls in zip(legs, thigh, shin):
        hip = p[_J[h]] + shift
        knee = hip + lt * fwd
        ankle = knee - ls * up
        out[_J[h]], out[_J[k]], out[_J[a]] = hip, knee, ankle
        out[_J[t]] = ankle + (p[_J[t]] - p[_J[a]])
    for side in ('l', 'r'):
        sh, el, wr, he = (_J[f'{side}_{n}'] for n in ('shoulder', 'elbow', 'wrist', 'hand_end'))
        hip, knee = out[_J[f'{side}_hip']], out[_J[f'{side}_knee']]
        lu = np.linalg.norm(p[sh] - p[el])
        lf = np.linalg.norm(p[el] - p[wr])
        lh = np.linalg.norm(p[wr] - p[he])
        target = hip + 0.45 * (knee - hip) + 0.09 * up
        outward = _unit(out[sh] - out[_J['chest']])
        out[el], out[wr] = _two_bone(out[sh], target, lu, lf, -fwd + 0.5 * outward)
        out[he] = out[wr] + lh * _unit(fwd - 0.3 * up)
    return out


def stretch(seg: npt.NDArray[np.float64], factor: int, frames: int) -> npt.NDArray[np.float64]:
    """``frames`` frames of ``seg`` (T, 22, 3) played ``factor`` times slower: frame k is
    ``seg`` at source time k / factor, linearly interpolated (held at its last frame beyond
    it)."""
    x = np.minimum(np.arange(frames) / factor, len(seg) - 1)
    i = np.minimum(x.astype(int), max(len(seg) - 2, 0))
    w = (x - i)[:, None, None]
    nxt = np.minimum(i + 1, len(seg) - 1)
    return (1 - w) * seg[i] + w * seg[nxt]


def cycled(pos: npt.NDArray[np.float64], frames: int) -> npt.NDArray[np.float64]:
    """At least ``frames`` frames of a cyclic clip ``pos`` (its last frame repeats its first
    one step further on, as DeepMimic's looping walks): the cycle repeated, each repetition
    moved on by the pelvis's horizontal travel over one cycle."""
    if len(pos) >= frames or len(pos) < 3:
        return pos
    period = len(pos) - 1
    step = pos[-1, _J['pelvis']] - pos[0, _J['pelvis']]
    step[1] = 0.0
    k = np.arange(frames)
    return pos[k % period] + (k // period)[:, None, None] * step


def feet_together(pos: npt.NDArray[np.float64], lo: int, hi: int) -> int:
    """The frame in ``[lo, hi)`` of ``pos`` whose ankles are closest horizontally (a walk's
    passing phase: the pose that best stands still)."""
    hi = max(hi, lo + 1)
    gap = np.linalg.norm((pos[lo:hi, _J['l_ankle']] - pos[lo:hi, _J['r_ankle']])[:, [0, 2]],
                         axis=1)
    return lo + int(np.argmin(gap))


def travel_frames(pos: npt.NDArray[np.float64], start: int, distance_m: float) -> int:
    """Frames from ``start`` until the pelvis of ``pos`` has moved ``distance_m``
    horizontally (``len(pos) - start`` when it never does)."""
    pel = pos[start:, _J['pelvis']][:, [0, 2]]
    far = np.flatnonzero(np.linalg.norm(pel - pel[0], axis=1) >= distance_m)
    return int(far[0]) + 1 if len(far) else len(pel)


def person_joints(full: npt.NDArray[np.float64], case: str, start: int, frames: int,
                  hold: int, factor: int, rng: np.random.Generator
                  ) -> tuple[npt.NDArray[np.float64], slice | None]:
    """(body-frame joints (frames, 22, 3), the frames to centre in the view or ``None`` for
    all) of one person of ``case`` from ``full`` (the clip scaled, 30 fps). ``start``: the
    pose's frame (still cases, ``leaves``), the first frame (``segment``, ``slowed``,
    ``idle``, ``arrives``); ``hold``: frames standing still before leaving (``leaves``) or
    walking before stopping (``arrives``); ``factor``: the slow-down (``slowed``)."""
    if case not in CASES:
        msg = f'motion case must be one of {sorted(CASES)}, got {case!r}'
        raise ValueError(msg)
    if case in ('segment', 'idle'):  # a short clip holds its last pose
        return _fit(full[start:start + frames], frames), None
    if case == 'slowed':
        need = int(np.ceil(frames / factor)) + 1
        return stretch(full[start:start + need], factor, frames), None
    if case in ('frozen', 'breathing', 'seated'):
        pose = full[start] if case != 'seated' else seat(full[start])
        still = np.repeat(pose[None], frames, 0)
        return (still if case == 'frozen' else breathe(still, rng)), None
    walk = cycled(full, start + frames)
    if case == 'leaves':
        still = breathe(np.repeat(walk[start][None], hold, 0), rng)
        moving = _fit(walk[start:start + frames - hold], frames - hold)
        return np.concatenate([still, moving]), slice(0, hold)
    moving = _fit(walk[start:start + hold], hold)
    still = breathe(np.repeat(moving[-1:], frames - hold, 0), rng)
    return np.concatenate([moving, still]), slice(hold, frames)


def _fit(seg: npt.NDArray[np.float64], frames: int) -> npt.NDArray[np.float64]:
    """``seg`` cut or padded (its last pose held) to ``frames`` frames."""
    if len(seg) >= frames:
        return seg[:frames]
    return np.concatenate([seg, np.repeat(seg[-1:], frames - len(seg), 0)])
