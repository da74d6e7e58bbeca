"""Run one check per bag, in parallel processes when asked (the bag tools of ``tools/``)."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from endeff_ros.bag.errors import BagError
from endeff_ros.bag.reader import find_bags
from endeff_ros.cli_common import load_params_option, positive_int
from endeff_ros.core.params import EndeffParams


def parse_bag_args(doc: str, argv: list[str] | None, name: str,
                   extra: Callable[[argparse.ArgumentParser], None] | None = None,
                   ) -> tuple[argparse.Namespace, list[Path], EndeffParams | None]:
    """The command line of a per-bag tool (bags or folders searched for bags as ``endeff
    eval`` does, ``--every``, ``--params``, ``--jobs``, ``--json``): the parsed arguments, the
    bags (sorted by path, every ``--every``-th) and the parameters. ``doc``: the
    tool's docstring (its first line describes it); ``name``: the tool's name for errors;
    ``extra(parser)`` adds the tool's own options."""
    parser = argparse.ArgumentParser(description=doc.split('\n')[0])
    if extra is not None:
        extra(parser)
    parser.add_argument('bags', nargs='+', help='bags, or folders holding bags')
    parser.add_argument('--every', type=int, default=1, help='every N-th bag (sorted by name)')
    parser.add_argument('--params', help='parameter YAML (default: the defaults)')
    parser.add_argument('--jobs', type=positive_int, default=1,
                        help='bags checked in parallel processes (default 1)')
    parser.add_argument('--json', help='also write the report here')
    args = parser.parse_args(argv)
    params = load_params_option(args.params, name)
    try:
        bags = sorted(find_bags(args.bags))[::max(1, args.every)]
    except BagError as exc:
        parser.error(f'no bags: {exc}')
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
