"""End-to-end latency of endeff_node over DDS, against a trivial relay in the same run.

A synthetic (or any benchmark) bag is replayed at a fixed rate (30 Hz by default, open loop, as
a live camera would send it) to ``endeff_node`` and to :mod:`tools.relay`, each in its
own process with the Fast DDS SHM profile. Latency is measured from the publication of each
depth image to the receipt of the output stamped with it (same clock, the driver process).
A frame without an output is ``dropped`` (the node skips frames it is too slow for), unless
its depth image had no colour image within the node's ``sync_slop`` in the bag: those are
``unpaired_inputs`` (the synthetic bags drop a few colour images on purpose; the
approximate-time synchroniser cannot complete such a set, and the node only processes a depth
image alone once colour has been missing for ``color_timeout``).

    python -m tools.latency_bench [--bag BAG] [--rate 30] [--loops 3] [--no-profile]

``benchmark()`` (what ``python -m tools.bench --ros`` calls) and ``ros_latency_bench()`` return the
JSON-ready dict.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from endeff_ros.cli_common import load_params_option, print_json

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
                      node_params: dict[str, Any] | None = None) -> dict[str, Any]:
    """Replay ``bag`` (default: a synthetic sequence) at ``rate_hz``; node vs relay latency.

    Returns ``{'bag', 'rate_hz', 'fastdds_profile', 'node': {...}, 'relay': {...},
    'node_diagnostics': {...}}`` where node and relay hold ``frames_sent``, ``outputs``,
    ``dropped_frames`` and ``latency_ms_p50/p95/p99/max``. ``markers``: also subscribe to
    ``end_effectors/markers`` (as RViz would), which makes the node build them.
    """
    from tools.session import run_session

    with tempfile.TemporaryDirectory(prefix='endeff_bench_') as tmp:
        path = Path(bag) if bag is not None else _default_bag(Path(tmp))
        record = run_session(path, rate_hz=rate_hz, relay=True, profile=profile,
                             max_frames=max_frames, loops=loops, frame_timeout_s=5.0,
                             node_params=node_params, markers=markers)
    diag = record.get('diagnostics', {})
    keys = ('processed', 'prepared', 'prepared_flow', 'flow_alongside', 'skipped', 'colorless',
            'dropped_unpaired.color', 'dropped_unpaired.depth', 'processing_ms.p50',
            'processing_ms.p95', 'processing_ms.p99')
    return {'bag': str(path), 'rate_hz': rate_hz, 'loops': loops,
            'fastdds_profile': profile, 'markers_subscribed': markers,
            'node': record['latency']['node'],
            'relay': record['latency']['relay'],
            'node_diagnostics': {k: diag[k] for k in keys if k in diag}}


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
    args = parser.parse_args(argv)
    params = load_params_option(args.params, 'latency_bench')
    result = ros_latency_bench(args.bag, rate_hz=args.rate, loops=args.loops,
                               profile=not args.no_profile, max_frames=args.max_frames,
                               markers=args.markers,
                               node_params=params.to_dict() if params else None)
    print_json(result, args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
