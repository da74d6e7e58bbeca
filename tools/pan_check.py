"""After a camera pan: are the tracks' ids kept, and is the scene clean again within 2 s?

For every bag of the rooms suite whose camera pans (``*-pan``; the pan's stamps are in the
bag's ``endeff.details``), the tracker runs over the bag with the given parameters; tracks are
matched to the ground truth per frame as ``endeff eval`` does (``scoring.score_frame``).
Reported per bag: how many end-effectors (the ground truth's ``id``) in view in the last
frame before the pan, whose track is still reported in that frame, are matched to the same
track id when next matched after it (an end that left the image, or whose track had ended
before the pan, has no id to keep across it: counted apart as ``ids_gone_before``); as a
control, the same count summed over every instant of the still camera before and 2 s after
the pan (``still_ids_*``: how well the tracker keeps ids from one match to the next without
a pan); and the false positives per frame before the pan (after its first 10 frames), at
most during the pan and the 2 s after it, and from 2 s after the pan's end on.

A stricter reading of the ids, reported beside them (``ids_on_end_*``): only the ends
matched to their track in the eve itself are compared; an end whose track was still reported
there but had already left it (a false positive in that frame) had no track of its own on it
to keep across the pan.

    python -m tools.pan_check data/rooms/mcap [--params YAML] [--jobs 2] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from endeff_ros.attributes import custom_data
from endeff_ros.bag.reader import BagReader
from endeff_ros.cli_common import load_params_option, positive_int, print_json
from endeff_ros.core.errors import InputError
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.tracker import Tracker
from endeff_ros.evaluate import gt_ids
from endeff_ros.scoring import score_frame
from endeff_ros.synth.suite import DETAILS_KEY
from tools.per_bag import run_per_bag

if TYPE_CHECKING:
    import numpy.typing as npt

CLEAN_AFTER_NS = 2_000_000_000


def _pan_stamps(reader: BagReader) -> tuple[int, int]:
    """Stamps (ns) of the frames at which the bag's camera turn starts and ends."""
    pan = json.loads(custom_data(reader.reader)[DETAILS_KEY])['pan']
    return int(pan['start_stamp_ns']), int(pan['end_stamp_ns'])


def end_ids(gt: npt.NDArray[np.float64],
            gt_id: npt.NDArray[np.int64] | None) -> npt.NDArray[np.int64]:
    """The name of each ground-truth row: the ``id`` field (``gt_id``, aligned with ``gt``),
    whose row changes when another end-effector leaves or enters the view, as during a pan;
    without ids (None, or not aligned), the row index."""
    return gt_id if gt_id is not None and len(gt_id) == len(gt) else np.arange(len(gt))


def matched_ids(positions: npt.NDArray[np.float64], track_ids: list[int],
                gt: npt.NDArray[np.float64], gt_id: npt.NDArray[np.int64] | None,
                ) -> tuple[dict[int, int], int]:
    """``({ground-truth id: track id}, false positives)`` of one frame scored as ``endeff
    eval`` does, the ground truth named by :func:`end_ids`."""
    score = score_frame(np.asarray(positions, dtype=np.float64).reshape(-1, 3), gt[:, :3])
    key = end_ids(gt, gt_id)
    return {int(key[g]): int(track_ids[e]) for e, g in score.matches}, score.fp


class _Row(NamedTuple):
    """One scored frame: false positives, ``{ground-truth id: track id}``, the track ids
    reported and the ground-truth ids in view."""

    stamp_ns: int
    fp: int
    ids: dict[int, int]
    alive: set[int]
    in_view: set[int]


def ids_across(rows: list[_Row], at: int, *, on_end: bool = False) -> tuple[int, int, int]:
    """``(kept, compared, gone)`` across the instant ``at`` (ns). An end is compared when it
    is matched before and from ``at`` on, is in view in the eve (the last row before ``at``)
    and the track last matched to it is reported there (``on_end``: and matched to it
    there); it is kept when its first match from ``at`` on is that track. ``gone`` counts
    the other ends matched on both sides (they left the image, or their track ended or left
    them, before ``at``)."""
    before = [r for r in rows if r.stamp_ns < at]
    if not before:
        return 0, 0, 0
    last: dict[int, int] = {}
    for r in before:
        last.update(r.ids)
    first: dict[int, int] = {}
    for r in rows[len(before):]:
        for k, v in r.ids.items():
            first.setdefault(k, v)
    eve = before[-1]
    both = [k for k in last if k in first]
    compared = [k for k in both if k in eve.in_view and last[k] in eve.alive
                and (not on_end or eve.ids.get(k) == last[k])]
    return (sum(first[k] == last[k] for k in compared), len(compared),
            len(both) - len(compared))


def check_bag(bag: Path, params: EndeffParams | None = None) -> dict[str, Any]:
    """The figures above for one pan bag."""
    tracker = Tracker(params)
    rows: list[_Row] = []
    with BagReader(bag) as reader:
        start, end = _pan_stamps(reader)
        ids_by_stamp = gt_ids(reader)
        for frame, gt in reader.frames():
            try:
                tracks = tracker.update(frame).tracks
            except InputError:
                tracks = []
            if gt is None:
                continue
            gt_id = ids_by_stamp.get(frame.stamp_ns)
            ids, fp = matched_ids(np.array([t.position for t in tracks]), [t.id for t in tracks],
                                  gt, gt_id)
            rows.append(_Row(frame.stamp_ns, fp, ids, {t.id for t in tracks},
                             {int(i) for i in end_ids(gt, gt_id)}))
    before = [r for r in rows if r.stamp_ns < start]
    during = [r for r in rows if start <= r.stamp_ns < end + CLEAN_AFTER_NS]
    after = [r for r in rows if r.stamp_ns >= end + CLEAN_AFTER_NS]
    kept, compared, gone = ids_across(rows, start)
    kept_on_end, compared_on_end, _ = ids_across(rows, start, on_end=True)
    # The control: the same comparison across every instant of a still camera (before the
    # pan after its first 10 frames, and 2 s after it): what the tracker keeps without a pan.
    still = [ids_across(before, r.stamp_ns) for r in before[11:]]
    still += [ids_across(after, r.stamp_ns) for r in after[1:]]
    return {'bag': bag.name, 'ids_kept': kept, 'ids_compared': compared,
            'ids_gone_before': gone,
            'ids_on_end_kept': kept_on_end, 'ids_on_end_compared': compared_on_end,
            'still_ids_kept': sum(c[0] for c in still),
            'still_ids_compared': sum(c[1] for c in still),
            'fp_per_frame_before': float(np.mean([r.fp for r in before[10:]]))
            if len(before) > 10 else None,
            'fp_max_during': max((r.fp for r in during), default=0),
            'fp_per_frame_after_2s': float(np.mean([r.fp for r in after])) if after else None}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('folder', help='folder holding the rooms suite bags')
    parser.add_argument('--params', help='parameter YAML (default: the defaults)')
    parser.add_argument('--jobs', type=positive_int, default=1,
                        help='bags checked in parallel processes (default 1)')
    parser.add_argument('--json', help='also write the report here')
    args = parser.parse_args(argv)
    params = load_params_option(args.params, 'pan_check')
    bags = sorted(p for p in Path(args.folder).glob('*-pan') if (p / 'metadata.yaml').is_file())
    if not bags:
        parser.error(f'no pan bags (*-pan) in {args.folder}')
    per_bag = run_per_bag(check_bag, bags, params, args.jobs)

    def mean(key: str, rows: list[dict[str, Any]]) -> float | None:
        vals = [r[key] for r in rows if r[key] is not None]
        return round(float(np.mean(vals)), 3) if vals else None

    counts = ('ids_kept', 'ids_compared', 'ids_gone_before', 'ids_on_end_kept',
              'ids_on_end_compared', 'still_ids_kept', 'still_ids_compared')
    report: dict[str, Any] = {'bags': per_bag}
    for room in ('empty', 'furnished'):
        rows = [r for r in per_bag if f'-{room}-' in r['bag']]
        report[room] = {'bags': len(rows), **{k: sum(r[k] for r in rows) for k in counts},
                        **{k: mean(k, rows) for k in ('fp_per_frame_before',
                                                      'fp_per_frame_after_2s')}}
    print_json(report, args.json)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
