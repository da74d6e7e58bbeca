"""``endeff synth``: generate the synthetic benchmark bags.

Writes ``OUT/mcap/<sequence>/`` and/or ``OUT/sqlite3/<sequence>/`` (rosbag2, ROS 2 Jazzy
messages, form of ``docs/benchmark-bags.md``). Sequences are generated in parallel
worker processes (one per core, at most one per sequence).

Three suites: ``paper`` (default; the procedural sequences, unchanged), ``mocap`` (motion
capture clips with attributes, ``synth/suite.py``) and ``rooms`` (the same clips rendered in
pairs, empty and furnished room, and camera pans, ``synth/rooms_suite.py``). For the last two
``--only`` takes glob patterns of bag names and ``--list`` prints the specs without rendering.

Every bag is written aside and moved into place once complete (``synth/writer.py``), so that
every bag in ``OUT`` is complete whatever ends a worker (an error, Ctrl-C, SIGTERM, SIGKILL);
a bag of an earlier run stays until its replacement is complete.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import sys
import time
from pathlib import Path

from endeff_ros.bag.outputs import check_output_option
from endeff_ros.cli_common import EXIT_SIGINT, EXIT_SIGTERM, Terminated, positive_int
from endeff_ros.workers import run_jobs

from .sequences import GROUPS, SEQUENCES, SPECS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--suite', choices=('paper', 'mocap', 'rooms'), default='paper',
                        help='paper: the procedural sequences (default); mocap: motion-capture '
                             'clips with attributes; rooms: pairs of bags, empty and furnished '
                             'room, and camera pans')
    parser.add_argument('--out', type=Path, help='output directory (required unless --list)')
    parser.add_argument('--quick', action='store_true',
                        help='few frames per sequence (for tests), same motions')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3', 'both'), default=None,
                        help='rosbag2 storage plugin(s) to write (default: both for paper, '
                             'mcap for mocap and rooms)')
    parser.add_argument('--only', default='',
                        help='paper: comma-separated sequence names or groups '
                             f'({", ".join(GROUPS)}); mocap, rooms: comma-separated glob '
                             "patterns of bag names (e.g. 'dev__*'); default all")
    parser.add_argument('--clip-cache', type=Path, default=None,
                        help="mocap, rooms: folder of fetched clips (default: the "
                             "catalogue's own)")
    parser.add_argument('--max-seconds', type=float, default=None,
                        help='mocap full suite: longest segment per clip in s (default 5)')
    parser.add_argument('--list', action='store_true',
                        help='mocap, rooms: print the bag names and attributes, render '
                             'nothing')
    parser.add_argument('--no-margins', action='store_true',
                        help="mocap, rooms: render depth without the sensors' dead margins "
                             '(twins of the default bags, same names, for comparison)')
    parser.add_argument('--jobs', type=positive_int, default=None, metavar='N',
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
             seed: int = 0, jobs: int | None = None) -> dict[str, int]:
    """Generate the bags of ``names``; returns frames written per sequence."""
    jobs = jobs or os.cpu_count() or 1
    jobs = max(1, min(jobs, len(names)))
    if jobs == 1:
        return {n: generate_one(n, out, storages, quick, seed) for n in names}
    # Longest sequences first so the workers finish together.
    order = sorted(names, key=lambda n: -SPECS[n].frames)
    outcomes = run_jobs(generate_one, [(n, out, storages, quick, seed) for n in order], jobs)
    done = {n: o.result() for n, o in zip(order, outcomes, strict=True)}
    return {n: done[n] for n in names}


LOOP_S = 8.0  # full suite: cyclic clips (short walks, runs) repeated to this length


def load_suite_clips(quick: bool, cache: Path | None) -> list:
    """The clips of the mocap suite: committed ones only for ``quick``, else the catalogue
    with whatever has been fetched into ``cache`` and cyclic clips looped to ``LOOP_S`` (so
    that a walk can cross the view)."""
    from .mocap.catalogue import load_clips
    from .mocap.kin import MocapError

    try:
        return list(load_clips(cache_dir=cache, committed_only=quick,
                               loop_s=None if quick else LOOP_S))
    except (MocapError, OSError) as exc:
        msg = f'could not load the clip catalogue: {exc}'
        raise ValueError(msg) from exc


def select_specs(specs: list, only: str, suite: str = 'mocap') -> list:
    """The specs whose bag name matches one of the comma-separated glob patterns (all if
    empty); a pattern that matches nothing is an error."""
    pats = [t.strip() for t in only.split(',') if t.strip()]
    if not pats:
        return specs
    for pat in pats:
        if not any(fnmatch.fnmatchcase(s.name, pat) for s in specs):
            msg = f'--only pattern {pat!r} matches no bag of the {suite} suite'
            raise ValueError(msg)
    return [s for s in specs if any(fnmatch.fnmatchcase(s.name, p) for p in pats)]


def _mocap_one(spec, clips: dict, out: Path, storages: list[str]) -> dict:
    from .suite import write_bag

    return write_bag(spec, clips, out, storages)


def _suite_specs(args: argparse.Namespace, clips: list) -> list:
    """The specs of ``args.suite`` (mocap or rooms) for ``clips``."""
    from .cases import suite_specs
    from .rooms_suite import rooms_specs

    max_s = getattr(args, 'max_seconds', None)
    margins = not getattr(args, 'no_margins', False)
    if args.suite == 'rooms':
        if max_s is not None:
            msg = '--max-seconds applies to the mocap suite only (rooms bags have fixed lengths)'
            raise ValueError(msg)
        return rooms_specs(clips, quick=args.quick, seed=args.seed, margins=margins)
    extra = {} if max_s is None else {'max_s': max_s}
    return suite_specs(clips, quick=args.quick, seed=args.seed, margins=margins, **extra)


def run_mocap(args: argparse.Namespace, storages: list[str]) -> int:
    """``endeff synth --suite mocap|rooms``: render the suite's bags (longest first, in
    parallel)."""
    suite = getattr(args, 'suite', 'mocap')
    try:
        clips = load_suite_clips(args.quick, args.clip_cache)
        specs = select_specs(_suite_specs(args, clips), args.only, suite)
    except ValueError as exc:
        print(f'endeff synth: {exc}', file=sys.stderr)
        return 2
    if args.list:
        for s in specs:
            print(s.name, json.dumps(s.attributes, sort_keys=True))
        print(f'{len(specs)} bags, {sum(s.frames for s in specs)} frames')
        return 0
    byname = {c.name: c for c in clips}
    t0 = time.monotonic()
    jobs = max(1, min(args.jobs or os.cpu_count() or 1, len(specs)))
    results: dict[str, dict] = {}
    failed: dict[str, str] = {}
    if jobs == 1:
        for s in specs:
            try:
                results[s.name] = _mocap_one(s, byname, args.out, storages)
            except (OSError, ValueError, KeyError) as exc:
                failed[s.name] = f'{type(exc).__name__}: {exc}'
    else:
        order = sorted(specs, key=lambda s: -s.frames * len(s.people))
        outcomes = run_jobs(_mocap_one, [
            (s, {p.clip: byname[p.clip] for p in s.people}, args.out, storages)
            for s in order], jobs)
        by_name = {s.name: o for s, o in zip(order, outcomes, strict=True)}
        for s in specs:
            try:
                results[s.name] = by_name[s.name].result()
            except (OSError, ValueError, KeyError) as exc:
                failed[s.name] = f'{type(exc).__name__}: {exc}'
    dt = time.monotonic() - t0
    total = sum(r['frames'] for r in results.values())
    for name, r in results.items():
        print(f"{name}: {r['frames']} frames, truncated={r['truncated']}")
    print(f'wrote {len(results)} {suite} bags ({total} frames) x {len(storages)} storage(s) '
          f'to {args.out} in {dt:.1f} s')
    for name, why in failed.items():
        print(f'endeff synth: bag {name} failed: {why}', file=sys.stderr)
    return 1 if failed else 0


def run(args: argparse.Namespace) -> int:
    """``endeff synth``: the exit statuses of :mod:`endeff_ros.cli_common`."""
    try:
        return _run(args)
    except KeyboardInterrupt as err:
        print('endeff synth: interrupted; bags not finished were removed (finished ones are '
              'complete)', file=sys.stderr)
        return EXIT_SIGTERM if isinstance(err, Terminated) else EXIT_SIGINT


def _run(args: argparse.Namespace) -> int:
    suite = getattr(args, 'suite', 'paper')
    clips_suite = suite in ('mocap', 'rooms')
    listing = clips_suite and getattr(args, 'list', False)
    if args.out is None and not listing:
        print('endeff synth: --out is required', file=sys.stderr)
        return 2
    if not listing:  # an output that cannot be written: one line before any rendering
        check_output_option(str(args.out), 'endeff synth', kind='dir')
    storage = args.storage or ('mcap' if clips_suite else 'both')
    storages = ['mcap', 'sqlite3'] if storage == 'both' else [storage]
    if clips_suite:
        return run_mocap(args, storages)
    try:
        names = select(args.only)
    except ValueError as exc:
        print(f'endeff synth: {exc}', file=sys.stderr)
        return 2
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
