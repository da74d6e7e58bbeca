"""Scoring of estimated end-effectors against ground truth (the paper's Section 6.1).

Pure numpy/scipy: no ROS imports, so ``endeff eval`` and the tests run without ROS.

Per scored frame t the estimated end-effectors are matched one-to-one to the ground-truth points
by the Hungarian method on Euclidean distances (minimum total distance); a matched pair within
``threshold`` (0.15 m) is a true positive (TP). Every estimate that is not a TP is a false
positive (FP).

- Recall_t = TP_t / #GT_t                                           (Eq. 10)
- mean error = mean Euclidean distance over all TP pairs              (Eq. 11)
- FPR_t = FP_t / #estimated_t, 0 when nothing was estimated           (Eq. 12)

A sequence's recall and FPR are the means over its scored frames; its mean error is the mean over
all TP pairs of the sequence. Overall figures are the means over sequences.

Conventions for cases the paper does not cover (documented in the report, never silently):

- a scored frame whose ground truth is empty has no defined recall; it counts for FPR only;
- a sequence without any TP has no mean error (``nan``; ``None`` in JSON); a sequence without
  scored frames has no recall and no FPR; undefined values are left out of the overall means.

Per end-effector kind (head, hand, foot of a person; ``other`` for any other entity), the
recall of a kind is the number of its ground-truth points matched as TPs over all of its
ground-truth points (pooled over the frames of a sequence, since a kind has at most a few
points per frame), and its mean error the mean over those TP pairs. The matching is the same
one-to-one matching over all kinds as above, so a kind's recall never counts an estimate that
the frame's Hungarian assignment gave to another point.

A ground-truth point is *seen* in a frame when the depth image holds at least
:data:`SEEN_MIN_READINGS` readings within :data:`SEEN_RADIUS_M` of it (:func:`seen_labels`).
The benchmark counts every end-effector in view, seen or not (the paper's M_human is
constant), so a hand behind a shelf or beyond the sensor's range is a miss whatever a
single-frame estimator does; the recall over the seen points (``seen_recall``, extra report
keys) separates those from the estimator's own misses. It is a diagnostic only: the scores
above do not use it.

References
----------
Lin, Pardàs & Casas, *Time-consistent estimation of end-effectors from RGB-D data*, 2016,
Section 6.1, Eqs. 10-12.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .core.assignment import min_cost_assignment

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    import numpy.typing as npt

MATCH_THRESHOLD_M = 0.15
"""A Hungarian match within this distance (metres) is a true positive (Section 6.1)."""

PERSON_KINDS = ('head', 'hand', 'hand', 'foot', 'foot')
"""Kind of a person's ground-truth id ``i`` is ``PERSON_KINDS[i % 5]`` (ids 0 head, 1 left hand,
2 right hand, 3 left foot, 4 right foot, +5 per further person: the benchmark-bag contract)."""
KINDS = ('head', 'hand', 'foot', 'other')
"""Every kind reported, in report order."""

SEEN_RADIUS_M = 0.10
"""A ground-truth point is seen when depth readings lie within this distance (m) of it: the
labels are part centres, at most a head's radius (under 0.1 m) behind the visible surface."""
SEEN_MIN_READINGS = 3
"""Readings needed within :data:`SEEN_RADIUS_M` (one or two stray pixels are no surface)."""


def seen_labels(labels: npt.ArrayLike, depth: npt.NDArray[np.floating], intrinsics: Any, *,
                radius: float = SEEN_RADIUS_M,
                min_readings: int = SEEN_MIN_READINGS) -> npt.NDArray[np.bool_]:
    """(N,) whether each (N, 3) label (optical frame, m) has at least ``min_readings`` depth
    readings within ``radius`` metres in the (H, W) ``depth`` image (m, NaN or <= 0 = none).

    ``intrinsics`` has ``fx, fy, cx, cy``. Only the pixels of a window that holds the sphere's
    projection are back-projected (about 60 x 60 at 2 m with a 525 px focal length); a label
    that is not finite, lies behind the camera or whose window misses the image is not seen.
    """
    pts = np.asarray(labels, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(pts), dtype=bool)
    h, w = depth.shape
    fx, fy, cx, cy = (float(intrinsics.fx), float(intrinsics.fy), float(intrinsics.cx),
                      float(intrinsics.cy))
    for i, (x, y, z) in enumerate(pts):
        if not (z > radius and math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            continue
        half = int(np.ceil(max(fx, fy) * radius / (z - radius)))
        u, v = fx * x / z + cx, fy * y / z + cy
        u0, u1 = max(int(np.floor(u)) - half, 0), min(int(np.floor(u)) + half + 1, w)
        v0, v1 = max(int(np.floor(v)) - half, 0), min(int(np.floor(v)) + half + 1, h)
        if u0 >= u1 or v0 >= v1:
            continue
        d = np.asarray(depth[v0:v1, u0:u1], dtype=np.float64)
        vv, uu = np.nonzero(np.isfinite(d) & (d > 0))
        zz = d[vv, uu]
        dist2 = (((uu + u0 - cx) * zz / fx - x) ** 2 + ((vv + v0 - cy) * zz / fy - y) ** 2
                 + (zz - z) ** 2)
        out[i] = np.count_nonzero(dist2 <= radius * radius) >= min_readings
    return out


def kinds_of_ids(ids: npt.ArrayLike, *, person: bool) -> npt.NDArray[np.str_]:
    """(N,) kind names of ground-truth ids: :data:`PERSON_KINDS` by ``id % 5`` when the
    sequence shows people (``person``), else ``'other'`` for every id."""
    arr = np.asarray(ids).reshape(-1)
    if not person:
        return np.full(arr.shape, 'other')
    if arr.size and (not np.issubdtype(arr.dtype, np.integer) or arr.min() < 0):
        msg = f'ground-truth ids must be non-negative integers, got {arr[:5].tolist()}'
        raise ValueError(msg)
    return np.asarray(PERSON_KINDS)[arr.astype(np.int64) % len(PERSON_KINDS)]


def _as_points(points: npt.ArrayLike | None, what: str) -> npt.NDArray[np.float64]:
    """Validate an (N, 3) array of finite positions in metres."""
    if points is None:
        return np.zeros((0, 3))
    arr = np.asarray(points, dtype=np.float64)
    if arr.size == 0:
        return np.zeros((0, 3))
    if arr.ndim != 2 or arr.shape[1] != 3:
        msg = f'{what} must be an (N, 3) array of positions, got shape {arr.shape}'
        raise ValueError(msg)
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.all(np.isfinite(arr), axis=1)))
        msg = f'{what} contains {bad} non-finite position(s)'
        raise ValueError(msg)
    return arr


@dataclass(frozen=True)
class FrameScore:
    """Scores of one frame.

    ``errors`` holds the distances (m) of the TP pairs; ``matches`` the (estimate, ground truth)
    index pairs of the TPs. ``recall`` is ``nan`` when the frame has no ground-truth points.
    """

    n_gt: int
    n_est: int
    tp: int
    errors: npt.NDArray[np.float64]
    matches: npt.NDArray[np.intp]

    @property
    def fp(self) -> int:
        """Estimates that are not true positives."""
        return self.n_est - self.tp

    @property
    def recall(self) -> float:
        """Eq. 10: TP / #GT (``nan`` without ground-truth points)."""
        return self.tp / self.n_gt if self.n_gt else math.nan

    @property
    def fpr(self) -> float:
        """Eq. 12: FP / #estimated, 0 when nothing was estimated."""
        return self.fp / self.n_est if self.n_est else 0.0


def score_frame(estimated: npt.ArrayLike | None, ground_truth: npt.ArrayLike | None, *,
                threshold: float = MATCH_THRESHOLD_M) -> FrameScore:
    """Match (M, 3) ``estimated`` to (N, 3) ``ground_truth`` positions (metres), one-to-one.

    Hungarian assignment (:func:`~endeff_ros.core.assignment.min_cost_assignment`)
    minimising the total Euclidean distance; matched pairs within ``threshold`` metres are
    true positives.

    Raises
    ------
    ValueError
        If an input is not (N, 3) or holds non-finite values, or ``threshold`` is negative.
    """
    if not threshold >= 0:
        msg = f'match threshold must be >= 0 m, got {threshold}'
        raise ValueError(msg)
    est = _as_points(estimated, 'estimated end-effectors')
    gt = _as_points(ground_truth, 'ground-truth end-effectors')
    if len(est) == 0 or len(gt) == 0:
        return FrameScore(len(gt), len(est), 0, np.zeros(0), np.zeros((0, 2), dtype=np.intp))
    dist = np.linalg.norm(est[:, None, :] - gt[None, :, :], axis=2)
    rows, cols = min_cost_assignment(dist)
    d = dist[rows, cols]
    ok = d <= threshold
    matches = np.stack([rows[ok], cols[ok]], axis=1).astype(np.intp)
    return FrameScore(len(gt), len(est), int(ok.sum()), d[ok], matches)


@dataclass(frozen=True)
class MethodScore:
    """One method's scores on one sequence (or the mean over sequences)."""

    recall: float
    mean_error_m: float
    fpr: float

    def to_json(self) -> dict[str, float | None]:
        """The spec's ``{"recall", "mean_error_m", "fpr"}`` with ``None`` for undefined values."""
        return {'recall': _json_float(self.recall), 'mean_error_m': _json_float(self.mean_error_m),
                'fpr': _json_float(self.fpr)}


def _kind_key(kind: str) -> tuple[int, str]:
    """Sort key: the kinds of :data:`KINDS` in that order, unknown names after them."""
    return (KINDS.index(kind) if kind in KINDS else len(KINDS), kind)


@dataclass(frozen=True)
class KindScore:
    """One kind's recall (TPs / ground-truth points of that kind) and mean TP error (m)."""

    recall: float
    mean_error_m: float
    gt_points: int
    tp: int
    #: Recall over the seen points of that kind (:func:`seen_labels`), and their counts.
    seen_recall: float = math.nan
    seen_points: int = 0
    seen_tp: int = 0

    def to_json(self) -> dict[str, float | int | None]:
        """``{"recall", "mean_error_m", "gt_points", "tp", "seen_recall", "seen_points",
        "seen_tp"}``, ``None`` for undefined values."""
        return {'recall': _json_float(self.recall), 'mean_error_m': _json_float(self.mean_error_m),
                'gt_points': self.gt_points, 'tp': self.tp,
                'seen_recall': _json_float(self.seen_recall), 'seen_points': self.seen_points,
                'seen_tp': self.seen_tp}


def _json_float(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


@dataclass
class SequenceScorer:
    """Accumulates one method's frame scores over a sequence.

    Call :meth:`add` once per processed frame (``ground_truth=None`` for frames that are not
    annotated: they are counted but not scored).
    """

    threshold: float = MATCH_THRESHOLD_M
    frames: int = 0
    recalls: list[float] = field(default_factory=list)
    fprs: list[float] = field(default_factory=list)
    errors: list[float] = field(default_factory=list)
    tp: int = 0
    n_gt: int = 0
    n_est: int = 0
    #: Ground-truth points seen (:func:`seen_labels`) and those of them that are TPs, over the
    #: frames whose ``seen`` mask was given.
    seen_points: int = 0
    seen_tp: int = 0
    #: kind -> [ground-truth points, TPs, sum of TP errors (m), seen points, seen TPs] over the
    #: scored frames.
    kinds: dict[str, list[float]] = field(default_factory=dict)

    def add(self, estimated: npt.ArrayLike | None, ground_truth: npt.ArrayLike | None,
            kinds: npt.ArrayLike | None = None,
            seen: npt.ArrayLike | None = None) -> FrameScore | None:
        """Score one frame; returns its :class:`FrameScore` (None when not annotated).

        ``kinds``: optional (N,) kind name per ground-truth point (see :func:`kinds_of_ids`);
        frames without it do not count in :meth:`kind_result`. ``seen``: optional (N,) bool,
        which ground-truth points are seen (:func:`seen_labels`), for :attr:`seen_recall`.
        """
        self.frames += 1
        if ground_truth is None:
            return None
        score = score_frame(estimated, ground_truth, threshold=self.threshold)
        self.recalls.append(score.recall)
        self.fprs.append(score.fpr)
        self.errors.extend(score.errors.tolist())
        self.tp += score.tp
        self.n_gt += score.n_gt
        self.n_est += score.n_est
        seen_mask = None
        if seen is not None:
            seen_mask = np.asarray(seen, dtype=bool).reshape(-1)
            if len(seen_mask) != score.n_gt:
                msg = f'{len(seen_mask)} seen flags given for {score.n_gt} ground-truth points'
                raise ValueError(msg)
            self.seen_points += int(np.count_nonzero(seen_mask))
            self.seen_tp += int(np.count_nonzero(seen_mask[score.matches[:, 1]]))
        if kinds is not None:
            self._add_kinds(np.asarray(kinds).reshape(-1), score, seen_mask)
        return score

    def _add_kinds(self, kinds: npt.NDArray[np.str_], score: FrameScore,
                   seen: npt.NDArray[np.bool_] | None) -> None:
        if len(kinds) != score.n_gt:
            msg = f'{len(kinds)} kinds given for {score.n_gt} ground-truth points'
            raise ValueError(msg)
        matched = kinds[score.matches[:, 1]]
        matched_seen = None if seen is None else seen[score.matches[:, 1]]
        for kind in np.unique(kinds).tolist():
            acc = self.kinds.setdefault(kind, [0, 0, 0.0, 0, 0])
            of_kind, hit = kinds == kind, matched == kind
            acc[0] += int(np.count_nonzero(of_kind))
            acc[1] += int(np.count_nonzero(hit))
            acc[2] += float(score.errors[hit].sum())
            if seen is not None and matched_seen is not None:  # both or neither
                acc[3] += int(np.count_nonzero(seen & of_kind))
                acc[4] += int(np.count_nonzero(matched_seen & hit))

    def kind_result(self) -> dict[str, KindScore]:
        """Per kind (in :data:`KINDS` order): recall over its ground-truth points, mean error,
        recall over its seen points."""
        out = {}
        for kind in sorted(self.kinds, key=_kind_key):
            n, tp, err, n_seen, tp_seen = self.kinds[kind]
            out[kind] = KindScore(tp / n if n else math.nan, err / tp if tp else math.nan,
                                  int(n), int(tp), tp_seen / n_seen if n_seen else math.nan,
                                  int(n_seen), int(tp_seen))
        return out

    @property
    def seen_recall(self) -> float:
        """TPs among the seen ground-truth points over the seen points (``nan`` without any)."""
        return self.seen_tp / self.seen_points if self.seen_points else math.nan

    @property
    def scored_frames(self) -> int:
        """Frames with ground truth."""
        return len(self.fprs)

    def result(self) -> MethodScore:
        """Sequence recall and FPR (means over scored frames), mean error over all TP pairs."""
        return MethodScore(nanmean(self.recalls), nanmean(self.errors), nanmean(self.fprs))


def nanmean(values: Iterable[float]) -> float:
    """Mean of the finite values; ``nan`` when there are none."""
    arr = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    return float(arr.mean()) if arr.size else math.nan


def mean_over_sequences(scores: Sequence[MethodScore]) -> MethodScore:
    """Overall figures: the mean over sequences of each defined value."""
    return MethodScore(nanmean(s.recall for s in scores),
                       nanmean(s.mean_error_m for s in scores),
                       nanmean(s.fpr for s in scores))


def mean_kinds_over_sequences(scores: Sequence[dict[str, KindScore]]) -> dict[str, KindScore]:
    """Per kind, the mean over the sequences that have that kind (as the overall figures);
    ``gt_points`` and ``tp`` are the sums."""
    kinds = sorted({k for s in scores for k in s}, key=_kind_key)
    out = {}
    for kind in kinds:
        have = [s[kind] for s in scores if kind in s]
        out[kind] = KindScore(nanmean(k.recall for k in have),
                              nanmean(k.mean_error_m for k in have),
                              sum(k.gt_points for k in have), sum(k.tp for k in have),
                              nanmean(k.seen_recall for k in have),
                              sum(k.seen_points for k in have), sum(k.seen_tp for k in have))
    return out


def score_sequence(estimates: Iterable[npt.ArrayLike | None],
                   ground_truths: Iterable[npt.ArrayLike | None], *,
                   threshold: float = MATCH_THRESHOLD_M) -> MethodScore:
    """Score a whole sequence given per-frame estimates and ground truth (None = not scored)."""
    scorer = SequenceScorer(threshold=threshold)
    for est, gt in zip(estimates, ground_truths, strict=True):
        scorer.add(est, gt)
    return scorer.result()


def summary_dict(scorer: SequenceScorer) -> dict[str, Any]:
    """Counts behind a method's sequence score (extra report keys)."""
    return {'tp': scorer.tp, 'gt_points': scorer.n_gt, 'estimated': scorer.n_est,
            'seen_points': scorer.seen_points, 'seen_tp': scorer.seen_tp}
