"""``endeff eval``'s confusion matrix of the published ``kind`` (head, hand, foot, other).

A subscriber reads ``kind`` to find a person's hand, so what matters is how often the kind of
a published end-effector that is a real one is right. Per scored frame, the temporal
estimator's tracks that the frame's Hungarian matching made true positives (within
:data:`~endeff_ros.scoring.MATCH_THRESHOLD_M`, :func:`~endeff_ros.scoring.score_frame`) are
counted in a row for the ground truth's kind (:func:`~endeff_ros.scoring.kinds_of_ids`: head,
hand, foot of a person; ``other`` for every other entity) and a column for the track's kind.
The published ends that matched no label are counted in the row ``unmatched``: for an entity
that is no person (a chair, a robot arm), every end should be ``other``, matched or not.

Accuracy: the matched ends whose kind equals their label's, over all matched ends; per kind,
over the matched ends of that label (the recall of each row). Groups and overall add up the
counts of their sequences (a confusion matrix is a count; a sequence with more matched ends
weighs more).

No ROS import.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from endeff_ros.core.kinds import KIND_NAMES

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

    from endeff_ros.scoring import FrameScore

#: Rows: the labels' kinds, then the published ends that matched no label.
ROWS = ('head', 'hand', 'foot', 'other', 'unmatched')
#: Columns: the published kinds (``Track.kind`` values 0-3, by name).
COLUMNS = KIND_NAMES


@dataclass
class KindConfusion:
    """Counts (len(ROWS), len(COLUMNS)) of one sequence or group."""

    counts: npt.NDArray[np.int64] = field(
        default_factory=lambda: np.zeros((len(ROWS), len(COLUMNS)), dtype=np.int64))

    def add(self, tracks: Sequence[Any], kinds: npt.ArrayLike | None,
            score: FrameScore | None) -> None:
        """One scored frame: ``tracks`` as published (a ``kind`` attribute, 0 when absent),
        ``kinds`` the names of the frame's labels (None: the labels have no ids, the frame is
        not counted), ``score`` the frame's matching of the tracks to the labels."""
        if score is None or kinds is None:
            return
        names = np.asarray(kinds)
        published = [_kind_of(t) for t in tracks]
        matched = set()
        for est, gt in np.asarray(score.matches, dtype=np.intp).reshape(-1, 2):
            row = ROWS.index(str(names[gt])) if str(names[gt]) in ROWS else ROWS.index('other')
            self.counts[row, published[est]] += 1
            matched.add(int(est))
        for k, kind in enumerate(published):
            if k not in matched:
                self.counts[ROWS.index('unmatched'), kind] += 1

    def matched(self) -> int:
        """Published ends matched to a label."""
        return int(self.counts[:-1].sum())

    def accuracy(self) -> float | None:
        """Matched ends of the right kind over all matched ends (None: none matched)."""
        n = self.matched()
        return None if n == 0 else float(self._right().sum() / n)

    def row_accuracy(self, row: str) -> float | None:
        """The right kind among the matched ends labelled ``row`` (None: none)."""
        i = ROWS.index(row)
        n = int(self.counts[i].sum())
        return None if n == 0 else float(self.counts[i, COLUMNS.index(row)] / n)

    def other_fraction(self) -> float | None:
        """All ends of kind ``other`` over all published ends counted (None: none)."""
        n = int(self.counts.sum())
        return None if n == 0 else float(self.counts[:, 0].sum() / n)

    def _right(self) -> npt.NDArray[np.int64]:
        return np.array([self.counts[i, COLUMNS.index(r)] for i, r in enumerate(ROWS[:-1])])

    def to_json(self) -> dict[str, Any]:
        """``{'rows', 'columns', 'counts', 'accuracy', 'per_kind', 'other_fraction'}``."""
        return {'rows': list(ROWS), 'columns': list(COLUMNS),
                'counts': self.counts.tolist(), 'matched': self.matched(),
                'accuracy': _round(self.accuracy()),
                'per_kind': {r: _round(self.row_accuracy(r)) for r in ROWS[:-1]},
                'other_fraction': _round(self.other_fraction())}


def _kind_of(track: Any) -> int:
    kind = int(getattr(track, 'kind', 0))
    return kind if 0 <= kind < len(COLUMNS) else 0


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 4)


def confusion_group(members: Sequence[KindConfusion]) -> dict[str, Any]:
    """The JSON entry of a group: its sequences' counts added up."""
    total = KindConfusion()
    for m in members:
        total.counts += m.counts
    return total.to_json()


def confusion_table(report: dict[str, Any]) -> list[str]:
    """Lines of the overall confusion matrix and the accuracy per group (empty without
    counts): printed by ``endeff eval`` after the per-kind recall."""
    overall = report.get('kind_confusion')
    if not overall or not np.asarray(overall['counts']).sum():
        return []
    counts = np.asarray(overall['counts'], dtype=np.int64)
    cols = overall['columns']
    lines = ["published kind (temporal; rows: the matched label's kind, or unmatched)",
             f'{"label":<11}' + ''.join(f'{c:>8}' for c in cols) + f'{"right":>9}']
    for row, values in zip(overall['rows'], counts, strict=True):
        right = overall['per_kind'].get(row)
        lines.append(f'{row:<11}' + ''.join(f'{int(v):>8}' for v in values)
                     + (f'{right:>9.3f}' if right is not None else f'{"-":>9}'))
    acc = overall['accuracy']
    lines.append(f'kind right for {_pct(acc)} of {overall["matched"]} matched ends; '
                 f'kind other for {_pct(overall["other_fraction"])} of all published ends')
    groups = {g: d['kind_confusion'] for g, d in report.get('groups', {}).items()
              if d.get('kind_confusion', {}).get('matched')}
    if groups:
        width = max(len(g) for g in groups) + 2
        lines.append(f'{"group":<{width}}{"matched":>8}{"right":>8}' + ''.join(
            f'{r:>8}' for r in ROWS[:-1]) + f'{"other%":>8}')
        for g, d in groups.items():
            lines.append(f'{g:<{width}}{d["matched"]:>8}{_num(d["accuracy"]):>8}' + ''.join(
                f'{_num(d["per_kind"][r]):>8}' for r in ROWS[:-1])
                + f'{_num(d["other_fraction"]):>8}')
    return lines


def _pct(value: float | None) -> str:
    return '-' if value is None else f'{100 * value:.1f} %'


def _num(value: float | None) -> str:
    return '-' if value is None else f'{value:.3f}'
