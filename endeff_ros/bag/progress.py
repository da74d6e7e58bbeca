"""Progress bars (frames, frames/s, ETA) for the offline tools, on a terminal only.

``tqdm`` is optional: without it, or when stderr is not a terminal (CI logs, pipes), every
call here is a no-op, so commands print the same lines either way. Work done in worker
processes is sent to the parent over each worker's pipe (:func:`report`,
:func:`endeff_ros.workers.report_progress`) and added to the bar there.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from endeff_ros.workers import report_progress, run_jobs

if TYPE_CHECKING:
    from collections.abc import Iterable
    from pathlib import Path

    from .reader import ReaderOptions


class ProgressBar:
    """A frame counter drawn by tqdm on stderr when enabled; a context manager."""

    def __init__(self, total: int, *, desc: str = '', enabled: bool | None = None) -> None:
        self.done = 0
        self._bar: Any = None
        if enabled is None:
            enabled = sys.stderr.isatty()
        if not enabled:
            return
        try:
            from tqdm import tqdm
        except ImportError:  # optional dependency: no bar
            return
        self._bar = tqdm(total=max(int(total), 0) or None, desc=desc or None, unit='frame',
                         file=sys.stderr, dynamic_ncols=True, smoothing=0.1, leave=True)

    @property
    def enabled(self) -> bool:
        """Whether a bar is drawn."""
        return self._bar is not None

    def update(self, n: int = 1) -> None:
        """Count ``n`` more frames."""
        self.done += n
        if self._bar is not None and n:
            if self._bar.total is not None and self.done > self._bar.total:
                self._bar.total = self.done
            self._bar.update(n)

    def update_to(self, done: int) -> None:
        """Set the count to ``done`` (for a counter polled from workers)."""
        self.update(done - self.done)

    def close(self) -> None:
        """Finish the bar's line."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def progress_bar(total: int, *, desc: str = '', enabled: bool | None = None) -> ProgressBar:
    """A :class:`ProgressBar` of ``total`` frames (drawn only on a terminal, with tqdm)."""
    return ProgressBar(total, desc=desc, enabled=enabled)


def count_frames(paths: Iterable[Path], options: ReaderOptions | None = None) -> int:
    """Depth messages listed in the bags' indexes: the bar's total (bags that cannot be opened
    count 0; their error is reported when they are processed)."""
    from .errors import BagError
    from .reader import BagReader

    total = 0
    for p in paths:
        try:
            with BagReader(p, options, warn=lambda _text: None) as bag:
                total += bag.depth_count
        except BagError:
            pass
    return total


# Frames counted in worker processes ------------------------------------------------------------


def report(n: int = 1) -> None:
    """In a worker of :func:`map_in_workers`: ``n`` more frames for the parent's bar (a no-op
    elsewhere)."""
    report_progress(n)


def map_in_workers(fn: Callable[[Any], Any], jobs: Sequence[Any], workers: int,
                   bar: ProgressBar) -> list[Any]:
    """``[fn(job) for job in jobs]`` on ``workers`` spawned processes, in job order, while
    ``bar`` follows the frames the workers :func:`report`. ``fn`` is expected to return its
    errors; one it raises is raised here. An interrupt stops every worker within seconds
    (:mod:`endeff_ros.workers`: a worker's job unwinds on SIGTERM) and goes on.
    """
    outcomes = run_jobs(fn, [(j,) for j in jobs], workers, on_progress=bar.update_to)
    return [o.result() for o in outcomes]
