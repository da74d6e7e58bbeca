"""What any estimator could reach on a set of benchmark bags: the recall of one that finds
every ground-truth point the depth sees, and of one that also holds every hidden end-effector
perfectly for a while after it was last seen.

A point is *seen* as the reports count it (``endeff_ros.scoring.seen_labels``: at least 3 depth
readings of its frame within 0.1 m). For a point not seen, the tool counts the frames since
the same end-effector (its ``id`` field, else its row) was last seen. The *ceiling* for a hold
of ``k`` frames is the recall of an estimator that reports every seen point exactly, and every
hidden one seen within the last ``k`` frames (a tracker that keeps an occluded end-effector
where it is for ``k`` frames and is never wrong), and nothing else. ``ever``: seen at any
earlier frame of the bag. Recall is averaged as the reports average it: over each bag's
frames with ground truth, then over the bags (overall and per attribute group, the groups of
``endeff eval``). No estimator runs: only the depth and the ground truth are read.

Why: the accuracy targets are stated over every end-effector in view, seen or not. Where the
ceiling lies below a target, no estimator without a model of the body (which would infer
end-effectors it never saw) can meet it.

    python -m tools.seen_ceiling BAG_OR_DIR [...] [--every N] [--jobs 2] [--json OUT]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.attributes import attribute_groups, custom_data, parse_attributes
from endeff_ros.bag.reader import BagReader
from endeff_ros.cli_common import print_json
from endeff_ros.evaluate import gt_ids
from endeff_ros.scoring import seen_labels
from tools.per_bag import parse_bag_args, run_per_bag

#: Holds (frames) the ceilings are given for; ``ever`` is any earlier frame.
HOLDS = (0, 8, 30)
HOLD_NAMES = tuple(f'hold_{k}' for k in HOLDS) + ('ever',)


def check_bag(bag: Path, params: Any = None) -> dict[str, Any]:
    """One bag's seen and hidden points and its ceilings (``params`` is not used: the
    estimators do not run)."""
    del params
    frames = []  # per frame with ground truth: labels, then the points each ceiling finds
    last: dict[int, int] = {}
    with BagReader(bag) as reader:
        attributes, _ = parse_attributes(custom_data(reader.reader), str(bag))
        ids = gt_ids(reader)
        for index, (frame, gt) in enumerate(reader.frames()):
            if gt is None or len(gt) == 0:
                continue
            gt = gt[:, :3]
            seen = seen_labels(gt, frame.depth, frame.intrinsics)
            frame_ids = ids.get(frame.stamp_ns)
            keys = (frame_ids.tolist() if frame_ids is not None and len(frame_ids) == len(gt)
                    else list(range(len(gt))))
            # Frames since the end-effector was last seen: 0 if seen now, -1 if never.
            gaps = np.array([0 if s else index - last[k] if k in last else -1
                             for k, s in zip(keys, seen)])
            for k, s in zip(keys, seen):
                if s:
                    last[k] = index
            found = [int(np.count_nonzero(seen | ((gaps > 0) & (gaps <= h)))) for h in HOLDS]
            found.append(int(np.count_nonzero(seen | (gaps > 0))))
            frames.append([len(gt), *found])
    counts = np.array(frames, dtype=np.int64).reshape(-1, len(HOLD_NAMES) + 1)
    ceilings = ({name: float(np.mean(counts[:, i + 1] / counts[:, 0]))
                 for i, name in enumerate(HOLD_NAMES)} if len(counts) else None)
    # A hold of 0 frames finds exactly the seen points.
    return {'bag': bag.name, 'attributes': attributes, 'points': int(counts[:, 0].sum()),
            'seen': int(counts[:, 1].sum()), 'ceiling': ceilings}


def _mean(rows: list[dict[str, Any]]) -> dict[str, Any]:
    scored = [r for r in rows if r['ceiling'] is not None]
    points = sum(r['points'] for r in rows)
    return {'bags': len(rows), 'points': points,
            'seen': round(sum(r['seen'] for r in rows) / points, 3) if points else None,
            **{name: round(float(np.mean([r['ceiling'][name] for r in scored])), 3)
               if scored else None for name in HOLD_NAMES}}


def report(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Overall and per-group ceilings (means over the bags, as the reports' recall)."""
    by_name = {r['bag']: r for r in rows}
    groups = attribute_groups([(r['bag'], r['attributes']) for r in rows])
    return {'overall': _mean(rows),
            'groups': {g: _mean([by_name[n] for n in names])
                       for key in groups.values() for g, names in key.items()},
            'bags': [{k: v for k, v in r.items() if k != 'attributes'} for r in rows]}


def main(argv: list[str] | None = None) -> int:
    args, bags, _ = parse_bag_args(__doc__, argv, 'seen_ceiling')
    print_json(report(run_per_bag(check_bag, bags, None, args.jobs)), args.json)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
