"""Predict-update tracker of Section 5: end-effectors kept stable over time.

Per frame t+1:

1. **Single-frame candidates** E^est_{t+1} from Section 4 (:func:`estimate_frame`).
2. **Predict** (§5.1): the end-effectors E_t are moved by the 3D scene flow (dense optical flow
   between the colour images back-projected with depth and K: :mod:`.flow`), giving E^pr_{t+1}.
   Without a colour pair (first frame, dropped colour) the prediction is zero motion.
3. **Rectify**: each prediction snaps to the closest current foreground point, which gives it
   a node of the current topology graph (and its entity). Tracks are predicted and rectified
   through their surface anchor (an end-effector lies a part radius behind the surface). A
   prediction farther than ``max_rectify_distance`` from every point has left the foreground
   and is dropped. Tracks follow the centre of their part's rounded end
   (``Candidate.end_centre``) and publish the part's centre, which for a long part such as a
   hand lies deeper along its axis (``Candidate.centre_shift``, kept by predictions): how
   much of a part is visible moves its centre, not the point that is tracked.
4. **Correspondence**: similarity between a prediction and a candidate is inversely
   proportional to their geodesic distance in the current graph,
   ``s = 1 / (1 + d_G / similarity_scale)``; the Hungarian algorithm (scipy) maximises it.
5. **Cases**: a matched pair with s > ε_a is *related* (case A); with ε_b < s <= ε_a it is an
   *unrelated* pair (case B), where ε_b is the similarity of the larger geodesic distance of the
   two to the root (times ``unrelated_ratio``): two real end-effectors are farther apart than
   either is from the root, so they are not compared; and the candidate must lie on the
   track's limb (within ``case_b_path_distance`` of the path by which the track's end reached
   the root when last detected), for case B is an end replaced by a part of its own limb;
   everything else is *unmatched* (case C).
6. **Selection**: in case B the candidate with the longer approximate geodesic distance
   (Eq. 7, memorised by Eq. 8 for predictions) survives, a memorised one for at most twice as
   many consecutive frames as detections ever supported its track (the paper's warning that
   memory must not get stuck with errors); a case-C prediction is kept at most T frames, and
   no longer than it was detected; an unmatched current candidate starts a new track. In
   case A the pair is one end-effector: the longer geodesic distance is kept, the position
   is the current detection (the paper favours "the natural detection of end-effectors"; the
   prediction only guides it when needed).
7. **Memory** (Eqs. 8-9): a track's geodesic distance is
   ``α d(e_t) + (1 - α) d(e^pr_{t+1})`` with ``α = σ^k`` while it lives on predictions, k the
   frames since it was last related; a detection takes its current Eq. 7 value.

Each track has a stable id, its entity, age, state (detected / predicted) and a confidence:
the chance that it is right, scored from its evidence (:mod:`.confidence`), or with
``scored_confidence`` off the paper's memory weight ``σ^k (T + 1 - m) / (T + 1)`` with m the
consecutive unmatched frames. Ends below ``min_confidence`` are tracked but not returned.
Its published position is filtered along the track (One Euro, :mod:`.smoothing`), which also
gives its velocity; the tracker itself follows the raw positions, so the filter's lag never
enters the matching. A track dropped within ``revive_frames`` gives its id back to a new track
found where it was, or farther on where the same limb is found again
(:meth:`Tracker._revived_ids`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from .assignment import min_cost_assignment
from .background import BackgroundModel
from .bands import UNREACHED
from .confidence import ConfidenceModel, end_features
from .floor import FloorPlane
from .flow import FlowEstimator, propagate_points
from .graph import (
    approximate_geodesic,
    approximate_geodesic_along,
    distance_to_path,
    path_to_sources,
)
from .kinds import KindLabeller, person_points
from .nearest import nearest_point
from .params import EndeffParams
from .readable import ReadableArea
from .single_frame import FrameEstimate, estimate_frame
from .smoothing import OneEuroParams, one_euro
from .types import Candidate, Intrinsics, RGBDFrame, Track

if TYPE_CHECKING:
    from collections.abc import Callable

    import numpy.typing as npt

    #: The tracker's region-of-interest flow: field, top-left pixel (u0, v0), scale (sx, sy).
    RoiFlow = tuple[npt.NDArray[np.float32], tuple[int, int], tuple[float, float]]


#: Pixels around the tracked end-effectors for which optical flow is computed: covers the
#: propagation windows and displacements of ~2.5 m/s at 2 m and 30 Hz.
ROI_MARGIN_PX = 64


@dataclass(frozen=True)
class TrackerResult:
    """Output of one tracker step: the published tracks plus the frame's single-frame estimate."""

    stamp_ns: int
    frame_id: str
    tracks: list[Track]
    estimate: FrameEstimate
    stage_ms: dict[str, float] = field(default_factory=dict)

    def positions(self) -> npt.NDArray[np.float64]:
        """(M, 3) positions of the tracks."""
        return np.array([t.position for t in self.tracks], dtype=np.float64).reshape(-1, 3)


#: Case B keeps a memorised end-effector against a current candidate (Fig. 7b) for at most
#: this many times as many consecutive frames as detections ever supported its track; then
#: the candidate wins. Unbounded, an extreme seen for a few frames (an elbow while a walker's
#: arm swings) held its place for 20 frames and more and dropped the real candidates beside
#: it; at 1 a fist resting on the chest between punches, about as long as it was out, gave
#: way to the elbow (docs/design.md, "Case B memory lasts no longer than twice its evidence").
CASE_B_HOLD_FACTOR = 2
#: A track that went on its prediction no more than this many frames ago takes back a new
#: candidate on its limb within ``revive_distance`` (:meth:`Tracker._resume_predicted`). One
#: held longer is an end-effector its memory kept against the candidates (a fist resting on
#: the chest, Fig. 7b), and a candidate beside it is then another end (the other fist).
RESUME_MAX_HELD = 2
#: A new end-effector beyond ``revive_distance`` takes a lost track's id back only if it
#: points from its entity's root the same way as the lost track did (cosine of the two
#: offsets from the root at least this; :meth:`Tracker._revived_ids`).
REVIVE_FAR_MIN_COSINE = 0.5


def _nearest_pairs(d: npt.NDArray[np.float64], radius: float,
                   accept: Callable[[int, int], bool] | None = None) -> list[tuple[int, int]]:
    """One-to-one (row, column) pairs of the distance matrix ``d`` closer than ``radius``,
    nearest pairs first; ``accept(row, column)`` may refuse a pair (both stay free for
    others). A few new end-effectors and tracks at most: a greedy pass over the sorted
    matrix, no assignment solver."""
    rows: set[int] = set()
    cols: set[int] = set()
    pairs = []
    for flat in np.argsort(d, axis=None):
        i, k = (int(x) for x in np.unravel_index(flat, d.shape))
        if d[i, k] >= radius:
            break
        if i not in rows and k not in cols and (accept is None or accept(i, k)):
            pairs.append((i, k))
            rows.add(i)
            cols.add(k)
    return pairs


class _Lost(NamedTuple):
    """A track dropped in update number ``frame``, last predicted at ``position`` and last
    kept at ``seen`` (where it was before the frame that dropped it), with its memorised
    geodesic distance to the root (Eq. 8) then, its published kind (``Track.kind``) and
    ``offset``, from its entity's root to ``seen`` (None: not known)."""

    id: int
    position: npt.NDArray[np.float64]
    frame: int
    seen: npt.NDArray[np.float64]
    geodesic: float
    kind: int = Track.KIND_OTHER
    offset: npt.NDArray[np.float64] | None = None


@dataclass
class _TrackState:
    """Mutable per-track memory between frames."""

    id: int
    position: npt.NDArray[np.float64]
    geodesic: float  # dist_G^ap memory (Eq. 8)
    entity: int = 0
    not_related: int = 0  # k of Eq. 9
    missed: int = 0  # consecutive case-C frames
    age: int = 1
    path: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    detected: bool = True
    offset: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    hits: int = 1  # frames in which a current candidate supported the track
    protrusion: float = 0.0  # of the candidate that last supported it (Candidate.protrusion)
    # The candidate scorer's chance for the candidate that last supported it, and the sum over
    # all that did (its mean: score_sum / hits); 1 for one not scored (_candidate_score).
    score: float = 1.0
    score_sum: float = 1.0
    held: int = 0  # consecutive frames on its prediction (case B or C)
    # From ``position`` (the rounded end's centre, which is tracked) to the part centre
    # published; a prediction keeps the last detection's (Candidate.centre_shift).
    centre_shift: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    # Published position: raw (``position + centre_shift``) and filtered along the track, its
    # velocity (m/s) and the stamp they belong to (-1: not published yet).
    raw: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    smoothed: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    velocity: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    stamp_ns: int = -1
    moved: float = 0.0  # the highest speed (m/s) of its published velocity so far


def _candidate_score(cand: Candidate) -> float:
    """The candidate scorer's chance for ``cand`` (:mod:`.candidates`); 1 when it was not
    scored (``candidate_floor`` 0: the thresholds alone kept it)."""
    return 1.0 if np.isnan(cand.score) else float(cand.score)


@dataclass(frozen=True)
class _Prediction:
    """A rectified prediction E^pr_{t+1} of one track."""

    track: _TrackState
    position: npt.NDArray[np.float64]
    node: int  # graph node of the closest current point, -1 if none
    entity: int
    geodesic_now: float  # dist_G^ap of the prediction (_predicted_geodesic), nan off-graph


class Tracker:
    """Keeps end-effectors stable over time (Section 5). ``params`` may change between frames."""

    def __init__(self, params: EndeffParams | None = None) -> None:
        self.params = params or EndeffParams()
        self._flow: FlowEstimator | None = None
        self.background = BackgroundModel()
        self.readable = ReadableArea()
        # head, hand, foot or other per track (Track.kind); its models are loaded now when
        # the kinds are scored, so that a broken install fails at start.
        self.kinds = KindLabeller()
        self.kinds.use_models(self.params.scored_kinds)
        # Loaded now when the confidence is scored, so that a broken install fails at start.
        self._confidence_model = ConfidenceModel.load() if self.params.scored_confidence else None
        self.features = np.zeros((0, 0))  # the last published ends' evidence (end_features)
        self.reset(forget_ids=True)

    def reset(self, *, forget_ids: bool = False) -> None:
        """Forget all tracks (e.g. when time jumps backwards during bag replay). New tracks
        get ids never used before, so that a subscriber never confuses an old end-effector with
        a new one; ``forget_ids`` starts them at 0 again (a fresh tracker, a warm-up). The
        static background is kept (the camera still sees the same room), except with
        ``forget_ids``."""
        self._tracks: list[_TrackState] = []
        if forget_ids:
            self.background = BackgroundModel()
            self.readable = ReadableArea()
        if forget_ids or not hasattr(self, '_next_id'):
            self._next_id = 0
        self._prev: RGBDFrame | None = None
        self._floor: FloorPlane | None = None
        self._relearns = self.background.relearns  # camera motions seen (the floor is refitted)
        self._frame = 0  # updates since the reset
        self._lost: list[_Lost] = []  # tracks dropped lately
        self._roots: dict[int, npt.NDArray[np.float64]] = {}  # last update's entity roots
        self._intrinsics: Intrinsics | None = None  # last frame's (the kinds of new ends)

    def reset_background(self, *, empty: bool = False) -> None:
        """Re-learn the static background and fit the floor anew from the next frame (the
        camera may have been moved on purpose); the tracks are kept. ``empty``: the room is
        empty of people now, and all it holds is background
        (:meth:`~endeff_ros.core.background.BackgroundModel.reset`)."""
        self.background.reset(empty=empty)
        self._refit_floor()

    def _refit_floor(self) -> None:
        """Fit the floor anew from the next frame on, until a frame shows one; the current
        plane serves the frames in which none is found (no plane at all would leave the whole
        floor foreground)."""
        if self._floor is not None:
            self._floor = replace(self._floor, refit=True)

    def _flow_estimator(self) -> FlowEstimator:
        if self._flow is None or self._flow.method != self.params.flow_method:
            self._flow = FlowEstimator(self.params.flow_method)
        return self._flow

    def estimate(self, frame: RGBDFrame) -> FrameEstimate:
        """Sections 3-4 of ``frame`` with this tracker's floor: the first step of
        :meth:`update`, which a caller may run early (depth needs no colour, except while
        :attr:`estimate_wants_color`) and pass on."""
        if not self.params.background:
            self.background.reset()  # learnt afresh if it is turned on again
        return estimate_frame(frame, self.params, floor=self._floor,
                              background=self.background if self.params.background else None,
                              readable=self.readable)

    @property
    def estimate_wants_color(self) -> bool:
        """Whether :meth:`estimate` of the next frame should wait for its colour image: while
        the static background learns, the frame's own colour motion decides what is static
        (:attr:`~endeff_ros.core.background.BackgroundModel.wants_color`); a caller running
        Sections 3-4 early without it would see another foreground than ``endeff process``."""
        return self.params.background and self.background.wants_color

    def flow(self, color: npt.NDArray[np.uint8] | None,
             intrinsics: Intrinsics) -> RoiFlow | None:
        """Section 5.1's optical flow from the previous frame's colour image to ``color``
        around the tracked anchors (None when there is nothing to predict): the part of
        :meth:`update` that needs no depth, which a caller may run as soon as the colour
        image arrives and pass on."""
        prev, anchors = self._prev, self._anchors()
        if (len(anchors) == 0 or prev is None or prev.color is None or color is None
                or prev.color.shape != color.shape):
            return None
        return self._roi_flow(prev.color, color, anchors, intrinsics)

    def update(self, frame: RGBDFrame, estimate: FrameEstimate | None = None,
               flow: RoiFlow | None = None) -> TrackerResult:
        """Process one frame and return the current end-effectors. ``estimate`` and
        ``flow``: what :meth:`estimate` and :meth:`flow` returned for this frame's depth and
        colour, if they ran since the last update (with the same parameters); computed here
        otherwise."""
        if estimate is None:
            estimate = self.estimate(frame)
        if self.params.background:  # colour motion, for the next frame's background
            self.background.observe_color(frame.color, frame.stamp_ns)
        self._floor = estimate.floor
        if self.background.relearns != self._relearns:  # the camera moved: fit the floor anew
            self._relearns = self.background.relearns
            self._refit_floor()
        stages = dict(estimate.stage_ms)
        self._intrinsics = frame.intrinsics
        self.kinds.use_models(self.params.scored_kinds)
        t0 = time.perf_counter()
        predicted = self._predict(frame, flow)
        stages['predict'] = (time.perf_counter() - t0) * 1e3
        t0 = time.perf_counter()
        self._tracks = self._update(estimate, predicted)
        self._anchor(estimate)
        self._smooth(frame.stamp_ns)
        stages['update'] = (time.perf_counter() - t0) * 1e3
        self._prev = frame
        tracks = self._score(self.kinds.label([self._publish(t) for t in self._tracks],
                                              estimate, frame.intrinsics), estimate)
        if self.params.background:  # tracked entities are never absorbed by the background
            person = (self.kinds.may_be_people(tracks) if self.background.wants_people
                      else None)
            self.background.protect(self._anchors(), [t.id for t in self._tracks],
                                    frame.intrinsics, self.params.pixel_stride,
                                    detected=[t.detected for t in self._tracks],
                                    person=person,
                                    person_points=person_points(
                                        estimate, [t.entity for t in tracks], person))
        shown = [t for t in tracks if t.confidence >= self.params.min_confidence]
        return TrackerResult(frame.stamp_ns, frame.frame_id, shown, estimate, stages)

    def _score(self, tracks: list[Track], estimate: FrameEstimate) -> list[Track]:
        """The tracks with their evidence (:func:`end_features`, kept in
        :attr:`features` for the tools that fit the model) and, with ``scored_confidence``,
        the model's confidence (:mod:`.confidence`)."""
        self.features = end_features(tracks, self._tracks, estimate, self._intrinsics)
        if not self.params.scored_confidence or not tracks:
            return tracks
        if self._confidence_model is None:
            self._confidence_model = ConfidenceModel.load()
        score = self._confidence_model(self.features)
        return [replace(t, confidence=float(c)) for t, c in zip(tracks, score, strict=True)]

    # -- predict (Section 5.1) ---------------------------------------------------------------

    def _anchor(self, estimate: FrameEstimate) -> None:
        """Remember where each track sits relative to the visible surface.

        An end-effector is the centre of its part, about one radius behind the surface, but
        scene flow moves surface points and rectification snaps to surface points. So the
        surface point closest to the track (its anchor) is what gets predicted and rectified,
        and the offset is added back: prediction and detection then compare like with like.
        """
        if not self._tracks:
            return
        positions = np.array([t.position for t in self._tracks])
        if len(estimate.points) == 0:
            offsets = np.zeros_like(positions)
        else:
            _, nearest = nearest_point(estimate.points, positions)
            offsets = positions - estimate.points[nearest]
        for track, offset in zip(self._tracks, offsets):
            track.offset = offset

    def _anchors(self) -> npt.NDArray[np.float64]:
        return np.array([t.position - t.offset for t in self._tracks]).reshape(-1, 3)

    def _predict(self, frame: RGBDFrame, flow: RoiFlow | None = None,
                 ) -> npt.NDArray[np.float64]:
        """Anchors of E^pr_{t+1}: previous surface anchors moved by the scene flow (zero motion
        without a colour pair)."""
        positions = self._anchors()
        prev = self._prev
        if (len(positions) == 0 or prev is None or prev.color is None or frame.color is None
                or prev.depth.shape != frame.depth.shape):
            return positions
        if flow is None:
            flow = self._roi_flow(prev.color, frame.color, positions, frame.intrinsics)
        moved, _ = propagate_points(positions, flow[0], prev.depth, frame.depth,
                                    frame.intrinsics, flow_origin=flow[1], flow_scale=flow[2])
        return moved

    def _roi_flow(self, prev_color: npt.NDArray[np.uint8], color: npt.NDArray[np.uint8],
                  anchors: npt.NDArray[np.float64], k: Intrinsics) -> RoiFlow:
        """Dense flow where it is needed: inside the box around the tracked anchors (with a
        margin for the window reads and the motion); returns the flow of that region at the
        estimator's working resolution, its top-left pixel (u0, v0) and its scale (sx, sy).
        Elsewhere there is no flow (``propagate_points`` then falls back as for missing
        flow). A person fills a fraction of a 640x480 frame, so this is several times cheaper
        than the whole image and gives the same vectors there."""
        h, w = k.height, k.width
        uv = k.project(anchors[anchors[:, 2] > 1e-6]) if len(anchors) else np.zeros((0, 2))
        uv = uv[np.all(np.isfinite(uv), axis=1)]
        none = np.zeros((0, 0, 2), dtype=np.float32), (0, 0), (1.0, 1.0)
        if len(uv) == 0:
            return none
        margin = ROI_MARGIN_PX
        u0, v0 = (np.floor(uv.min(axis=0)) - margin).astype(int)
        u1, v1 = (np.ceil(uv.max(axis=0)) + margin).astype(int)
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w), min(v1, h)
        if u1 - u0 < 16 or v1 - v0 < 16:
            return none
        flow = self._flow_estimator().flow(prev_color[v0:v1, u0:u1], color[v0:v1, u0:u1],
                                           upsample=False)
        scale = (flow.shape[1] / (u1 - u0), flow.shape[0] / (v1 - v0))
        return flow, (int(u0), int(v0)), scale

    # -- update (Section 5.2) ----------------------------------------------------------------

    def _rectify(self, estimate: FrameEstimate,
                 predicted: npt.NDArray[np.float64]) -> list[_Prediction]:
        """Snap predicted anchors to the closest current point (graph node, entity, Eq. 7),
        then put each track's offset from its anchor back."""
        out: list[_Prediction] = []
        if len(predicted) == 0:
            return out
        p = self.params
        pts = estimate.points
        usable = np.flatnonzero(estimate.subband != UNREACHED)
        if usable.size == 0:
            return [_Prediction(t, predicted[i] + t.offset, -1, t.entity, np.nan)
                    for i, t in enumerate(self._tracks)]
        dist, nearest = nearest_point(pts[usable], predicted)
        for i, track in enumerate(self._tracks):
            if dist[i] > p.max_rectify_distance:
                out.append(_Prediction(track, predicted[i] + track.offset, -1, track.entity,
                                       np.nan))
                continue
            idx = usable[nearest[i]]
            node = int(estimate.subband[idx])
            entity = int(estimate.entity[idx])
            position = pts[idx] + track.offset
            geo = self._predicted_geodesic(estimate, track, entity, node, position)
            out.append(_Prediction(track, position, node, entity, geo))
        return out

    @staticmethod
    def _predicted_geodesic(estimate: FrameEstimate, track: _TrackState, entity: int,
                            node: int, position: npt.NDArray[np.float64]) -> float:
        """dist_G^ap of a rectified prediction (Section 5.2), nan off the entity's graph.

        A predicted candidate is no extremum of the current graph, so, in the paper's words,
        its distance "is assimilated to the approximated geodesic distance in the previous
        frame": Eq. 7 through the mid-band of the track's path when it was last detected,
        dist_E(e^pr, mid_t) + dist_E(mid_t, L_0^0) with the current root. (Eq. 7 through the
        current graph's path instead gives a fist back on the chest the chest's short
        distance, and the elbow, now the arm's extremum, wins case B; docs/design.md.) A track
        without a stored path uses the current graph's path.
        """
        if entity < 0 or estimate.graph is None:
            return np.nan
        ent = estimate.entities[entity]
        if not np.isfinite(estimate.graph.dist[ent.root_node, node]):
            return np.nan
        if len(track.path) >= 2:
            return approximate_geodesic_along(position, track.path, ent.root)
        path = path_to_sources(estimate.graph.pred[ent.root_node], node)
        return approximate_geodesic(position, estimate.graph, path, ent.root)

    def _similarity(self, estimate: FrameEstimate, preds: list[_Prediction],
                    cands: list[Candidate]) -> tuple[npt.NDArray[np.float64],
                                                     npt.NDArray[np.float64]]:
        """Similarity s (P, C) and geodesic distance d_G (P, C) between predictions and
        candidates in the current graph (0 / inf across entities or without a node)."""
        n_p, n_c = len(preds), len(cands)
        geo = np.full((n_p, n_c), np.inf)
        if n_p and n_c and estimate.graph is not None:
            rows = [i for i, pr in enumerate(preds) if pr.node >= 0]
            if rows:
                g = estimate.graph.geodesic_between([preds[i].node for i in rows],
                                                    [c.node for c in cands])
                euclid = np.linalg.norm(np.array([preds[i].position for i in rows])[:, None]
                                        - np.array([c.end_centre for c in cands])[None],
                                        axis=2)
                geo[rows] = np.maximum(g, euclid)
        sim = 1.0 / (1.0 + geo / self.params.similarity_scale)
        return sim, geo

    def _update(self, estimate: FrameEstimate,
                predicted: npt.NDArray[np.float64]) -> list[_TrackState]:
        p = self.params
        self._frame += 1
        # Loop far sides (``loop_far_sides``) are matched too, but start no track.
        listed = [(c, e.entity, side) for e in estimate.entities
                  for side, group in ((False, e.candidates), (True, e.loop_sides))
                  for c in group]
        cands = [c for c, _, _ in listed]
        cand_entity = [entity for _, entity, _ in listed]
        loop_side = [side for _, _, side in listed]
        preds = self._rectify(estimate, predicted)
        sim, geo = self._similarity(estimate, preds, cands)
        rows, cols = (min_cost_assignment(-sim) if sim.size
                      else (np.zeros(0, int), np.zeros(0, int)))
        matched_pred: dict[int, int] = {}
        for i, j in zip(rows, cols):
            if sim[i, j] > 0:
                matched_pred[int(i)] = int(j)

        survivors: list[_TrackState] = []
        used_cands: set[int] = set()
        for i, pr in enumerate(preds):
            track = pr.track
            j = matched_pred.get(i)
            pred_geo = self._memory(track, pr.geodesic_now)  # if it lives on its prediction
            case = 'C'
            if j is not None:
                cand = cands[j]
                if sim[i, j] > p.related_similarity:
                    case = 'A'
                else:
                    eps_b_geo = p.unrelated_ratio * max(pred_geo, cand.geodesic_approx)
                    case = ('B' if geo[i, j] < eps_b_geo and self._on_limb(track, cand)
                            else 'C')
            if case == 'A':
                cand = cands[j]
                used_cands.add(j)
                self._take_detection(track, cand, cand_entity[j], related=True)
                survivors.append(track)
            elif case == 'B':
                cand = cands[j]
                used_cands.add(j)
                if (cand.geodesic_approx >= pred_geo
                        or track.held >= CASE_B_HOLD_FACTOR * track.hits):
                    # The current candidate wins (Fig. 7c): the track follows it. So it does
                    # once the memory has outlasted its evidence (CASE_B_HOLD_FACTOR).
                    self._take_detection(track, cand, cand_entity[j], related=False)
                else:
                    # The memorised end-effector wins (Fig. 7b); the candidate is dropped.
                    self._take_prediction(track, pr, pred_geo, missed=False)
                    if np.linalg.norm(cand.end_centre - pr.position) < p.similarity_scale:
                        # ... unless it is where the prediction is: then it is this
                        # end-effector seen again (a hand leaving the body, its geodesic
                        # distance still short), and the track takes its position.
                        self._reacquire(track, cand)
                survivors.append(track)
            else:
                # Dropped: farther than max_rectify_distance from the foreground (it left), in
                # case C for more than T frames (or for longer than detections ever supported
                # it: a few spurious detections die as fast as they came), or never confirmed
                # (a one-off candidate is not kept alive).
                if (pr.node < 0 or track.missed + 1 > min(p.keep_frames, track.hits)
                        or track.hits < p.confirm_hits):
                    root = self._roots.get(track.entity)
                    self._lost.append(_Lost(
                        track.id, pr.position, self._frame, track.position.copy(),
                        track.geodesic, self.kinds.kind_of(track.id),
                        None if root is None else track.position - root))
                    continue
                self._take_prediction(track, pr, pred_geo, missed=True)
                survivors.append(track)
        new = [j for j in range(len(cands)) if j not in used_cands and not loop_side[j]]
        new = self._resume_predicted(survivors, new, cands, cand_entity)
        far = self._lost and new and self.params.revive_far_distance > 0
        roots = {e.entity: np.asarray(e.root, dtype=np.float64) for e in estimate.entities}
        ids = self._revived_ids(
            [cands[j].end_centre for j in new], [cands[j].geodesic_approx for j in new],
            self._candidate_kinds(estimate, [cands[j] for j in new]) if far else None,
            [cands[j].end_centre - roots[cand_entity[j]] for j in new])
        self._roots = roots
        for j, track_id in zip(new, ids):
            cand = cands[j]
            score = _candidate_score(cand)
            survivors.append(_TrackState(
                id=track_id, position=cand.end_centre, geodesic=cand.geodesic_approx,
                entity=cand_entity[j], path=cand.path, centre_shift=cand.centre_shift,
                protrusion=cand.protrusion, score=score, score_sum=score))
        return self._drop_duplicates(survivors)

    def _on_limb(self, track: _TrackState, cand: Candidate) -> bool:
        """Whether ``cand`` may be case B for ``track``: it lies within
        ``case_b_path_distance`` of the path by which the track's end reached the root when
        last detected. Case B is one end-effector replaced by a part of its own limb while it
        touches the body (Fig. 7b: the elbow of a hand on the chest, near the arm's path).
        Within ε_b of a prediction there may also be another limb's end (a head 0.4-0.6 m
        through the neck from a hand whose track lives on its prediction); without this
        test that end was dropped for the memory, or took the hand's id (Fig. 7c).
        docs/design.md, "Case B stays on the limb"."""
        limit = self.params.case_b_path_distance
        return (limit <= 0 or len(track.path) == 0
                or distance_to_path(cand.end_centre, track.path) <= limit)

    def _resume_predicted(self, survivors: list[_TrackState], new: list[int],
                          cands: list[Candidate], cand_entity: list[int]) -> list[int]:
        """The candidates ``new`` (indices into ``cands``) that no track matched, less those a
        track on its prediction takes back. A track that lost its detection in this frame or
        the one before (``RESUME_MAX_HELD``) takes, as a detection in which its end-effector is
        unrelated to the memory (Eq. 8's second case), the nearest such candidate of its entity
        within ``revive_distance`` that lies on its limb (:meth:`_on_limb`), nearest pairs
        first. Why: the Hungarian matching pairs a prediction with its own end-effector, but
        when their geodesic similarity falls below the case-A and case-B thresholds (the root
        moved, a loop opened or closed) the track goes on predicted (case C) and the candidate
        starts a second track beside it: the same end-effector twice, one copy false, under a
        new id. This is :meth:`_revived_ids` for tracks still alive. docs/design.md, "A track
        on its prediction takes back its end-effector"."""
        predicted = [t for t in survivors if not t.detected and t.held <= RESUME_MAX_HELD]
        if not predicted or not new:
            return new
        d = np.linalg.norm(np.array([cands[j].end_centre for j in new])[:, None]
                           - np.array([t.position for t in predicted])[None], axis=2)
        d[np.array([cand_entity[j] for j in new])[:, None]
          != np.array([t.entity for t in predicted])[None]] = np.inf
        pairs = _nearest_pairs(d, self.params.revive_distance,
                               lambda i, k: self._on_limb(predicted[k], cands[new[i]]))
        for i, k in pairs:
            self._take_detection(predicted[k], cands[new[i]], cand_entity[new[i]],
                                 related=False)
        taken = {i for i, _ in pairs}
        return [j for i, j in enumerate(new) if i not in taken]

    def _candidate_kinds(self, estimate: FrameEstimate, new: list[Candidate]) -> list[int]:
        """The kind this frame gives each candidate of ``new``
        (:meth:`.kinds.KindLabeller.candidate_kinds`; -1: none)."""
        kinds = self.kinds.candidate_kinds(estimate, self._intrinsics)
        index = {id(c): k for k, c in enumerate(c for e in estimate.entities
                                                for c in e.candidates)}
        return [int(kinds[index[id(c)]]) if id(c) in index else -1 for c in new]

    def _revived_ids(self, positions: list[npt.NDArray[np.float64]],
                     geodesics: list[float] | None = None, kinds: list[int] | None = None,
                     offsets: list[npt.NDArray[np.float64]] | None = None) -> list[int]:
        """Ids for new tracks at ``positions`` (with their geodesic distances to the root,
        Eq. 7, ``geodesics``, the kinds this frame gives them, ``kinds``, and their offsets
        from their entity's root, ``offsets``). A track dropped within the last
        ``revive_frames`` frames gives its id back to the nearest new track within
        ``revive_distance`` of where it was last predicted or last kept (nearest pairs
        first): the same end-effector found again after a loss (a hand that was no extremum
        for a few frames, a foot hidden behind the other leg for half a second, a foot lost
        while the camera turns) keeps its id for a subscriber. So does one too young to
        have been kept alive (``confirm_hits``): an end that is an extreme in a frame or
        two at a time would otherwise get a new id each time. Where it was kept counts as
        well as its last prediction because a track is mostly dropped when that prediction
        left the foreground (the flow lost the part), so the prediction is the wrong place
        to look for it. The window is longer than T (case C keeps a track alive on its
        prediction, which costs false positives; remembering an id costs nothing): most of
        the ends found again under a new id on the dev split had been lost for 4 frames or
        more.

        Beyond ``revive_distance``, up to ``revive_far_distance``, the id comes back only to
        a new track on the same limb: a foot lost in a cartwheel or a kick is found again
        0.3-0.8 m on, and at that distance the nearest new end is as often another limb's.
        Three tests, each for a way the wrong limb was taken: the geodesic distance to the
        root within ``revive_geodesic_tolerance`` of the lost track's memory (a head or a
        knee where a hand was lost); neither the lost track (its published kind) nor the new
        end (the kind this frame gives it) a head, which moves with the trunk and is never
        the fast end, while a head-like end far from a lost one is a raised hand or a kicking
        foot; and both pointing the same way from their entity's root
        (:data:`REVIVE_FAR_MIN_COSINE`: a hand and a foot have similar geodesic distances but
        leave the root up and down). Quick mocap dev split (ids replayed over one run):
        103 id switches with ``revive_distance`` alone, 73 with the geodesic test alone but
        swaps between limbs 13 -> 15 (11 of 38 checkable far revivals to another end), 81
        with all three and 13 swaps (5 of 26); the lost and new kinds asked to agree for
        hands and feet too cost 2 more switches (an acrobat's raised feet are labelled
        hands) for no fewer swaps (docs/design.md, "An id comes back"). Otherwise a new id,
        never used before."""
        p = self.params
        self._lost = [lost for lost in self._lost if self._frame - lost.frame <= p.revive_frames]
        ids: list[int | None] = [None] * len(positions)
        if self._lost and positions and p.revive_distance > 0:
            new = np.array(positions)[:, None]
            d = np.minimum(
                np.linalg.norm(new - np.array([lost.position for lost in self._lost])[None],
                               axis=2),
                np.linalg.norm(new - np.array([lost.seen for lost in self._lost])[None], axis=2))
            if geodesics is None:
                same_limb = np.zeros(d.shape, dtype=bool)
            else:
                same_limb = (np.abs(np.asarray(geodesics, dtype=np.float64)[:, None]
                                    - np.array([lost.geodesic for lost in self._lost])[None])
                             <= p.revive_geodesic_tolerance)
                same_limb &= np.array([lost.kind != Track.KIND_HEAD for lost in self._lost])[None]
                if kinds is not None:
                    same_limb &= np.asarray(kinds)[:, None] != Track.KIND_HEAD
                if offsets is not None:
                    for i, k in zip(*np.nonzero(same_limb)):
                        a, b = offsets[i], self._lost[k].offset
                        if b is not None and (a @ b < REVIVE_FAR_MIN_COSINE * np.linalg.norm(a)
                                              * np.linalg.norm(b)):
                            same_limb[i, k] = False
            pairs = _nearest_pairs(
                d, max(p.revive_distance, p.revive_far_distance),
                lambda i, k: bool(d[i, k] < p.revive_distance or same_limb[i, k]))
            for i, k in pairs:
                ids[i] = self._lost[k].id
            taken = {k for _, k in pairs}
            self._lost = [lost for k, lost in enumerate(self._lost) if k not in taken]
        return [self._new_id() if i is None else i for i in ids]

    def _drop_duplicates(self, tracks: list[_TrackState]) -> list[_TrackState]:
        """Remove predicted tracks closer than ``duplicate_distance`` to a track kept before
        them (detections first, then by memorised geodesic distance): a prediction that ends
        up on an end-effector another track already holds is the same end-effector twice."""
        radius = self.params.duplicate_distance
        if radius <= 0 or len(tracks) < 2:
            return tracks
        order = sorted(tracks, key=lambda t: (not t.detected, -t.geodesic))
        kept: list[_TrackState] = []
        for t in order:
            if not t.detected and any(np.linalg.norm(t.position - k.position) < radius
                                      for k in kept):
                continue
            kept.append(t)
        return sorted(kept, key=lambda t: t.id)

    def _memory(self, track: _TrackState, geodesic_now: float) -> float:
        """Eq. 8 for a track that continues on its prediction: α = σ^k (Eq. 9), k counting
        this frame, in which it is not related to any candidate."""
        k = track.not_related + 1
        alpha = self.params.memory_sigma ** k
        if not np.isfinite(geodesic_now):
            return track.geodesic * alpha
        return alpha * track.geodesic + (1.0 - alpha) * geodesic_now

    @staticmethod
    def _take_detection(track: _TrackState, cand: Candidate, entity: int, *,
                        related: bool) -> None:
        Tracker._reacquire(track, cand)
        if related:
            # Case A: the pair is one end-effector and the longer geodesic distance is
            # selected; with α = σ^0 = 1 the memorised one survives (Eq. 8), which keeps a
            # hand's distance while it approaches the body (Fig. 3b).
            track.geodesic = max(track.geodesic, cand.geodesic_approx)
        else:
            track.geodesic = cand.geodesic_approx  # Eq. 8, second case
        track.entity = entity
        track.not_related = 0 if related else track.not_related + 1
        track.missed = 0
        track.age += 1

    @staticmethod
    def _take_prediction(track: _TrackState, pr: _Prediction, geodesic: float, *,
                         missed: bool) -> None:
        track.position = pr.position
        track.geodesic = geodesic  # Eq. 8, first case
        track.entity = pr.entity
        track.not_related += 1
        track.missed = track.missed + 1 if missed else 0
        track.held += 1
        track.age += 1
        track.detected = False

    @staticmethod
    def _reacquire(track: _TrackState, cand: Candidate) -> None:
        """A case-B track whose memory won keeps it, but takes the position of a candidate
        lying where it was predicted. Also the part of every detection that
        :meth:`_take_detection` shares: position, part-centre shift, path, support."""
        track.position = cand.end_centre
        track.centre_shift = cand.centre_shift
        track.path = cand.path
        track.protrusion = cand.protrusion
        track.score = _candidate_score(cand)
        track.score_sum += track.score
        track.held = 0
        track.hits += 1
        track.detected = True

    def _new_id(self) -> int:
        self._next_id += 1
        return self._next_id - 1

    def _smooth(self, stamp_ns: int) -> None:
        """Filter each track's published position along the track (One Euro,
        :mod:`.smoothing`) and estimate its velocity; a track's first frame takes its raw
        position and zero velocity. Output only: the tracker itself follows the raw
        positions, so the filter's lag never enters the matching."""
        p = self.params
        raw = np.array([t.position + t.centre_shift for t in self._tracks]).reshape(-1, 3)
        old = np.array([t.stamp_ns >= 0 for t in self._tracks], dtype=bool)
        smoothed, velocity = raw.copy(), np.zeros_like(raw)
        if old.any():
            tracks = [t for t, o in zip(self._tracks, old, strict=True) if o]
            dt = (stamp_ns - np.array([t.stamp_ns for t in tracks], dtype=np.float64)) * 1e-9
            smoothed[old], velocity[old] = one_euro(
                raw[old], [t.raw for t in tracks], [t.smoothed for t in tracks],
                [t.velocity for t in tracks], dt,
                OneEuroParams(p.smoothing_min_cutoff, p.smoothing_beta, p.smoothing_d_cutoff,
                              p.smoothing_max_lag, p.smoothing_reset_distance))
        for t, r, s, v in zip(self._tracks, raw, smoothed, velocity, strict=True):
            t.raw, t.smoothed, t.velocity, t.stamp_ns = r, s, v, stamp_ns
            t.moved = max(t.moved, float(np.linalg.norm(v)))

    def _publish(self, t: _TrackState) -> Track:
        p = self.params
        confidence = (p.memory_sigma ** t.not_related
                      * (p.keep_frames + 1 - t.missed) / (p.keep_frames + 1))
        return Track(id=t.id, entity=t.entity,
                     position=np.array(t.smoothed if p.smoothing else t.raw, dtype=np.float64),
                     geodesic=float(t.geodesic), confidence=float(np.clip(confidence, 0, 1)),
                     state=Track.DETECTED if t.detected else Track.PREDICTED, age=t.age,
                     path=t.path, velocity=np.array(t.velocity, dtype=np.float64),
                     raw_position=np.array(t.raw, dtype=np.float64))
