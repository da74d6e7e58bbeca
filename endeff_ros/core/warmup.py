"""Warm-up: run a tracker once over two synthetic frames, then forget them.

The first frame a fresh process handles costs several times a later one: first calls into
scipy and OpenCV, the optical-flow object's first run, the compiled kernels' loading
(:mod:`.kernels`) and the first large allocations. In the
node at 30 Hz the first frame took several frame periods, so a live camera's first frames
arrived while the worker was busy and were skipped. The node pays this before it subscribes
instead (docs/design.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from endeff_ros.core import kernels
from endeff_ros.core.types import KINECT_640, Intrinsics, RGBDFrame

if TYPE_CHECKING:
    from endeff_ros.core.tracker import Tracker


def warm_up_frames(intrinsics: Intrinsics = KINECT_640,
                   shift_px: int = 3) -> list[RGBDFrame]:
    """Two RGB-D frames of a star (a disc with four limbs) 2 m away on no background; the
    second is the first moved ``shift_px`` pixels to the right, colour texture included, so
    the tracker predicts with optical flow."""
    h, w = intrinsics.height, intrinsics.width
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    rng = np.random.default_rng(0)
    texture = rng.integers(0, 256, (h, w + shift_px, 3), dtype=np.uint8)
    scale = min(h, w) / 480.0
    frames = []
    for k in range(2):
        cu, cv = w / 2 + k * shift_px, h / 2
        du, dv = u - cu, v - cv
        body = du ** 2 + dv ** 2 < (40 * scale) ** 2
        limbs = ((np.abs(du) < 10 * scale) & (np.abs(dv) < 150 * scale)) | (
            (np.abs(dv) < 10 * scale) & (np.abs(du) < 150 * scale))
        depth = np.where(body | limbs, np.float32(2.0), np.float32(np.nan))
        color = np.ascontiguousarray(texture[:, shift_px - k * shift_px:][:, :w])
        frames.append(RGBDFrame(k * 33_333_333, 'warm_up', depth, intrinsics, color))
    return frames


def warm_up(tracker: Tracker, intrinsics: Intrinsics = KINECT_640) -> int:
    """Run ``tracker`` over :func:`warm_up_frames`, then reset it (no track, id, floor or
    previous frame is kept). Returns the number of end-effectors of the last frame."""
    kernels.warm_up()  # the two frames reach not every kernel
    try:
        for frame in warm_up_frames(intrinsics):
            result = tracker.update(frame)
    finally:
        tracker.reset(forget_ids=True)
    return len(result.tracks)
