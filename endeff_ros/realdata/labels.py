"""Hand labels of the real frames: picked pixels lifted to 3D end-effector centres.

A label is picked by hand on a rendering of the frame (``python -m endeff_ros.realdata render``
draws the pixel grid and the current labels): the pixel ``(u, v)`` at the centre of the visible
part and a radius ``r_px`` that stays inside the part. The 3D label is the centre of the part,
behind its visible surface (the benchmark-bag contract): the surface depth is the median depth
of the part's pixels (the disk's pixels within :data:`SAME_PART_MM` of the depth at the picked
pixel, so that background or a limb behind does not count), plus the part's radius
(:data:`RADIUS_M`: head 0.09 m, hand 0.04 m, foot 0.04 m) along the viewing ray of ``(u, v)``.

The labels file (YAML) keeps the picks and the lifted values side by side, so that a reviewer
can move a pick and re-lift (``python -m endeff_ros.realdata label``)::

    frames:
    - frame: depth-data-1028894671
      labels:
      - {id: 0, kind: head, u: 305, v: 165, r_px: 30, depth_m: 1.112,
         xyz: [-0.029, -0.147, 1.202], note: ...}

Ids as the contract: per person 0 head, 1 left hand, 2 right hand, 3 left foot, 4 right foot,
+5 per further person; left is the person's left.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from endeff_ros.scoring import PERSON_KINDS

if TYPE_CHECKING:
    import numpy.typing as npt

    from endeff_ros.core.types import Intrinsics

RADIUS_M = {'head': 0.09, 'hand': 0.04, 'foot': 0.04}
"""Distance (m) from a part's visible surface to its centre, along the viewing ray."""
SAME_PART_MM = 100
"""Disk pixels farther than this (mm) from the picked pixel's depth belong to something else."""


class LabelError(ValueError):
    """A label is unusable (the message names the frame and id)."""


@dataclass(frozen=True)
class Label:
    """One end-effector label of one frame (pixels, metres)."""

    frame: str
    id: int
    kind: str
    u: int
    v: int
    r_px: int
    depth_m: float
    xyz: tuple[float, float, float]
    note: str = ''

    def to_yaml(self) -> dict[str, Any]:
        """The YAML mapping of this label (frame given by the enclosing entry)."""
        out: dict[str, Any] = {'id': self.id, 'kind': self.kind, 'u': self.u, 'v': self.v,
                               'r_px': self.r_px, 'depth_m': round(self.depth_m, 4),
                               'xyz': [round(c, 4) for c in self.xyz]}
        if self.note:
            out['note'] = self.note
        return out


def surface_depth_m(depth_mm: npt.NDArray[np.uint16], u: int, v: int, r_px: int) -> float:
    """Median depth (m) of the part around pixel ``(u, v)``: valid pixels within ``r_px`` whose
    depth is within :data:`SAME_PART_MM` of the picked pixel's (median of its 3x3 readings);
    ``nan`` if the pick has no reading around it."""
    h, w = depth_mm.shape
    v0, v1, u0, u1 = max(v - r_px, 0), min(v + r_px + 1, h), max(u - r_px, 0), min(u + r_px + 1, w)
    patch = depth_mm[v0:v1, u0:u1].astype(np.float64)
    vv, uu = np.mgrid[v0:v1, u0:u1]
    disk = ((uu - u) ** 2 + (vv - v) ** 2 <= r_px ** 2) & (patch > 0)
    seed = depth_mm[max(v - 1, 0):v + 2, max(u - 1, 0):u + 2]
    seed = seed[seed > 0]
    if seed.size == 0:
        if not disk.any():
            return float('nan')
        seed = patch[disk]
    centre = float(np.median(seed))
    part = disk & (np.abs(patch - centre) <= SAME_PART_MM)
    return float(np.median(patch[part])) / 1000.0


def lift(intr: Intrinsics, u: float, v: float, z: float) -> tuple[float, float, float]:
    """Optical-frame point (m) at depth ``z`` on the viewing ray of pixel ``(u, v)``."""
    return ((u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy, z)


def make_label(frame: str, depth_mm: npt.NDArray[np.uint16], intr: Intrinsics,
               pick: dict[str, Any]) -> Label:
    """Lift one pick (``id``, ``u``, ``v``, ``r_px``, optional ``kind`` and ``note``)."""
    try:
        ident, u, v, r = int(pick['id']), int(pick['u']), int(pick['v']), int(pick['r_px'])
    except (KeyError, TypeError, ValueError) as err:
        msg = f'{frame}: label {pick!r} needs integer id, u, v and r_px ({err})'
        raise LabelError(msg) from err
    kind = PERSON_KINDS[ident % len(PERSON_KINDS)]
    if pick.get('kind', kind) != kind:
        msg = f'{frame}: label id {ident} is a {kind} (id % 5), not a {pick["kind"]}'
        raise LabelError(msg)
    if not (0 <= u < intr.width and 0 <= v < intr.height) or r <= 0:
        msg = f'{frame}: label id {ident} at pixel ({u}, {v}) r {r} is outside the image'
        raise LabelError(msg)
    surface = surface_depth_m(depth_mm, u, v, r)
    if not np.isfinite(surface):
        msg = f'{frame}: label id {ident} at pixel ({u}, {v}) has no depth reading around it'
        raise LabelError(msg)
    xyz = lift(intr, u, v, surface + RADIUS_M[kind])
    return Label(frame, ident, kind, u, v, r, surface, xyz, str(pick.get('note', '')))


def read_labels(path: str | Path) -> dict[str, list[dict[str, Any]]]:
    """``{frame name: [label mappings]}`` from a labels YAML file."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding='utf-8'))
        return {str(f['frame']): list(f.get('labels') or []) for f in doc['frames']}
    except (OSError, yaml.YAMLError, KeyError, TypeError) as err:
        msg = f'{path}: not a labels file (need frames: [{{frame, labels}}]): {err}'
        raise LabelError(msg) from err


def write_labels(path: str | Path, labels: dict[str, list[Label]], header: str) -> None:
    """Write labels as YAML, one line per label (frames in the given order), ``header`` as a
    leading comment."""
    lines = [f'# {line}' if line else '#' for line in header.splitlines()] + ['frames:']
    for name, labs in labels.items():
        lines += [f'- frame: {name}', '  labels:']
        lines += ['  - ' + yaml.safe_dump(lab.to_yaml(), sort_keys=False, default_flow_style=True,
                                          width=1000).strip() for lab in labs]
    Path(path).write_text('\n'.join(lines) + '\n', encoding='utf-8')


def gt_arrays(labels: list[Label]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint32]]:
    """(M, 3) positions and (M,) ids of one frame's labels, ordered by id."""
    labels = sorted(labels, key=lambda lab: lab.id)
    pts = np.array([lab.xyz for lab in labels], np.float64).reshape(-1, 3)
    return pts, np.array([lab.id for lab in labels], np.uint32)
