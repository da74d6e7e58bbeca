"""The main demonstration: every benchmark bag through ``endeff_node`` over DDS, scored.

    python -m tools.demo --data DIR [--only a,b] [--no-offline] [--json report.json]

For each bag in ``DIR/mcap`` (else ``DIR/sqlite3``, else the bags under ``DIR``) a fresh
``endeff_node`` process is started with the Fast DDS SHM profile, the bag is replayed to it over
DDS in lock-step (original stamps, jittered colour/depth send times; every depth image is sent
once the node answered the previous one, so every frame is processed as offline), and the
``end_effectors`` clouds are scored against the bag's ground truth (Section 6.1, per
``docs/benchmark-bags.md``). The same run also evaluates the bag offline with both the
temporal and the single-frame estimator (``endeff eval``), so the table shows the node's scores
next to the offline ones and the single-frame baseline.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.bag.reader import bag_name, find_bags
from endeff_ros.scoring import MethodScore, SequenceScorer, mean_over_sequences


def find_demo_bags(data: Path, only: str = '') -> list[Path]:
    """Bags of ``data/mcap`` (else ``data/sqlite3``, else under ``data``), sorted by name."""
    for sub in ('mcap', 'sqlite3', ''):
        root = data / sub if sub else data
        if root.is_dir():
            bags = find_bags([root])
            if bags:
                break
    else:
        bags = []
    names = {n.strip() for n in only.split(',') if n.strip()}
    return sorted((b for b in bags if not names or bag_name(b) in names), key=bag_name)


def score_record(record: dict[str, Any], gt: dict[int, np.ndarray]) -> SequenceScorer:
    """Score the node's clouds of a replay record against ground truth (per depth stamp)."""
    scorer = SequenceScorer()
    for stamp in record['depth_sent']:
        cloud = record['outputs']['node'].get(stamp)
        est = (np.stack([cloud['x'], cloud['y'], cloud['z']], axis=1) if cloud and cloud['x']
               else np.zeros((0, 3)))
        scorer.add(est, gt.get(stamp))
    return scorer


def run_bag(bag: Path, *, offline: bool) -> dict[str, Any]:
    """Node over DDS (and optionally offline) on one bag -> one report row."""
    from tools.dds_run import run_over_dds
    from tools.replay import BagSource

    with BagSource(bag) as source:
        gt = source.ground_truth()
    t0 = time.monotonic()
    record = run_over_dds(bag)
    scorer = score_record(record, gt)
    clouds = record['outputs']['node']
    row: dict[str, Any] = {
        'bag': bag_name(bag), 'frames': len(record['depth_sent']),
        'scored_frames': scorer.scored_frames, 'clouds': len(clouds),
        'missing_clouds': sum(s not in clouds for s in record['depth_sent']),
        'node_seconds': round(time.monotonic() - t0, 2),
        'temporal': scorer.result().to_json()}
    if offline:
        from endeff_ros.evaluate import evaluate_bag

        result = evaluate_bag(bag)
        row['offline_temporal'] = result.score('temporal').to_json()
        row['single_frame'] = result.score('single_frame').to_json()
    return row


def _ms(d: dict[str, Any]) -> MethodScore:
    return MethodScore(*(math.nan if d[k] is None else d[k]
                         for k in ('recall', 'mean_error_m', 'fpr')))


def build_report(rows: list[dict[str, Any]], failed: list[dict[str, str]]) -> dict[str, Any]:
    """Spec-form report: ``sequences`` and ``overall`` (temporal = the node over DDS)."""
    methods = [m for m in ('temporal', 'offline_temporal', 'single_frame')
               if rows and all(m in r for r in rows)]
    overall = {m: mean_over_sequences([_ms(r[m]) for r in rows]).to_json() for m in methods}
    return {'sequences': rows, 'overall': overall, 'failed': failed,
            'note': 'temporal: endeff_node over DDS (Fast DDS SHM profile); offline_temporal '
                    'and single_frame: endeff eval on the same bag in the same run'}


def format_table(report: dict[str, Any]) -> str:
    """Plain-text table: node over DDS, offline temporal, single-frame baseline."""
    methods = list(report['overall'])
    titles = {'temporal': 'node over DDS (temporal)', 'offline_temporal': 'offline temporal',
              'single_frame': 'single-frame (offline)'}

    def num(v: float | None) -> str:
        return '-' if v is None else f'{v:.3f}'

    def cols(d: dict[str, Any]) -> str:
        return f'{num(d["recall"]):>7} {num(d["mean_error_m"]):>7} {num(d["fpr"]):>7}'

    names = [r['bag'] for r in report['sequences']] + ['overall']
    w = max(len(n) for n in [*names, 'sequence']) + 2
    head1 = f'{"":{w}}{"":>14} | ' + ' | '.join(f'{titles[m]:^23}' for m in methods)
    head2 = (f'{"sequence":{w}}{"frames":>7}{"clouds":>7} | ' +
             ' | '.join(f'{"recall":>7} {"err m":>7} {"FPR":>7}' for _ in methods))
    lines = [head1, head2, '-' * len(head2)]
    for r in report['sequences']:
        lines.append(f'{r["bag"]:{w}}{r["frames"]:>7}{r["clouds"]:>7} | ' +
                     ' | '.join(cols(r[m]) for m in methods))
    lines.append('-' * len(head2))
    lines.append(f'{"overall":{w}}{"":>14} | ' +
                 ' | '.join(cols(report['overall'][m]) for m in methods))
    lines.extend(f'FAILED {f["bag"]}: {f["error"]}' for f in report['failed'])
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m tools.demo',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--data', required=True, type=Path,
                        help='directory holding mcap/<sequence> bags (endeff synth --out)')
    parser.add_argument('--only', default='', help='comma-separated sequence names')
    parser.add_argument('--no-offline', action='store_true',
                        help='skip the offline evaluation (node over DDS only)')
    parser.add_argument('--json', type=Path, help='write the report as JSON here')
    args = parser.parse_args(argv)
    bags = find_demo_bags(args.data, args.only)
    if not bags:
        print(f'no benchmark bags under {args.data} (run `endeff synth --out {args.data}`)',
              file=sys.stderr)
        return 2
    rows, failed = [], []
    for i, bag in enumerate(bags, 1):
        print(f'[{i}/{len(bags)}] {bag_name(bag)}: replaying to endeff_node over DDS...',
              file=sys.stderr, flush=True)
        try:
            rows.append(run_bag(bag, offline=not args.no_offline))
        except Exception as exc:  # noqa: BLE001 - report every bag, fail at the end
            failed.append({'bag': bag_name(bag), 'error': f'{type(exc).__name__}: {exc}'})
            print(f'  failed: {exc}', file=sys.stderr)
    report = build_report(rows, failed)
    print(format_table(report))
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + '\n', encoding='utf-8')
    return 1 if failed or any(r['missing_clouds'] for r in rows) else 0


if __name__ == '__main__':
    sys.exit(main())
