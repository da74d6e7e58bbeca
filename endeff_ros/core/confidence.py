"""The published ``confidence``: the chance that an end-effector is right, from its evidence.

Section 5 gives each track a memory weight (``σ^k``) and a keep-alive count; as a confidence
they order right and wrong ends loosely (every detected end gets 1.0, and in a furnished room
four of five of them are wrong). Instead every published end is scored from the evidence the
estimator and the tracker already hold, combined in one model rather than in a cascade of
thresholds:

- its track's history: age, the share of its frames a candidate supported it, whether one
  supports it now, frames since it was last related (k of Eq. 9) and unmatched (case C);
- its place: height above the floor, distance to the image's border (a body cut by the
  border or a dead margin ends there), distance to the sensor;
- its geometry: Eq. 7 geodesic distance, its protrusion when the iterated Dijkstra found it
  (compared with g), the straightness of its path (root-to-end distance over geodesic), how
  far its part centre lies behind the rounded end;
- its place among its entity's ends: their count, its geodesic over the entity's longest,
  the nearest other end (second copies beside a hand); the entity's size;
- its speed now and the highest its track ever had, and the part it is (``kind``);
- the candidate scorer's verdict (:mod:`.candidates`) on the candidate that last supported
  it and its mean over the track's supporting candidates: the scorer sees a candidate's
  shape in one frame, the confidence adds what the track has seen since.

The model is additive and logistic: each feature cut at fixed edges (quantiles of the
training ends), one weight per interval, ``confidence = 1 / (1 + exp(-(b + sum_f w_f[bin])))``.
An additive model over binned features learns a non-monotone effect per feature (an end too
close to its neighbour is doubtful, so is one whose geodesic distance is a fraction of its
entity's longest) and is calibrated by its fit: trained by maximum likelihood, its
probabilities match the observed frequencies on the training ends. It is small (a few hundred
numbers, :data:`MODEL_FILE`), evaluated with numpy, and reproduced by
``python -m tools.train_confidence`` from the ``dev`` split (docs/design.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .additive import AdditiveModel, read_model
from .placement import NO_FLOOR as NO_FLOOR  # re-exported: the sentinel of `height`
from .placement import height_and_border

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

    from .single_frame import FrameEstimate
    from .types import Intrinsics, Track

MODEL_FILE = Path(__file__).with_name('confidence_model.json')
"""The committed model (``tools/train_confidence.py`` writes it)."""

FEATURES = ('age', 'hit_ratio', 'detected', 'not_related', 'missed', 'geodesic',
            'protrusion', 'straightness', 'shift', 'depth', 'entity_ends', 'geodesic_share',
            'nearest_end', 'entity_size', 'height', 'border', 'speed', 'moved', 'head', 'hand',
            'foot', 'candidate_score', 'score_mean')
"""Feature names, in column order of :func:`end_features`."""
_COLUMN = {name: i for i, name in enumerate(FEATURES)}

_HORIZON = 30  # frames: longer histories are alike (a second at 30 Hz)


def end_features(published: Sequence[Track], states: Sequence[Any],
                 estimate: FrameEstimate, intrinsics: Intrinsics | None = None,
                 ) -> npt.NDArray[np.float64]:
    """(M, len(FEATURES)) evidence per published end. ``states`` are the tracker's
    per-track memories in the same order (``age``, ``hits``, ``detected``, ``not_related``,
    ``missed``, ``protrusion``, ``centre_shift``, ``moved``, ``score``, ``score_sum``),
    ``estimate`` the frame's
    (entities, roots, points, floor), ``intrinsics`` its camera (None: no image border)."""
    m = len(published)
    out = np.zeros((m, len(FEATURES)))
    if m == 0:
        return out
    pos = np.array([t.position for t in published], dtype=np.float64).reshape(-1, 3)
    entity = np.array([t.entity for t in published])
    geo = np.array([t.geodesic for t in published], dtype=np.float64)
    age = np.array([s.age for s in states], dtype=np.float64)
    col = _COLUMN
    out[:, col['age']] = np.log1p(np.minimum(age, 10 * _HORIZON))
    out[:, col['hit_ratio']] = np.array([s.hits for s in states]) / np.maximum(age, 1)
    out[:, col['detected']] = [float(s.detected) for s in states]
    out[:, col['not_related']] = np.minimum([s.not_related for s in states], _HORIZON)
    out[:, col['missed']] = np.minimum([s.missed for s in states], _HORIZON)
    out[:, col['geodesic']] = np.where(np.isfinite(geo), geo, 0.0)
    out[:, col['protrusion']] = [s.protrusion for s in states]
    out[:, col['candidate_score']] = [s.score for s in states]
    out[:, col['score_mean']] = [s.score_sum / max(s.hits, 1) for s in states]
    out[:, col['shift']] = [float(np.linalg.norm(s.centre_shift)) for s in states]
    out[:, col['depth']] = pos[:, 2]
    out[:, col['speed']] = np.minimum(
        np.linalg.norm(np.array([t.velocity for t in published]).reshape(-1, 3), axis=1), 5.0)
    out[:, col['moved']] = np.minimum([s.moved for s in states], 5.0)
    out[:, col['height']], out[:, col['border']] = height_and_border(pos, estimate.floor,
                                                                     intrinsics)
    kind = np.array([t.kind for t in published])
    for name, code in (('head', 1), ('hand', 2), ('foot', 3)):
        out[:, col[name]] = kind == code
    roots = {e.entity: (np.asarray(e.root, dtype=np.float64), e.point_index)
             for e in estimate.entities}
    points = estimate.points
    for e in np.unique(entity):
        of = np.flatnonzero(entity == e)
        out[of, col['entity_ends']] = len(of)
        longest = np.max(out[of, col['geodesic']])
        out[of, col['geodesic_share']] = out[of, col['geodesic']] / longest if longest > 0 else 1
        if len(of) > 1:
            d = np.linalg.norm(pos[of, None] - pos[None, of], axis=2)
            np.fill_diagonal(d, np.inf)
            out[of, col['nearest_end']] = np.minimum(d.min(axis=1), 1.0)
        else:
            out[of, col['nearest_end']] = 1.0
        root, index = roots.get(int(e), (None, None))
        if root is not None:
            reach = np.linalg.norm(pos[of] - root, axis=1)
            out[of, col['straightness']] = np.minimum(
                reach / np.maximum(out[of, col['geodesic']], 1e-3), 1.5)
            ext = points[index]
            out[of, col['entity_size']] = (float(np.linalg.norm(ext.max(axis=0) - ext.min(axis=0)))
                                           if len(ext) else 0.0)
    return out


class ConfidenceModel(AdditiveModel):
    """The additive logistic model of the published confidence (see the module), over the
    columns of :func:`end_features`."""

    COLUMNS = FEATURES
    WHAT = 'confidence'

    @classmethod
    def load(cls, path: str | Path = MODEL_FILE) -> ConfidenceModel:
        """The model in ``path`` (default the committed :data:`MODEL_FILE`); raises
        ValueError naming the file when it cannot be read or is malformed."""
        return read_model(path, cls.from_json)
