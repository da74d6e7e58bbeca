"""Where recall and precision are lost: every ground-truth point and every reported
end-effector of the temporal estimator, put in one class each.

Ground-truth points (the first class that applies):

- ``outside_box``: the point lies outside the foreground box (Section 3 never sees it);
- ``hidden``: not seen (``endeff_ros.scoring.seen_labels``: fewer than 3 depth readings of
  the frame within 0.1 m of it; occluded, beyond the sensor's range, or a dropout), as the
  reports' ``labels_seen`` count it;
- ``removed``: the depth sees it, but no foreground point (after the box, the floor and the
  static background) lies within ``SURFACE_M``: the floor or the background took it;
- ``found``: a reported end-effector lies within the match threshold (0.15 m);
- ``near_miss``: in the foreground, the nearest reported end lies 0.15-``NEAR_M`` away (an end
  on the right part whose centre is off: a long foot, a hand against the body);
- ``missed``: in the foreground, nothing reported near it (the bands, graph or tracker).

The same classes per end-effector kind (head, hand, foot; ``other`` for entities that are not
people), from the ground truth's ids as ``endeff eval`` reads them.

Reported end-effectors: ``tp`` (within 0.15 m of a ground-truth point), ``fp_body`` (within
``BODY_M`` of one: an elbow, a knee, a shoulder), ``fp_far`` (farther: furniture, walls,
floor, noise); false positives in the first ``EARLY_S`` of a bag (the background's learning
time and the tracks that outlive it) are counted apart as ``*_early``.
Nearest-point classes, not the Hungarian matching of ``endeff eval``: a tally of causes, not
a score.

    python -m tools.miss_check BAG_OR_DIR [...] [--every N] [--params YAML] [--jobs 2]
                               [--json OUT]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from endeff_ros.attributes import custom_data, parse_attributes
from endeff_ros.bag.reader import BagReader
from endeff_ros.cli_common import print_json
from endeff_ros.core.cloud import box_mask
from endeff_ros.core.errors import InputError
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.tracker import Tracker
from endeff_ros.evaluate import gt_ids, is_person_sequence
from endeff_ros.scoring import MATCH_THRESHOLD_M, kinds_of_ids, seen_labels
from tools.per_bag import parse_bag_args, run_per_bag

SURFACE_M = 0.12  # a part's centre lies up to about its radius behind the foreground's surface
BODY_M = 0.6
NEAR_M = 0.25
EARLY_S = 0.5
GT_CLASSES = ('found', 'near_miss', 'missed', 'removed', 'hidden', 'outside_box')
EST_CLASSES = ('tp', 'fp_body', 'fp_far', 'fp_body_early', 'fp_far_early')


def _nearest(points: np.ndarray, queries: np.ndarray) -> np.ndarray:
    if len(points) == 0:
        return np.full(len(queries), np.inf)
    return cKDTree(points).query(queries)[0]


def check_bag(bag: Path, params: EndeffParams | None = None) -> dict[str, Any]:
    """Class counts of one bag's ground-truth points and reported end-effectors."""
    p = params or EndeffParams()
    tracker = Tracker(p)
    gt_counts = dict.fromkeys(GT_CLASSES, 0)
    by_kind: dict[str, dict[str, int]] = {}
    est_counts = dict.fromkeys(EST_CLASSES, 0)
    first = None
    with BagReader(bag) as reader:
        attributes, _ = parse_attributes(custom_data(reader.reader), str(bag))
        person = is_person_sequence(bag.name, attributes)
        ids = gt_ids(reader)
        for frame, gt in reader.frames():
            first = frame.stamp_ns if first is None else first
            try:
                result = tracker.update(frame)
            except InputError:
                continue
            if gt is None:
                continue
            gt = gt[:, :3]
            est = np.array([t.position for t in result.tracks]).reshape(-1, 3)
            fg = result.estimate.points
            seen = seen_labels(gt, frame.depth, frame.intrinsics)
            d_est = _nearest(est, gt)
            d_fg = _nearest(fg, gt)
            inside = box_mask(gt, p)
            frame_ids = ids.get(frame.stamp_ns)
            kinds = (kinds_of_ids(frame_ids, person=person)
                     if frame_ids is not None and len(frame_ids) == len(gt)
                     else np.full(len(gt), 'unknown'))
            for k in range(len(gt)):
                if not inside[k]:
                    cls = 'outside_box'
                elif not seen[k]:
                    cls = 'hidden'
                elif d_fg[k] > SURFACE_M:
                    cls = 'removed'
                elif d_est[k] <= MATCH_THRESHOLD_M:
                    cls = 'found'
                elif d_est[k] <= NEAR_M:
                    cls = 'near_miss'
                else:
                    cls = 'missed'
                gt_counts[cls] += 1
                kind = by_kind.setdefault(str(kinds[k]), dict.fromkeys(GT_CLASSES, 0))
                kind[cls] += 1
            early = (frame.stamp_ns - first) * 1e-9 < EARLY_S
            for d in _nearest(gt, est):
                cls = ('tp' if d <= MATCH_THRESHOLD_M else 'fp_body' if d <= BODY_M
                       else 'fp_far')
                est_counts[cls + ('_early' if early and cls != 'tp' else '')] += 1
    return {'bag': bag.name, 'ground_truth': gt_counts, 'ground_truth_by_kind': by_kind,
            'reported': est_counts}



def _shares(rows: list[dict[str, Any]], key: str) -> dict[str, Any]:
    total = {k: sum(r[key][k] for r in rows) for k in rows[0][key]} if rows else {}
    n = sum(total.values())
    return {'count': n, **{k: round(v / n, 3) if n else None for k, v in total.items()}}


def main(argv: list[str] | None = None) -> int:
    args, bags, params = parse_bag_args(__doc__, argv, 'miss_check')
    per_bag = run_per_bag(check_bag, bags, params, args.jobs)
    kinds = sorted({k for r in per_bag for k in r['ground_truth_by_kind']})
    by_kind = {k: _shares([{'c': r['ground_truth_by_kind'][k]} for r in per_bag
                           if k in r['ground_truth_by_kind']], 'c') for k in kinds}
    print_json({'ground_truth': _shares(per_bag, 'ground_truth'),
                'ground_truth_by_kind': by_kind,
                'reported': _shares(per_bag, 'reported'), 'bags': per_bag}, args.json)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
