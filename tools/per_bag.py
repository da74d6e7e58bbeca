"""Run one check per bag, in parallel processes when asked (the bag tools of ``tools/``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

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
