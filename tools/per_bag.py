"""Run one check per bag, in parallel processes when asked (the bag tools of ``tools/``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from endeff_ros.core.params import EndeffParams


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
