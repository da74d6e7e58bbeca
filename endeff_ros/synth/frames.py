"""From animated scenes to sensor frames: ``render_sequence`` and ``render_person_frame``.

Frame timing: depth stamps at exactly 30 Hz from ``T0_NS``; each colour stamp is the depth
stamp plus a uniform jitter of +-4 ms. About 2 % of colour frames and 2 % of depth frames (at
least one of each, never among the first 3) are dropped; everything is deterministic from the
seed (per sequence and per frame random streams).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..core.types import Intrinsics
from .render import Camera, default_camera, render
from .scenes import person
from .sensor import color_image, depth_image, depth_to_mm
from .sequences import SEQUENCES, SPECS, frame_time, n_frames, scene

T0_NS = 1_700_000_000 * 10**9
PERIOD_NS = 10**9 // 30 + 1  # 33 333 334 ns: 30 Hz
COLOR_JITTER_NS = 4_000_000
DROP_RATE = 0.02


@dataclass(frozen=True)
class SynthFrame:
    """One synthetic RGB-D frame with ground truth.

    ``stamp_ns`` is the depth stamp, ``color_stamp_ns`` the colour stamp. ``color`` (H, W, 3)
    uint8 RGB, or None if this colour frame is dropped; ``depth`` (H, W) float32 metres with NaN
    = no reading (millimetre-rounded for 16UC1 sequences), or None if the depth frame is dropped.
    ``gt`` (M, 3) float64 end-effector positions in the optical frame (m), ``gt_ids`` (M,)
    uint32, ``gt_visible`` (M,) bool: the end-effector's own part is what the camera sees at
    its projection and the sensor has a depth reading of that part within 2 px.
    """

    index: int
    stamp_ns: int
    color_stamp_ns: int
    color: npt.NDArray[np.uint8] | None
    depth: npt.NDArray[np.float32] | None
    intrinsics: Intrinsics
    gt: npt.NDArray[np.float64]
    gt_ids: npt.NDArray[np.uint32]
    gt_visible: npt.NDArray[np.bool_]
    frame_id: str


def dropped_frames(name: str, n: int, seed: int = 0) -> tuple[set[int], set[int]]:
    """(dropped colour indices, dropped depth indices) of an ``n``-frame sequence."""
    return drop_indices(np.random.default_rng([seed, SEQUENCES.index(name), 2]), n)


def drop_indices(rng: np.random.Generator, n: int) -> tuple[set[int], set[int]]:
    """(dropped colour indices, dropped depth indices) of ``n`` frames drawn from ``rng``:
    ``DROP_RATE`` of each (at least one), never among the first 3 frames, none if n <= 4."""
    if n <= 4:
        return set(), set()
    k = max(1, int(round(DROP_RATE * n)))
    cand = rng.permutation(np.arange(3, n))
    return {int(i) for i in cand[:k]}, {int(i) for i in cand[k:2 * k]}


def _frame(name: str, index: int, u: float, seed: int, cam: Camera, stamp: int,
           cstamp: int, drop_c: bool, drop_d: bool, entity=None) -> SynthFrame:
    ent = scene(name, u, seed) if entity is None else entity
    ren = render(ent, cam)
    sid = SEQUENCES.index(name) if name in SEQUENCES else 99
    rng = np.random.default_rng([seed, sid, 3, index])
    depth = depth_image(ren, rng)
    color = color_image(ren, rng)
    if name in SPECS and SPECS[name].depth_encoding == '16UC1':
        mm = depth_to_mm(depth)
        depth = np.where(mm > 0, mm.astype(np.float32) / np.float32(1000.0), np.float32(np.nan))
    return SynthFrame(index, stamp, cstamp, None if drop_c else color,
                      None if drop_d else depth.astype(np.float32), cam.intrinsics,
                      ren.gt.copy(), ent.gt_ids.astype(np.uint32),
                      sensed_visibility(ren, ent.gt_prims, depth), cam.frame_id)


def sensed_visibility(ren, gt_prims: npt.NDArray[np.int64],
                      depth: npt.NDArray[np.float32]) -> npt.NDArray[np.bool_]:
    """Visibility (M,): the end-effector's own part is in view at its projection (1 px
    tolerance) and has at least one depth reading within 2 px of it."""
    vis = ren.gt_visible.copy()
    uv = ren.camera.intrinsics.project(ren.gt)
    h, w = depth.shape
    for k in np.nonzero(vis)[0]:
        ui, vi = int(round(uv[k, 0])), int(round(uv[k, 1]))
        sl = np.s_[max(0, vi - 2):min(h, vi + 3), max(0, ui - 2):min(w, ui + 3)]
        vis[k] = bool(((ren.owner[sl] == gt_prims[k]) & np.isfinite(depth[sl])).any())
    return vis


def render_sequence(name: str, *, quick: bool = False, seed: int = 0) -> Iterator[SynthFrame]:
    """Frames of sequence ``name`` (one of ``SEQUENCES``), in order, 640x480.

    ``quick`` gives ``QUICK_FRAMES`` frames sampled over the whole motion (for tests).
    """
    if name not in SPECS:
        msg = f'unknown sequence {name!r}; known: {", ".join(SEQUENCES)}'
        raise KeyError(msg)
    cam = default_camera()
    n = n_frames(name, quick)
    drop_c, drop_d = dropped_frames(name, n, seed)
    jit = np.random.default_rng([seed, SEQUENCES.index(name), 4]).integers(
        -COLOR_JITTER_NS, COLOR_JITTER_NS + 1, size=n)
    for i in range(n):
        stamp = T0_NS + i * PERIOD_NS
        yield _frame(name, i, frame_time(name, i, quick), seed, cam, stamp,
                     stamp + int(jit[i]), i in drop_c, i in drop_d)


def render_person_frame(pose_name: str = 't_pose', seed: int = 0) -> SynthFrame:
    """One frame of a single standing person 2.5 m away (about 23k foreground pixels).

    ``pose_name``: ``'t_pose'`` (arms straight out sideways) or ``'arms_down'`` (arms hanging a
    little away from the body).
    """
    ent = person(pose_name, z=-2.5)
    cam = default_camera()
    return _frame(f'person:{pose_name}', 0, 0.0, seed, cam, T0_NS, T0_NS, False, False,
                  entity=ent)
