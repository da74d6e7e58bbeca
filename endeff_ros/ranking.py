"""How well the published ``confidence`` ranks and predicts right ends: average precision and
calibration, per sequence, per kind and pooled over groups.

Pure numpy: no ROS imports.

Every published end-effector of a scored frame is *right* when the frame's one-to-one matching
(:func:`~endeff_ros.scoring.score_frame`, 0.15 m) made it a true positive. Ranked by
confidence, the ends above a threshold give a precision (right ones among them) and a recall
(right ones over every ground-truth point of the frames, seen or not: the paper's Eq. 10
denominator). **Average precision** is the area under that precision-recall curve, each
distinct confidence a threshold (ends of equal confidence cannot be told apart, so they enter
together), ``AP = sum_i (R_i - R_{i-1}) P_i``: it is at most the recall of all published ends,
and equals it only when every right end outranks every wrong one. **Calibration**: the ends in
ten equal bins of confidence, per bin the mean confidence against the fraction right
(the reliability diagram); the **expected calibration error** is their mean absolute gap
weighted by the bins' shares of ends: 0.05 means an end published with 0.8 is right 75-85 %
of the time.

Per kind (head, hand, foot, other): the ends matched to a ground-truth point of that kind,
and the false ends *published* as that kind (a false end has no label), against the
ground-truth points of the kind. A sequence's AP is over its own frames; a group's AP and a
kind's are the means over the sequences that have them (as the reports average recall);
calibration pools the ends of a group, for it is a property of the score, not of a sequence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .attributes import group_sections
from .core.kinds import KIND_NAMES
from .scoring import KINDS, nanmean

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

CALIBRATION_BINS = 10
"""Equal-width confidence bins of the reliability diagram over [0, 1]."""

CURVE_POINTS = 200
"""Points kept of the overall precision-recall curve in the report."""

def precision_recall(confidence: npt.ArrayLike, right: npt.ArrayLike, n_gt: int
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Recall (over ``n_gt`` ground-truth points) and precision of the ends at or above
    each distinct ``confidence``, highest first (ends of equal confidence enter together);
    empty without ends or ground truth."""
    conf = np.asarray(confidence, dtype=np.float64).reshape(-1)
    ok = np.asarray(right, dtype=bool).reshape(-1)
    if len(conf) == 0 or n_gt <= 0:
        return np.zeros(0), np.zeros(0)
    order = np.argsort(-conf, kind='stable')
    conf, ok = conf[order], ok[order]
    last = np.r_[conf[1:] != conf[:-1], True]  # the last end of each group of equal confidence
    tp = np.cumsum(ok)[last]
    return tp / n_gt, tp / (np.flatnonzero(last) + 1)


def average_precision(confidence: npt.ArrayLike, right: npt.ArrayLike, n_gt: int) -> float:
    """Area under the precision-recall curve of ends ranked by ``confidence`` (see the
    module), recall over ``n_gt`` ground-truth points; ``nan`` without ground truth."""
    if n_gt <= 0:
        return math.nan
    recall, precision = precision_recall(confidence, right, n_gt)
    return float(np.sum(np.diff(np.r_[0.0, recall]) * precision))


def calibration_bins(confidence: npt.ArrayLike, right: npt.ArrayLike,
                     bins: int = CALIBRATION_BINS) -> npt.NDArray[np.float64]:
    """(bins, 3): per confidence bin its ends, their summed confidence and the right ones."""
    conf = np.clip(np.asarray(confidence, dtype=np.float64).reshape(-1), 0.0, 1.0)
    ok = np.asarray(right, dtype=np.float64).reshape(-1)
    b = np.minimum((conf * bins).astype(np.intp), bins - 1)
    out = np.zeros((bins, 3))
    np.add.at(out, b, np.stack([np.ones_like(conf), conf, ok], axis=1))
    return out


def calibration_error(bins: npt.NDArray[np.float64]) -> float:
    """Expected calibration error of :func:`calibration_bins` sums (``nan`` without ends)."""
    n = bins[:, 0]
    if n.sum() == 0:
        return math.nan
    used = n > 0
    gap = np.abs(bins[used, 1] - bins[used, 2]) / n[used]
    return float(np.sum(gap * n[used]) / n.sum())


def reliability_json(bins: npt.NDArray[np.float64]) -> dict[str, Any]:
    """The reliability diagram: per bin its ends, mean confidence and fraction right."""
    n = bins[:, 0]
    with np.errstate(invalid='ignore', divide='ignore'):
        conf, acc = bins[:, 1] / n, bins[:, 2] / n
    return {'ends': [int(v) for v in n],
            'confidence': [None if not math.isfinite(v) else round(float(v), 4) for v in conf],
            'right': [None if not math.isfinite(v) else round(float(v), 4) for v in acc]}


@dataclass
class ConfidenceRanking:
    """Accumulates one sequence's published ends: confidence, right or not, kind."""

    confidence: list[float] = field(default_factory=list)
    right: list[bool] = field(default_factory=list)
    kind: list[str] = field(default_factory=list)
    n_gt: int = 0
    gt_kinds: dict[str, int] = field(default_factory=dict)

    def add(self, confidence: npt.ArrayLike, published_kind: npt.ArrayLike | None,
            matches: npt.NDArray[np.intp], n_gt: int,
            gt_kinds: npt.ArrayLike | None = None) -> None:
        """One scored frame: the ends' confidences and published ``Track.kind`` codes, the
        frame's (end, label) true-positive ``matches``, its ground-truth count and their kinds
        (None: every label is kind ``other``)."""
        conf = np.asarray(confidence, dtype=np.float64).reshape(-1)
        right = np.zeros(len(conf), dtype=bool)
        right[matches[:, 0]] = True
        labels = (np.asarray(gt_kinds).reshape(-1) if gt_kinds is not None
                  else np.full(n_gt, 'other'))
        codes = (np.zeros(len(conf), dtype=np.intp) if published_kind is None
                 else np.asarray(published_kind, dtype=np.intp).reshape(-1))
        kind = [KIND_NAMES[c] if 0 <= c < len(KIND_NAMES) else 'other' for c in codes]
        for end, label in matches.tolist():
            kind[end] = str(labels[label])
        self.confidence += conf.tolist()
        self.right += right.tolist()
        self.kind += kind
        self.n_gt += n_gt
        for k in labels.tolist():
            self.gt_kinds[str(k)] = self.gt_kinds.get(str(k), 0) + 1

    def _arrays(self, kind: str | None = None) -> tuple[npt.NDArray, npt.NDArray]:
        conf, right = np.asarray(self.confidence), np.asarray(self.right, dtype=bool)
        if kind is None:
            return conf, right
        sel = np.asarray(self.kind) == kind
        return conf[sel], right[sel]

    def average_precision(self, kind: str | None = None) -> float:
        """AP over all ends, or over one kind's (``nan`` without its ground truth)."""
        n = self.n_gt if kind is None else self.gt_kinds.get(kind, 0)
        return average_precision(*self._arrays(kind), n)

    def bins(self) -> npt.NDArray[np.float64]:
        """Calibration bin sums of every end (:func:`calibration_bins`)."""
        return calibration_bins(*self._arrays())

    def to_json(self) -> dict[str, Any]:
        """AP overall and per kind, calibration error, reliability diagram."""
        return summary_json([self])


def _jf(value: float) -> float | None:
    return round(value, 4) if math.isfinite(value) else None


def summary_json(rankings: Sequence[ConfidenceRanking], *, curve: bool = False
                 ) -> dict[str, Any]:
    """A sequence's or a group's figures: AP (mean over the sequences), per kind, calibration
    pooled over the sequences' ends; with ``curve`` the pooled precision-recall curve at
    :data:`CURVE_POINTS` thresholds at most (for the plot)."""
    bins = sum((r.bins() for r in rankings), np.zeros((CALIBRATION_BINS, 3)))
    kinds = {k: _jf(nanmean(r.average_precision(k) for r in rankings)) for k in KINDS
             if any(r.gt_kinds.get(k) for r in rankings)}
    out = {'average_precision': _jf(nanmean(r.average_precision() for r in rankings)),
           'kinds': kinds, 'calibration_error': _jf(calibration_error(bins)),
           'reliability': reliability_json(bins), 'ends': int(bins[:, 0].sum())}
    if curve:
        recall, precision = pr_curve(rankings)
        keep = np.unique(np.linspace(0, len(recall) - 1, min(len(recall), CURVE_POINTS))
                         .astype(np.intp)) if len(recall) else np.zeros(0, np.intp)
        out['pr_curve'] = {'recall': [round(float(v), 4) for v in recall[keep]],
                           'precision': [round(float(v), 4) for v in precision[keep]]}
    return out


def pr_curve(rankings: Sequence[ConfidenceRanking]) -> tuple[npt.NDArray, npt.NDArray]:
    """Pooled precision-recall curve of the sequences' ends (for the plot)."""
    return precision_recall([c for r in rankings for c in r.confidence],
                            [ok for r in rankings for ok in r.right],
                            sum(r.n_gt for r in rankings))


def _cell(v: float | None) -> str:
    return '-' if v is None else f'{v:.3f}'


def format_table(report: dict[str, Any], width: int) -> list[str]:
    """AP (overall and per kind) and calibration error per group and overall; empty when the
    report holds none."""
    overall = report.get('confidence')
    if not overall:
        return []
    head = (f'{"confidence (temporal)":{width}} |{"AP":>8}'
            + ''.join(f'{k:>8}' for k in KINDS) + f'{"ECE":>8}{"ends":>9}')
    rule = '-' * len(head)

    def row(name: str, d: dict[str, Any]) -> str:
        return (f'{name:{width}} |{_cell(d.get("average_precision")):>8}'
                + ''.join(f'{_cell(d.get("kinds", {}).get(k)):>8}' for k in KINDS)
                + f'{_cell(d.get("calibration_error")):>8}{d.get("ends", 0):>9}')

    lines = [head, rule]
    groups = report.get('groups', {})
    for section, names in group_sections(groups, 'confidence'):
        lines.append(f'-- {section} ' + '-' * max(0, len(rule) - len(section) - 4))
        lines += [row(g, groups[g]['confidence']) for g in names]
    lines += [rule, row('overall', overall)]
    return lines
