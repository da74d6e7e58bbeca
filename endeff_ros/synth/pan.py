"""A camera that pans once: still, one smooth turn about its vertical axis, still again.

A robot turning its head or base moves the whole static scene through the image while the
people in it keep their ids; a background model learnt before the turn is wrong after it.
``Pan`` describes that motion for a synthetic bag: the yaw (``render.Camera.yaw``) relative to
the direction the camera was aimed at goes from ``+yaw_deg / 2`` to ``-yaw_deg / 2`` between
``start_s`` and ``end_s`` (seconds from the bag's first frame), so a person the camera was
aimed at stays within ``yaw_deg / 2`` of the image centre throughout. The profile is a raised
cosine (zero angular speed at both ends, peak ``pi / 2`` times the mean), as a pan-tilt unit or
a turning base accelerates and brakes; the camera's position does not change.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class Pan:
    """One pan: ``yaw_deg`` (signed, degrees; positive ends turned to the right, towards +x)
    over ``duration_s`` seconds starting ``start_s`` seconds after the first frame."""

    start_s: float
    duration_s: float
    yaw_deg: float

    def __post_init__(self) -> None:
        problems = []
        if not self.start_s >= 0.0:
            problems.append(f'start_s must be >= 0, got {self.start_s}')
        if not self.duration_s > 0.0:
            problems.append(f'duration_s must be > 0, got {self.duration_s}')
        if not 0.0 < abs(self.yaw_deg) <= 90.0:
            problems.append(f'yaw_deg must be non-zero and within +-90, got {self.yaw_deg}')
        if problems:
            msg = 'pan: ' + '; '.join(problems)
            raise ValueError(msg)

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def yaw_at(self, t_s: npt.ArrayLike) -> npt.NDArray[np.float64] | float:
        """Camera yaw (rad, ``render.Camera.yaw``) at time(s) ``t_s`` (s from the first frame):
        ``+yaw_deg / 2`` up to ``start_s``, ``-yaw_deg / 2`` from ``end_s`` on."""
        t = np.asarray(t_s, dtype=np.float64)
        s = np.clip((t - self.start_s) / self.duration_s, 0.0, 1.0)
        yaw = np.deg2rad(self.yaw_deg) * (0.5 - 0.5 * (1.0 - np.cos(np.pi * s)))
        return float(yaw) if yaw.ndim == 0 else yaw
