"""Run one check per bag, in parallel processes when asked (the bag tools of ``tools/``)."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from endeff_ros.cli_common import load_params_option
from endeff_ros.core.params import EndeffParams


def bag_paths(args: Sequence[str], every: int = 1) -> list[Path]:
    """The bags named by ``args`` (bag folders, or folders holding bag folders: each with a
    ``metadata.yaml``), sorted by path, every ``every``-th."""
    bags: list[Path] = []
    for arg in map(Path, args):
        if (arg / 'metadata.yaml').is_file():
            bags.append(arg)
        else:
            bags.extend(sorted(q.parent for q in arg.glob('*/metadata.yaml')))
    return sorted(bags)[::max(1, every)]


def parse_bag_args(doc: str, argv: list[str] | None, name: str,
                   ) -> tuple[argparse.Namespace, list[Path], EndeffParams | None]:
    """The command line of a per-bag tool (bags or folders, ``--every``, ``--params``,
    ``--jobs``, ``--json``): the parsed arguments, the bags and the parameters. ``doc``: the
    tool's docstring (its first line describes it); ``name``: the tool's name for errors."""
    parser = argparse.ArgumentParser(description=doc.split('\n')[0])
    parser.add_argument('bags', nargs='+', help='bags, or folders holding bags')
    parser.add_argument('--every', type=int, default=1, help='every N-th bag (sorted by name)')
    parser.add_argument('--params', help='parameter YAML (default: the defaults)')
    parser.add_argument('--jobs', type=int, default=1)
    parser.add_argument('--json', help='also write the report here')
    args = parser.parse_args(argv)
    params = load_params_option(args.params, name)
    bags = bag_paths(args.bags, args.every)
    if not bags:
        parser.error('no bags (folders with metadata.yaml) given')
    return args, bags, params


def run_per_bag(check: Callable[[Path, EndeffParams | None], Any], bags: Sequence[Path],
                params: EndeffParams | None, jobs: int) -> list[Any]:
    """``check(bag, params)`` for every bag, in order; ``jobs`` > 1 spreads the bags over
    that many spawned processes (``check`` must be a module-level function)."""
    work = [(b, params) for b in bags]
    if jobs <= 1:
        return [check(*w) for w in work]
    import multiprocessing

    with multiprocessing.get_context('spawn').Pool(jobs) as pool:
        return pool.starmap(check, work)
