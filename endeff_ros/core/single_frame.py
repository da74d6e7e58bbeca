"""The single-frame estimator of Section 4 (the R-NBLS-style baseline): frame in, candidates out."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .params import EndeffParams
from .types import Candidate, RGBDFrame

if TYPE_CHECKING:
    import numpy.typing as npt


@dataclass(frozen=True)
class EntityEstimate:
    """One connected foreground cluster with its root, topology graph and candidates."""

    entity: int
    root: npt.NDArray[np.float64]
    candidates: list[Candidate]
    graph: object  # graph.TopologyGraph
    point_index: npt.NDArray[np.intp]


@dataclass(frozen=True)
class FrameEstimate:
    """Everything the Section 4 estimator found in one frame.

    ``points`` (N, 3) is the foreground after downsampling; ``band`` and ``subband`` label each
    point (-1 where the expansion never reached it), ``entity`` the cluster it belongs to (-1:
    too small). ``unreachable`` counts entity points that no band reached.
    """

    points: npt.NDArray[np.float64]
    band: npt.NDArray[np.intp]
    subband: npt.NDArray[np.intp]
    entity: npt.NDArray[np.intp]
    entities: list[EntityEstimate]
    unreachable: int
    stage_ms: dict[str, float] = field(default_factory=dict)

    def positions(self) -> npt.NDArray[np.float64]:
        """(M, 3) positions of all candidates of all entities."""
        rows = [c.position for e in self.entities for c in e.candidates]
        return np.array(rows, dtype=np.float64).reshape(-1, 3)


def estimate_frame(frame: RGBDFrame, params: EndeffParams | None = None) -> FrameEstimate:
    """Run Sections 3-4 on one frame."""
    raise NotImplementedError('being written')
