"""Connected parts of a depth image, cut at depth edges: what the static background
(:mod:`.background`) labels into components.

Neighbouring pixels whose depths jump by more than the edge step
(``(EDGE_STEP + EDGE_STEP_Z z) * stride``) lie on two surfaces; the far side of each jump is
left out of the labelling (:func:`far_side_pixels`), and so are the flying pixels a sensor
reads between two surfaces (:func:`flying_pixels`). Dropouts inside a surface are bridged for
the labelling (:func:`bridge_dropouts`). The choice of the step and its measurements:
docs/design.md, "The static background"."""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

from . import kernels

if TYPE_CHECKING:
    import numpy.typing as npt


#: Neighbouring depths differing by more than ``(EDGE_STEP + EDGE_STEP_Z * z) * stride``
#: metres are a depth edge between two components (a limb's grazing side at 4 m differs by
#: less; a person 10 cm in front of a chair by more).
EDGE_STEP = 0.1
EDGE_STEP_Z = 0.03
#: A pixel between 4-neighbours that differ by more than the edge step, at least this fraction
#: of the step from each, is a flying pixel (:func:`flying_pixels`).
FLYING_FRACTION = 0.25
#: Dropouts (no reading) are bridged for the labelling where the readings around them agree
#: within this depth (m): stereo and ToF dropouts would cut a still leg into specks.
BRIDGE_STEP = 0.1


def depth_components(depth: npt.NDArray[np.float32], mask: npt.NDArray[np.bool_],
                     stride: int, far_side: npt.NDArray[np.bool_] | None = None,
                     ) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.bool_]]:
    """Connected parts of ``mask`` split at depth edges.

    ``depth`` (H, W) metres with 0 or NaN where there is no reading, ``mask`` (H, W) the
    pixels to label, ``stride`` the pixel stride of the image (neighbours are that many
    full-resolution pixels apart). A pixel whose 4-neighbour is nearer by more than the edge
    step is the far side of an edge and is left out, and so is a flying pixel on an edge;
    4-connectivity then cannot cross the edge. ``far_side``: :func:`far_side_pixels` of the
    same image, when the caller labels several masks of it. Returns the labels (0: none)
    and the left-out far-side pixels of ``mask``.
    """
    if far_side is None:
        far_side = far_side_pixels(depth, stride)
    far = far_side & mask
    _, labels = cv2.connectedComponents((mask & ~far).view(np.uint8), connectivity=4,
                                        ltype=cv2.CV_32S)
    return labels, far


def far_side_pixels(depth: npt.NDArray[np.float32], stride: int, *,
                    flying: bool = True) -> npt.NDArray[np.bool_]:
    """(H, W) pixels of ``depth`` with a 4-neighbour nearer by more than the edge step
    (``(EDGE_STEP + EDGE_STEP_Z * z) * stride`` metres): the far sides of depth edges, and
    with ``flying`` the :func:`flying_pixels` on them."""
    z = _readings(depth)
    step = _edge_step(z, stride)
    lo = _nearest_neighbour(z)
    far = lo < z - step  # some 4-neighbour is nearer by more than the step
    return (far | flying_pixels(z, step, lo)) if flying else far


def _readings(depth: npt.NDArray[np.floating]) -> npt.NDArray[np.float32]:
    """``depth`` as float32 with inf where there is no reading (0, NaN, inf)."""
    z = np.array(depth, dtype=np.float32)
    z[~((z > 0) & (z < np.inf))] = np.inf  # NaN compares False
    return z


def _nearest_neighbour(z: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """Per pixel of the readings ``z`` (inf: none), the nearest of its 4-neighbours (inf
    beyond the image): one erosion by the cross without its centre."""
    return cv2.erode(z, _CROSS, borderType=cv2.BORDER_CONSTANT, borderValue=np.inf)


def _edge_step(z: npt.NDArray[np.float32], stride: int) -> npt.NDArray[np.float32]:
    """The depth edge step at depths ``z`` (inf: none), metres."""
    return np.float32((EDGE_STEP + EDGE_STEP_Z * np.minimum(z, 20.0)) * stride)


_CROSS = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], np.uint8)


def flying_pixels(z: npt.NDArray[np.float32], step: npt.NDArray[np.float32],
                  lo: npt.NDArray[np.float32] | None = None) -> npt.NDArray[np.bool_]:
    """(H, W) pixels of the readings ``z`` (float32 metres, inf: no reading) that read a mix
    of two surfaces at an occlusion edge; ``step`` (H, W) the edge step at each.

    Time-of-flight and structured-light sensors give a pixel on an occlusion edge a depth
    between the near and the far surface. Each of its two steps may be below the edge step
    while the two together are not, so one such pixel joins a person's arm to the lamp 0.6 m
    behind it (docs/design.md, "Flying pixels cut"). A pixel is flying when its 4-neighbours
    differ by more than the edge step and it lies at least ``FLYING_FRACTION`` of the step
    from both the nearest and the farthest of them. A surface whose depth grows evenly
    across the pixel is one only when it grows by half the step per pixel: at 2 m and the
    default stride, a surface seen within 3 degrees of grazing. A fist punched at the camera
    (its forearm hidden behind it) may hang on its chest by flying pixels alone, so
    :meth:`.background.BackgroundModel.foreground` cuts them only while colour comes: the
    still chest then shows its own motion. ``lo``: :func:`_nearest_neighbour` of ``z`` if the
    caller has it.
    """
    if lo is None:
        lo = _nearest_neighbour(z)
    hi = cv2.dilate(np.where(np.isinf(z), np.float32(0), z), _CROSS,
                    borderType=cv2.BORDER_CONSTANT, borderValue=0)
    side = np.float32(FLYING_FRACTION) * step
    with np.errstate(invalid='ignore'):
        return (hi - lo > step) & (z - lo > side) & (hi - z > side)


def bridge_dropouts(depth: npt.NDArray[np.float32], mask: npt.NDArray[np.bool_],
                    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    """``depth`` and ``mask`` with the dropouts inside a surface bridged: a pixel without a
    reading whose 3x3 neighbourhood holds pixels of ``mask`` that agree within
    ``BRIDGE_STEP`` takes the nearest of their depths and joins the mask (not between a
    person and what stands behind them, whose depths disagree)."""
    box = np.ones((3, 3), np.uint8)
    # Outside the image nothing is masked: OpenCV's default border (the float maximum, which
    # is finite) would bridge a border dropout without a masked neighbour to 3.4e38.
    near = cv2.erode(np.where(mask, depth, np.float32(np.inf)).astype(np.float32, copy=False),
                     box, borderType=cv2.BORDER_CONSTANT, borderValue=np.inf)
    far = cv2.dilate(np.where(mask, depth, np.float32(0)).astype(np.float32, copy=False), box,
                     borderType=cv2.BORDER_CONSTANT, borderValue=0)
    fill = (depth <= 0) & np.isfinite(near) & (far - near <= np.float32(BRIDGE_STEP))
    return np.where(fill, near, depth).astype(np.float32, copy=False), mask | fill


# The constants as the numpy code's float32 arithmetic rounds them (for the compiled pass).
_F32_EDGE_STEP = np.float32(EDGE_STEP)
_F32_EDGE_STEP_Z = np.float32(EDGE_STEP_Z)
_F32_FLYING_FRACTION = np.float32(FLYING_FRACTION)
_F32_BRIDGE_STEP = np.float32(BRIDGE_STEP)


def bridged_edges(depth: npt.NDArray[np.float32], mask: npt.NDArray[np.bool_], stride: int, *,
                  flying: bool) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_],
                                         npt.NDArray[np.bool_]]:
    """:func:`bridge_dropouts` of ``depth`` (float32, 0: no reading) and ``mask``, and the
    :func:`far_side_pixels` of the bridged depths: what the static background labels a frame
    from. One compiled pass when :data:`.kernels.ENABLED`, the numpy functions otherwise
    (the reference, and the same arrays)."""
    if not kernels.ENABLED:
        bridged, joined = bridge_dropouts(depth, mask)
        return bridged, joined, far_side_pixels(bridged, stride, flying=flying)
    bridged = np.empty_like(depth)
    joined = np.empty_like(mask)
    far = np.empty_like(mask)
    kernels.bridge_and_far_side(depth, mask, _F32_EDGE_STEP, _F32_EDGE_STEP_Z, np.float32(stride),
                                _F32_FLYING_FRACTION, _F32_BRIDGE_STEP, flying,
                                bridged, joined, far)
    return bridged, joined, far
