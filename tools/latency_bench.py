"""End-to-end latency of endeff_node over DDS, against a trivial relay in the same run.

A synthetic (or any benchmark) bag is replayed at a fixed rate (30 Hz by default, open loop, as
a live camera would send it) to ``endeff_node`` and to :mod:`tools.relay`, each in its
own process with the Fast DDS SHM profile. Latency is measured from the publication of each
depth image to the receipt of the output stamped with it (same clock, the driver process).
A frame without an output is ``dropped`` (the node skips frames it is too slow for), unless
its depth image had no colour image within the node's ``sync_slop`` in the bag: those are
``unpaired_inputs`` (the synthetic bags drop a few colour images on purpose; the node answers
such a depth image without colour, so they normally have an output too).

Lost colour images: ``--drop-color-every N`` withholds every N-th colour image, ``--no-color``
sends none (no colour topic at all). The depth images whose colour was withheld are accounted
apart, under ``node.color_dropped`` (sent, outputs, ``dropped_frames``, their latency); the
top-level percentiles cover every output. ``--compare-drops`` runs all colour, 1 colour image
in 10 withheld and no colour one after another (``--rounds`` times, alternating) and prints
one JSON with the node's p50/p95 per case and the differences to the all-colour case.

    python -m tools.latency_bench [--bag BAG] [--rate 30] [--loops 3] [--no-profile]
    python -m tools.latency_bench --compare-drops [--rounds 2] [--loops 3]

``benchmark()`` (what ``python -m tools.bench --ros`` calls), ``ros_latency_bench()`` and
``compare_drops()`` return the JSON-ready dict.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.cli_common import load_params_option, print_json
from tools.replay import positive_int

DEFAULT_SEQUENCE = 'jumping_jacks'


def _default_bag(tmp: Path) -> Path:
    """``data/synth/mcap/<sequence>`` if generated, else a full-length synthetic bag in ``tmp``."""
    here = Path(__file__).resolve().parents[1] / 'data' / 'synth' / 'mcap' / DEFAULT_SEQUENCE
    if (here / 'metadata.yaml').is_file():
        return here
    from endeff_ros.synth.cli import generate_one

    generate_one(DEFAULT_SEQUENCE, tmp, ['mcap'], False, 0)
    return tmp / 'mcap' / DEFAULT_SEQUENCE


def ros_latency_bench(bag: str | Path | None = None, *, rate_hz: float = 30.0,
                      markers: bool = False,
                      loops: int = 3, profile: bool = True,
                      max_frames: int | None = None,
                      node_params: dict[str, Any] | None = None,
                      drop_color_every: int | None = None,
                      no_color: bool = False) -> dict[str, Any]:
    """Replay ``bag`` (default: a synthetic sequence) at ``rate_hz``; node vs relay latency.

    Returns ``{'bag', 'rate_hz', 'fastdds_profile', 'color', 'node': {...}, 'relay': {...},
    'node_diagnostics': {...}}`` where node and relay hold ``frames_sent``, ``outputs``,
    ``dropped_frames``, ``latency_ms_p50/p95/p99/max`` and ``color_dropped`` (the same for
    the depth images whose colour was withheld). ``markers``: also subscribe to
    ``end_effectors/markers`` (as RViz would), which makes the node build them.
    ``drop_color_every=N``: withhold every N-th colour image; ``no_color``: send none.
    """
    from tools.dds_run import run_over_dds

    with tempfile.TemporaryDirectory(prefix='endeff_bench_') as tmp:
        path = Path(bag) if bag is not None else _default_bag(Path(tmp))
        record = run_over_dds(path, rate_hz=rate_hz, relay=True, profile=profile,
                             max_frames=max_frames, loops=loops, frame_timeout_s=5.0,
                             node_params=node_params, markers=markers,
                             drop_color_every=drop_color_every, no_color=no_color)
    diag = record.get('diagnostics', {})
    keys = ('processed', 'prepared', 'prepared_flow', 'flow_alongside', 'skipped', 'colorless',
            'dropped_unpaired.color', 'dropped_unpaired.depth', 'processing_ms.p50',
            'processing_ms.p95', 'processing_ms.p99', 'warnings.color_lost',
            'warnings.color_late', 'warnings.color_stopped')
    color = 'none' if no_color else (f'1 in {drop_color_every} withheld'
                                     if drop_color_every else 'all')
    return {'bag': str(path), 'rate_hz': rate_hz, 'loops': loops,
            'fastdds_profile': profile, 'markers_subscribed': markers, 'color': color,
            'node': record['latency']['node'],
            'relay': record['latency']['relay'],
            'node_diagnostics': {k: diag[k] for k in keys if k in diag}}


#: The cases of :func:`compare_drops`: name -> ``ros_latency_bench`` colour options.
DROP_CASES = {'all_color': {}, 'drop_color_1_in_10': {'drop_color_every': 10},
              'no_color': {'no_color': True}}
#: What a case may cost over all colour: (percentile, ms). Losing 1 colour image in 10 should
#: barely show at p95; a camera without colour may wait a little for colour at the start.
DROP_TARGETS = {'drop_color_1_in_10': ('p95', 5.0), 'no_color': ('p50', 10.0)}


def compare_drops(bag: str | Path | None = None, *, rounds: int = 1,
                  **kwargs: Any) -> dict[str, Any]:
    """:func:`ros_latency_bench` with all colour, 1 colour image in 10 withheld and no colour,
    one after another (``rounds`` times, in that order, so that a drift of the machine's speed
    touches every case); ``kwargs`` go to every run.

    Returns ``{'cases': {case: {'node': {p50, p95, outputs, dropped_frames, color_dropped...},
    'relay_p95', 'runs': [...]}}, 'differences': {case: {'p50_ms', 'p95_ms'}}, 'targets':
    {case: {'percentile', 'limit_ms', 'met', 'every_frame_answered'}}}``: per case the median
    over rounds of the node's p50 and p95 (ms), frames without output (with colour, and of
    those whose colour was withheld), the differences of the medians to the all-colour case,
    and whether they are within :data:`DROP_TARGETS`. Each run's full result is kept under
    ``runs``.
    """
    with tempfile.TemporaryDirectory(prefix='endeff_bench_') as tmp:
        path = Path(bag) if bag is not None else _default_bag(Path(tmp))
        runs: dict[str, list[dict[str, Any]]] = {case: [] for case in DROP_CASES}
        for _ in range(rounds):
            for case, options in DROP_CASES.items():
                runs[case].append(ros_latency_bench(path, **kwargs, **options))
    cases = {case: _case_summary(results) for case, results in runs.items()}
    base = cases['all_color']['node']
    differences = {case: {f'{q}_ms': _minus(c['node'].get(f'latency_ms_{q}'),
                                            base.get(f'latency_ms_{q}'))
                          for q in ('p50', 'p95')}
                   for case, c in cases.items() if case != 'all_color'}
    targets = {case: {'percentile': q, 'limit_ms': limit,
                      'met': differences[case][f'{q}_ms'] is not None
                      and differences[case][f'{q}_ms'] <= limit,
                      'every_frame_answered': cases[case]['node']['outputs']
                      == cases[case]['node']['frames_sent']}
               for case, (q, limit) in DROP_TARGETS.items()}
    return {'bag': str(path), 'rounds': rounds, 'cases': cases, 'differences': differences,
            'targets': targets}


def _case_summary(results: list[dict[str, Any]]) -> dict[str, Any]:
    """One case of :func:`compare_drops`: medians over its runs, counts summed."""
    def median(values: list[Any]) -> float | None:
        values = [v for v in values if v is not None]
        return round(float(np.median(values)), 3) if values else None

    nodes = [r['node'] for r in results]
    node = {f'latency_ms_{q}': median([n.get(f'latency_ms_{q}') for n in nodes])
            for q in ('p50', 'p95')}
    for key in ('frames_sent', 'outputs', 'dropped_frames', 'unpaired_inputs'):
        node[key] = sum(n[key] for n in nodes)
    node['color_dropped'] = {
        **{key: sum(n['color_dropped'][key] for n in nodes)
           for key in ('frames_sent', 'outputs', 'dropped_frames')},
        **{f'latency_ms_{q}': median([n['color_dropped'].get(f'latency_ms_{q}') for n in nodes])
           for q in ('p50', 'p95')}}
    return {'color': results[0]['color'], 'node': node,
            'relay_p95_ms': median([r['relay'].get('latency_ms_p95') for r in results]),
            'runs': results}


def _minus(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None else round(a - b, 3)


def benchmark(**kwargs: Any) -> dict[str, Any]:
    """``python -m tools.bench --ros``: :func:`ros_latency_bench` with every CPU available.

    ``tools.bench`` pins itself to one core for the single-frame timings; the node, the relay
    and the driver are child processes and would inherit that, so the pinning is lifted for
    the duration of the run.
    """
    pinned = os.sched_getaffinity(0) if hasattr(os, 'sched_getaffinity') else None
    try:
        if pinned is not None:
            try:
                os.sched_setaffinity(0, set(range(os.cpu_count() or 1)))
            except OSError:
                pass
        return ros_latency_bench(**kwargs)
    finally:
        if pinned is not None:
            os.sched_setaffinity(0, pinned)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bag', help='benchmark bag (default: a synthetic sequence)')
    parser.add_argument('--rate', type=float, default=30.0, help='depth images per second')
    parser.add_argument('--loops', type=int, default=3, help='replay the bag this many times')
    parser.add_argument('--max-frames', type=int, default=None)
    parser.add_argument('--no-profile', action='store_true',
                        help='run without the Fast DDS SHM profile (for comparison)')
    parser.add_argument('--json', help='also write the result to this file')
    parser.add_argument('--markers', action='store_true',
                        help='also subscribe to the markers, as RViz would (the node builds '
                             'them only for subscribers)')
    parser.add_argument('--params', metavar='YAML', help='node parameter file (e.g. the fast '
                        'preset config/endeff_fast.yaml)')
    color = parser.add_mutually_exclusive_group()
    color.add_argument('--drop-color-every', type=positive_int, metavar='N',
                       help='withhold every N-th colour image (a camera losing colour images)')
    color.add_argument('--no-color', action='store_true',
                       help='send no colour image at all (no colour topic)')
    color.add_argument('--compare-drops', action='store_true',
                       help='run all colour, 1 in 10 withheld and no colour one after another; '
                            'one JSON with p50/p95 per case and the differences')
    parser.add_argument('--rounds', type=positive_int, default=1,
                        help='--compare-drops: repeat the three cases this many times')
    args = parser.parse_args(argv)
    params = load_params_option(args.params, 'latency_bench')
    common = {'rate_hz': args.rate, 'loops': args.loops, 'profile': not args.no_profile,
              'max_frames': args.max_frames, 'markers': args.markers,
              'node_params': params.to_dict() if params else None}
    if args.compare_drops:
        result = compare_drops(args.bag, rounds=args.rounds, **common)
    else:
        result = ros_latency_bench(args.bag, drop_color_every=args.drop_color_every,
                                   no_color=args.no_color, **common)
    print_json(result, args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
