"""Predict-update tracker of Section 5."""

from __future__ import annotations

from dataclasses import dataclass, field

from .params import EndeffParams
from .single_frame import FrameEstimate
from .types import RGBDFrame, Track


@dataclass(frozen=True)
class TrackerResult:
    """Output of one tracker step: the published tracks plus the frame's single-frame estimate."""

    stamp_ns: int
    frame_id: str
    tracks: list[Track]
    estimate: FrameEstimate
    stage_ms: dict[str, float] = field(default_factory=dict)


class Tracker:
    """Keeps end-effectors stable over time. ``params`` may be replaced between frames."""

    def __init__(self, params: EndeffParams | None = None) -> None:
        self.params = params or EndeffParams()

    def reset(self) -> None:
        """Forget all tracks (e.g. when time jumps backwards during bag replay)."""

    def update(self, frame: RGBDFrame) -> TrackerResult:
        """Process one frame and return the current end-effectors."""
        raise NotImplementedError('being written')
