"""What the temporal estimator's misses were before: every missed ground-truth point by the
time since its end-effector was last matched, and what became of the track that matched it.

Per ground-truth end-effector (its ``id`` field, else its row) and frame, scored as ``endeff
eval`` scores the temporal estimator (Hungarian matching within 0.15 m):

- ``found``: matched in this frame;
- ``never``: missed, and not matched before in the bag (the single-frame estimator never
  gave it, or the tracker never kept it);
- ``within_10`` / ``within_30`` / ``later``: missed, last matched 1-10, 11-30 or more frames
  before.

For the misses within 30 frames, the track that matched last time (``lost_track``):

- ``gone_unconfirmed``: dropped before ``confirm_hits`` detections supported it (case C keeps
  confirmed tracks only);
- ``gone_left``: dropped because its prediction had no usable foreground point within
  ``max_rectify_distance`` (the part left the foreground, or the bands did not reach it);
- ``gone_short``: dropped after more case-C frames than it had detections;
- ``gone_expired``: dropped after T (``keep_frames``) case-C frames;
- ``gone_duplicate``: dropped as a duplicate of another track;
- ``alive_near`` / ``alive_far``: still published, within / beyond ``NEAR_M`` of the point;
- ``matched_other``: still published, matched to another point.

Counts per end-effector kind (head, hand, foot; ``other`` for entities that are not people).
A tally of causes for the tracker's work, not a score.

    python -m tools.track_history BAG_OR_DIR [...] [--every N] [--params YAML] [--jobs 2]
                                  [--json OUT]
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from endeff_ros.attributes import custom_data, parse_attributes
from endeff_ros.bag.reader import BagReader
from endeff_ros.cli_common import print_json
from endeff_ros.core.errors import InputError
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.tracker import Tracker
from endeff_ros.evaluate import gt_ids, is_person_sequence
from endeff_ros.scoring import kinds_of_ids
from tools.pan_check import matched_ids
from tools.per_bag import parse_bag_args, run_per_bag

NEAR_M = 0.3
RECENT = (10, 30)
HISTORY = ('found', 'never', 'within_10', 'within_30', 'later')
LOST = ('gone_unconfirmed', 'gone_left', 'gone_short', 'gone_expired', 'gone_duplicate',
        'alive_near', 'alive_far', 'matched_other')


class _RecordingTracker(Tracker):
    """A tracker that tells why each track it dropped in the last update was dropped (the
    drop conditions of :meth:`Tracker._update`, in their order)."""

    def _update(self, estimate, predicted):  # type: ignore[no-untyped-def]
        before = {t.id: (t.missed, t.hits) for t in self._tracks}
        nodes: dict[int, int] = {}
        rectify = self._rectify

        def recording(est, pred):  # type: ignore[no-untyped-def]
            out = rectify(est, pred)
            nodes.update({pr.track.id: pr.node for pr in out})
            return out

        self._rectify = recording  # type: ignore[method-assign]
        try:
            survivors = super()._update(estimate, predicted)
        finally:
            del self._rectify
        alive = {t.id for t in survivors}
        p = self.params
        self.dropped: dict[int, str] = {}
        for track_id, (missed, hits) in before.items():
            if track_id in alive:
                continue
            if nodes.get(track_id, -1) < 0:
                why = 'gone_left'
            elif hits < p.confirm_hits:
                why = 'gone_unconfirmed'
            elif missed + 1 > p.keep_frames:
                why = 'gone_expired'
            elif missed + 1 > hits:
                why = 'gone_short'
            else:
                why = 'gone_duplicate'
            self.dropped[track_id] = why
        return survivors


class TrackedFrame(NamedTuple):
    """One frame of :func:`tracked_frames`: the tracker's tracks, the tracks it dropped in
    that update (id -> why), and the frame's ground truth (None without) with its keys (the
    ground-truth ids, or positions when the ids do not line up) and kinds."""

    index: int
    tracks: list[Any]
    dropped: dict[int, str]
    gt: npt.NDArray[np.float64] | None
    keys: npt.NDArray[np.int64]
    kinds: npt.NDArray[Any]
    frame_ids: npt.NDArray[np.int64] | None


def tracked_frames(bag: Path, tracker: _RecordingTracker) -> Iterator[TrackedFrame]:
    """The recording ``tracker`` run over ``bag``, frame by frame (frames the tracker rejects
    are left out)."""
    with BagReader(bag) as reader:
        attributes, _ = parse_attributes(custom_data(reader.reader), str(bag))
        person = is_person_sequence(bag.name, attributes)
        ids = gt_ids(reader)
        for index, (frame, gt) in enumerate(reader.frames()):
            try:
                tracks = tracker.update(frame).tracks
            except InputError:
                continue
            if gt is None or len(gt) == 0:
                yield TrackedFrame(index, tracks, dict(tracker.dropped), None,
                                   np.zeros(0, np.int64), np.zeros(0, object), None)
                continue
            gt = gt[:, :3]
            frame_ids = ids.get(frame.stamp_ns)
            aligned = frame_ids is not None and len(frame_ids) == len(gt)
            keys = frame_ids if aligned else np.arange(len(gt))
            kinds = (kinds_of_ids(frame_ids, person=person) if aligned
                     else np.full(len(gt), 'unknown'))
            yield TrackedFrame(index, tracks, dict(tracker.dropped), gt, keys, kinds, frame_ids)


def check_bag(bag: Path, params: EndeffParams | None = None) -> dict[str, Any]:
    """History counts of one bag's ground-truth points, per kind."""
    tracker = _RecordingTracker(params or EndeffParams())
    history: dict[str, dict[str, int]] = {}
    lost: dict[str, dict[str, int]] = {}
    last: dict[int, tuple[int, int]] = {}  # ground-truth key -> (frame, track id)
    why_dropped: dict[int, str] = {}
    for index, tracks, dropped, gt, keys, kinds, frame_ids in tracked_frames(bag, tracker):
        for track_id, why in dropped.items():
            why_dropped.setdefault(track_id, why)
        if gt is None:
            continue
        matched, _ = matched_ids(np.array([t.position for t in tracks]),
                                 [t.id for t in tracks], gt, frame_ids)
        matched_tracks = set(matched.values())
        by_id = {t.id: t for t in tracks}
        for g in range(len(gt)):
            key, kind = int(keys[g]), str(kinds[g])
            h = history.setdefault(kind, dict.fromkeys(HISTORY, 0))
            if key in matched:
                h['found'] += 1
                last[key] = (index, matched[key])
                continue
            if key not in last:
                h['never'] += 1
                continue
            since = index - last[key][0]
            h['within_10' if since <= RECENT[0] else
              'within_30' if since <= RECENT[1] else 'later'] += 1
            if since > RECENT[1]:
                continue
            track_id = last[key][1]
            track = by_id.get(track_id)
            if track is None:
                cls = why_dropped.get(track_id, 'gone_duplicate')
            elif track_id in matched_tracks:
                cls = 'matched_other'
            else:
                near = np.linalg.norm(track.position - gt[g]) <= NEAR_M
                cls = 'alive_near' if near else 'alive_far'
            lost.setdefault(kind, dict.fromkeys(LOST, 0))[cls] += 1
    return {'bag': bag.name, 'history': history, 'lost_track': lost}


def _sum(rows: list[dict[str, Any]], key: str, names: tuple[str, ...]) -> dict[str, Any]:
    kinds = sorted({k for r in rows for k in r[key]})
    return {k: {n: sum(r[key].get(k, {}).get(n, 0) for r in rows) for n in names}
            for k in kinds}


def main(argv: list[str] | None = None) -> int:
    args, bags, params = parse_bag_args(__doc__, argv, 'track_history')
    per_bag = run_per_bag(check_bag, bags, params, args.jobs)
    print_json({'history': _sum(per_bag, 'history', HISTORY),
                'lost_track': _sum(per_bag, 'lost_track', LOST), 'bags': per_bag}, args.json)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
