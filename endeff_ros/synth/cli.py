"""``endeff synth``: generate the synthetic benchmark bags.

Writes ``OUT/mcap/<sequence>/`` and/or ``OUT/sqlite3/<sequence>/`` (rosbag2, ROS 2 Jazzy
messages, form of ``shared/spec/benchmark-bags.md``). Sequences are generated in parallel
worker processes (one per core, at most one per sequence).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from .sequences import GROUPS, SEQUENCES, SPECS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--out', required=True, type=Path, help='output directory')
    parser.add_argument('--quick', action='store_true',
                        help='few frames per sequence (for tests), same motions')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3', 'both'), default='both',
                        help='rosbag2 storage plugin(s) to write (default both)')
    parser.add_argument('--only', default='',
                        help='comma-separated sequence names or groups '
                             f'({", ".join(GROUPS)}); default all')
    parser.add_argument('--jobs', type=int, default=0,
                        help='worker processes (default: number of CPUs)')


def select(only: str) -> list[str]:
    """Sequence names from a comma-separated list of names and group names (all if empty)."""
    if not only.strip():
        return list(SEQUENCES)
    names: list[str] = []
    for tok in (t.strip() for t in only.split(',') if t.strip()):
        if tok in GROUPS:
            names.extend(GROUPS[tok])
        elif tok in SPECS:
            names.append(tok)
        else:
            msg = (f'unknown sequence or group {tok!r}; sequences: {", ".join(SEQUENCES)}; '
                   f'groups: {", ".join(GROUPS)}')
            raise ValueError(msg)
    return [n for n in SEQUENCES if n in names]


def generate_one(name: str, out: Path, storages: list[str], quick: bool, seed: int) -> int:
    """Render sequence ``name`` and write it to ``out/<storage>/<name>``; returns frames."""
    from .frames import render_sequence
    from .writer import write_bags

    paths = {s: Path(out) / s / name for s in storages}
    return write_bags(render_sequence(name, quick=quick, seed=seed), SPECS[name], paths, seed)


def generate(out: Path, names: list[str], storages: list[str], *, quick: bool = False,
             seed: int = 0, jobs: int = 0) -> dict[str, int]:
    """Generate the bags of ``names``; returns frames written per sequence."""
    jobs = jobs or os.cpu_count() or 1
    jobs = max(1, min(jobs, len(names)))
    if jobs == 1:
        return {n: generate_one(n, out, storages, quick, seed) for n in names}
    # Longest sequences first so the workers finish together; spawned workers (no fork of a
    # possibly multi-threaded caller).
    order = sorted(names, key=lambda n: -SPECS[n].frames)
    with ProcessPoolExecutor(jobs, mp_context=get_context('spawn')) as pool:
        futs = {n: pool.submit(generate_one, n, out, storages, quick, seed) for n in order}
        return {n: futs[n].result() for n in names}


def run(args: argparse.Namespace) -> int:
    try:
        names = select(args.only)
    except ValueError as exc:
        print(f'endeff synth: {exc}', file=sys.stderr)
        return 2
    storages = ['mcap', 'sqlite3'] if args.storage == 'both' else [args.storage]
    t0 = time.monotonic()
    counts = generate(args.out, names, storages, quick=args.quick, seed=args.seed,
                      jobs=args.jobs)
    dt = time.monotonic() - t0
    total = sum(counts.values())
    for n in names:
        print(f'{n}: {counts[n]} frames')
    print(f'wrote {len(names)} sequences ({total} frames) x {len(storages)} storage(s) '
          f'to {args.out} in {dt:.1f} s')
    return 0
