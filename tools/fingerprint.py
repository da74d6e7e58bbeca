"""Per-frame fingerprints of what the estimators publish: does a change leave behaviour as it was?

A speed-up or a reorganisation should publish exactly what the code before it did. For each
bag, the tracker (as ``endeff eval`` runs it, static background included) and the
single-frame estimator with a background of its own run over every frame; each frame's
published tracks (id, state, position) and single-frame positions, rounded to a nanometre,
are hashed, and the bag's digest chains the frames' hashes. A frame an estimator rejects
(``InputError``) hashes as such.

``--compare OLD.json`` (a report this tool wrote, e.g. from a ``git worktree`` of the code
before) lists the bags whose digests differ and the first frame that differs in each, and
exits with status 1 if any does (2 for bags missing from either report or that could not be
read). Without it, the report is printed (and written with ``--json``); a bag that cannot be
read (corrupt, truncated) is named on stderr, has no digest, and the status is 2.

    python -m tools.fingerprint BAG_OR_DIR [...] [--every N] [--params YAML] [--jobs 2]
                                [--json OUT] [--compare OLD.json]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.bag.errors import BagError
from endeff_ros.bag.reader import BagReader
from endeff_ros.cli_common import print_json
from endeff_ros.core.errors import InputError
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.tracker import Tracker
from endeff_ros.evaluate import _background_estimate
from tools.per_bag import parse_bag_args, run_per_bag

#: Positions are hashed rounded to this many decimals of a metre (a nanometre): the last
#: bits of a float sum may differ between numpy builds, behaviour may not.
DECIMALS = 9


def _frame_hash(tracks: Any, single: Any) -> str:
    h = hashlib.sha1()
    if tracks is None:
        h.update(b'tracker: input error')
    else:
        for t in tracks:
            h.update(repr((int(t.id), int(t.state))).encode())
            h.update(np.round(np.asarray(t.position, dtype=np.float64), DECIMALS).tobytes())
    h.update(b'|')
    if single is None:
        h.update(b'single frame: input error')
    else:
        h.update(np.round(np.asarray(single, dtype=np.float64).reshape(-1, 3), DECIMALS).tobytes())
    return h.hexdigest()[:16]


def fingerprint_bag(bag: Path, params: EndeffParams | None = None) -> dict[str, Any]:
    """The bag's name, frame count, per-frame hashes and digest; a bag that cannot be read
    (``BagError``: corrupt, truncated, missing topics) has no digest and says why."""
    tracker = Tracker(params or EndeffParams())
    estimate = _background_estimate()
    frames = []
    try:
        with BagReader(bag) as reader:
            for frame, _ in reader.frames():
                try:
                    tracks = tracker.update(frame).tracks
                except InputError:
                    tracks = None
                try:
                    single = estimate(frame, params).positions()
                except InputError:
                    single = None
                frames.append(_frame_hash(tracks, single))
    except BagError as exc:
        return {'bag': bag.name, 'frames': len(frames), 'digest': None, 'error': str(exc),
                'frame_hashes': frames}
    digest = hashlib.sha1('\n'.join(frames).encode()).hexdigest()[:16]
    return {'bag': bag.name, 'frames': len(frames), 'digest': digest, 'frame_hashes': frames}


def compare(old: dict[str, Any], new: dict[str, Any]) -> tuple[int, list[str]]:
    """Exit status and the lines telling how reports ``old`` and ``new`` differ."""
    a = {b['bag']: b for b in old['bags']}
    b = {x['bag']: x for x in new['bags']}
    lines, status = [], 0
    for name in sorted(set(a) | set(b)):
        if name not in a or name not in b:
            lines.append(f'{name}: only in the {"new" if name in b else "old"} report')
            status = 2
            continue
        if a[name]['digest'] is None or b[name]['digest'] is None:
            why = a[name].get('error') or b[name].get('error')
            lines.append(f'{name}: not read in the {"old" if a[name]["digest"] is None else "new"}'
                         f' run: {why}')
            status = 2
            continue
        if a[name]['digest'] == b[name]['digest']:
            continue
        status = max(status, 1)
        first = next((i for i, (x, y) in enumerate(zip(a[name]['frame_hashes'],
                                                         b[name]['frame_hashes'])) if x != y),
                     min(a[name]['frames'], b[name]['frames']))
        lines.append(f'{name}: differs from frame {first} on ({a[name]["frames"]} / '
                     f'{b[name]["frames"]} frames)')
    same = sum(1 for n in set(a) & set(b)
               if a[n]['digest'] is not None and a[n]['digest'] == b[n]['digest'])
    lines.append(f'{same} of {len(set(a) | set(b))} bags identical')
    return status, lines


def _compare_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--compare', metavar='OLD.json',
                        help='compare with a report this tool wrote (exit status 1: differs)')


def main(argv: list[str] | None = None) -> int:
    args, bags, params = parse_bag_args(__doc__, argv, 'fingerprint', _compare_option)
    old_path = args.compare
    report = {'bags': run_per_bag(fingerprint_bag, bags, params, args.jobs)}
    unread = [b for b in report['bags'] if b['digest'] is None]
    for b in unread:
        print(f'fingerprint: {b["error"]}', file=sys.stderr)
    if old_path is None:
        print_json(report, args.json)
        return 2 if unread else 0
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1) + '\n')
    try:
        old = json.loads(Path(old_path).read_text())
    except (OSError, ValueError) as exc:
        print(f'fingerprint: cannot read {old_path}: {exc}', file=sys.stderr)
        return 2
    status, lines = compare(old, report)
    print('\n'.join(lines))
    return status


if __name__ == '__main__':
    raise SystemExit(main())
