"""Where an end lies in the scene, as evidence for the scorers (:mod:`.confidence`,
:mod:`.candidates`): its height above the floor and its distance to the image border."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import numpy.typing as npt

    from .types import Intrinsics

NO_FLOOR = -1.0
"""Height of every end when no floor is known (below any height an end can have)."""


def height_and_border(pos: npt.NDArray[np.float64], floor: Any,
                      intrinsics: Intrinsics | None) -> tuple[npt.NDArray[np.float64],
                                                              npt.NDArray[np.float64]]:
    """Per position (M, 3) its height above ``floor`` (a :class:`~.floor.FloorPlane`;
    clipped to -0.5-3 m, :data:`NO_FLOOR` without one) and its distance to the image border
    over the image width (clipped to 0-0.25; 0.25 without ``intrinsics``)."""
    height = (np.clip(floor.distance(pos), -0.5, 3.0) if floor is not None
              else np.full(len(pos), NO_FLOOR))
    if intrinsics is None:
        return height, np.full(len(pos), 0.25)
    uv = intrinsics.project(pos)
    to_border = np.minimum.reduce([uv[:, 0], intrinsics.width - 1 - uv[:, 0], uv[:, 1],
                                   intrinsics.height - 1 - uv[:, 1]])
    return height, np.clip(np.nan_to_num(to_border / intrinsics.width), 0, 0.25)
