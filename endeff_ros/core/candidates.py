"""The candidate scorer: over-generated extremes kept by their evidence, not by thresholds.

Section 4 keeps an extreme of the iterated Dijkstra when it protrudes g or more from the
found paths; the estimator adds a cascade of thresholds (the chain rule below g, broad
corners, ends cut by the view), each a trade of true for false ends. With
``candidate_floor`` > 0 the estimator instead over-generates: the iteration goes on past
those thresholds down to ``candidate_floor``, broad corners and cut ends are kept, and each
candidate carries the thresholds' verdicts (:class:`~.types.Candidate`). This module scores
them from their evidence combined in one additive logistic model (:mod:`.additive`, fitted by
``python -m tools.train_candidates`` on the ``dev`` split), the chance that the candidate is
an end-effector, from:

- the thresholds' verdict and its parts: protrusion from the found paths, the rank in which
  the iteration found it, broad corner, cut by the view;
- its shape: the terminal part's width, protrusion over width (aspect), the Eq. 6 geodesic
  distance and its share of the entity's longest, straightness (root-to-end distance over
  geodesic), how far the part centre lies behind the rounded end;
- its node in the graph: how much farther from the root (Eq. 6) it lies than its farthest
  neighbour (an end is a local maximum; an elbow on a bent arm is passed by the forearm),
  its neighbour count (an end hangs on one) and its points;
- its neighbours: the nearest other candidate of its entity, the entity's candidate count
  and how many of them the thresholds keep (a person has five ends: a sixth candidate found
  past the thresholds is most likely an elbow or a knee), the entity's size and points;
- its place: distance to the sensor, height above the floor, distance to the image border.

A candidate the thresholds pass over is kept when it scores ``min_candidate_score`` or more,
one they keep is dropped only when it scores below ``drop_candidate_score``
(:func:`select_candidates`). Without ``candidate_scorer`` the thresholds' verdicts decide, so
over-generation alone changes no output (the training tool collects the evidence that way).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import numpy as np

from .additive import AdditiveModel, read_model
from .placement import height_and_border

if TYPE_CHECKING:
    import numpy.typing as npt

    from .floor import FloorPlane
    from .params import EndeffParams
    from .types import Intrinsics


class FrameEstimate(Protocol):
    """What this module reads of a :class:`~.single_frame.FrameEstimate` (which imports
    this module, so it is described here rather than imported)."""

    points: npt.NDArray[np.float64]
    entities: Sequence[Any]
    floor: FloorPlane | None

    def positions(self) -> npt.NDArray[np.float64]: ...


E = TypeVar('E', bound=FrameEstimate)

MODEL_FILE = Path(__file__).with_name('candidate_model.json')
"""The committed model (``tools/train_candidates.py`` writes it)."""

FEATURES = ('thresholds', 'protrusion', 'order', 'broad', 'cut', 'width', 'aspect',
            'geodesic', 'geodesic_share', 'straightness', 'shift', 'nearest', 'count',
            'entity_size', 'entity_points', 'depth', 'height', 'border', 'rise', 'degree',
            'node_points', 'found')
"""Feature names, in column order of :func:`candidate_features`."""
BINARY = ('thresholds', 'broad', 'cut')
"""Features that are 0 or 1."""
_COLUMN = {name: i for i, name in enumerate(FEATURES)}


class CandidateModel(AdditiveModel):
    """The additive logistic model of a candidate's chance of being an end-effector, over
    the columns of :func:`candidate_features`."""

    COLUMNS = FEATURES
    WHAT = 'candidate'

    @classmethod
    def load(cls, path: str | Path = MODEL_FILE) -> CandidateModel:
        """The model in ``path`` (default the committed :data:`MODEL_FILE`); raises
        ValueError naming the file when it cannot be read or is malformed."""
        return read_model(path, cls.from_json)


_MODEL: CandidateModel | None = None


def committed_model() -> CandidateModel:
    """The committed model, read once per process."""
    global _MODEL
    if _MODEL is None:
        _MODEL = CandidateModel.load()
    return _MODEL


def candidate_features(estimate: FrameEstimate,
                       intrinsics: Intrinsics | None = None) -> npt.NDArray[np.float64]:
    """(M, len(FEATURES)) evidence per candidate of ``estimate``, entities in order, each
    entity's candidates in order (as :meth:`~.single_frame.FrameEstimate.positions`)."""
    cands = [(e, c) for e in estimate.entities for c in e.candidates]
    out = np.zeros((len(cands), len(FEATURES)))
    if not cands:
        return out
    col = _COLUMN
    pos = np.array([c.position for _, c in cands], dtype=np.float64).reshape(-1, 3)
    geo = np.array([c.geodesic for _, c in cands], dtype=np.float64)
    geo = np.where(np.isfinite(geo), geo, 0.0)
    width = np.array([c.width for _, c in cands], dtype=np.float64)
    protrusion = np.array([c.protrusion for _, c in cands], dtype=np.float64)
    out[:, col['thresholds']] = [c.thresholds for _, c in cands]
    out[:, col['protrusion']] = np.minimum(protrusion, 2.0)
    out[:, col['order']] = np.minimum([c.order for _, c in cands], 12)
    out[:, col['broad']] = [c.broad for _, c in cands]
    out[:, col['cut']] = [c.cut for _, c in cands]
    out[:, col['width']] = np.where(np.isfinite(width), np.minimum(width, 1.0), 1.0)
    out[:, col['aspect']] = np.where(np.isfinite(width) & (width > 0),
                                     np.minimum(protrusion / np.maximum(width, 1e-3), 10.0), 10.0)
    out[:, col['geodesic']] = np.minimum(geo, 3.0)
    out[:, col['shift']] = [float(np.linalg.norm(c.centre_shift)) for _, c in cands]
    out[:, col['depth']] = pos[:, 2]
    out[:, col['height']], out[:, col['border']] = height_and_border(pos, estimate.floor,
                                                                     intrinsics)
    start = 0
    for entity in estimate.entities:
        n = len(entity.candidates)
        if n == 0:
            continue
        of = slice(start, start + n)
        start += n
        longest = float(np.max(geo[of]))
        out[of, col['geodesic_share']] = geo[of] / longest if longest > 0 else 1.0
        out[of, col['count']] = min(n, 12)
        out[of, col['found']] = min(sum(c.thresholds for c in entity.candidates), 12)
        if n > 1:
            d = np.linalg.norm(pos[of, None] - pos[None, of], axis=2)
            np.fill_diagonal(d, np.inf)
            out[of, col['nearest']] = np.minimum(d.min(axis=1), 1.0)
        else:
            out[of, col['nearest']] = 1.0
        reach = np.linalg.norm(pos[of] - np.asarray(entity.root, dtype=np.float64), axis=1)
        out[of, col['straightness']] = np.minimum(reach / np.maximum(geo[of], 1e-3), 1.5)
        ext = estimate.points[entity.point_index]
        out[of, col['entity_size']] = (float(np.linalg.norm(ext.max(axis=0) - ext.min(axis=0)))
                                       if len(ext) else 0.0)
        out[of, col['entity_points']] = np.log1p(len(ext))
        graph = entity.graph
        nodes = np.array([c.node for c in entity.candidates])
        from_root = graph.dist[entity.root_node]
        edges = graph.dense_weights[nodes] > 0
        beside = np.where(edges, from_root[None, :], -np.inf).max(axis=1)
        rise = np.where(np.isfinite(beside), from_root[nodes] - beside, 0.3)
        out[of, col['rise']] = np.clip(np.nan_to_num(rise, nan=0.0), -0.3, 0.3)
        out[of, col['degree']] = np.minimum(edges.sum(axis=1), 6)
        out[of, col['node_points']] = np.log1p(graph.sizes[nodes])
    return out


def select_candidates(estimate: E, intrinsics: Intrinsics, params: EndeffParams) -> E:
    """``estimate`` with only the candidates kept, each with its score (NaN without the
    scorer). With ``candidate_scorer``, by the committed model's score: a candidate the
    thresholds keep stays unless it scores below ``drop_candidate_score``, any other needs
    ``min_candidate_score``. Why two: dropping an end the thresholds found risks a person's
    hand, adding one they passed over risks an elbow; people first, the scorer overrules the
    thresholds' yes only when it is sure (dev clip halves held out in turn, people: the score
    alone at 0.4 gained 0.3-0.4 points of recall, this rule 3.9-4.3, both with fewer false
    ends; docs/design.md).
    Without it, by the thresholds' verdicts."""
    if not any(e.candidates for e in estimate.entities):
        return estimate
    features = candidate_features(estimate, intrinsics)
    by_thresholds = features[:, _COLUMN['thresholds']] > 0.5
    if params.candidate_scorer:
        score = committed_model()(features)
        keep = np.where(by_thresholds, score >= params.drop_candidate_score,
                        score >= params.min_candidate_score)
    else:
        score, keep = np.full(len(features), np.nan), by_thresholds
    entities, start = [], 0
    for e in estimate.entities:
        of = slice(start, start + len(e.candidates))
        entities.append(dataclasses.replace(e, candidates=[
            dataclasses.replace(c, score=float(s))
            for c, s, k in zip(e.candidates, score[of], keep[of], strict=True) if k]))
        start += len(e.candidates)
    return dataclasses.replace(estimate, entities=entities, scored=Scored(  # type: ignore[type-var]
        features, estimate.positions(), keep))


@dataclasses.dataclass(frozen=True)
class Scored:
    """Every over-generated candidate of a frame, before the selection: its evidence
    (M, len(FEATURES)), position (M, 3) and whether it was kept (M,)."""

    features: npt.NDArray[np.float64]
    positions: npt.NDArray[np.float64]
    kept: npt.NDArray[np.bool_]
