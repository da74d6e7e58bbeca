"""Progress bars (frames, frames/s, ETA) for the offline tools, on a terminal only.

``tqdm`` is optional: without it, or when stderr is not a terminal (CI logs, pipes), every
call here is a no-op, so commands print the same lines either way. Work done in worker
processes is counted in one shared integer (:func:`shared_counter`, :func:`init_worker`,
:func:`report`) that the parent polls into the bar.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from endeff_ros.workers import ignore_sigint, process_pool

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


# Shared frame counter for worker processes -----------------------------------------------------

_COUNTER: Any = None


def shared_counter(ctx: Any = None) -> Any:
    """A process-shared integer for :func:`init_worker` (``ctx``: a multiprocessing context)."""
    import multiprocessing

    return (ctx or multiprocessing.get_context()).Value('q', 0)


def init_worker(counter: Any) -> None:
    """Pool initializer: :func:`report` in this worker adds to ``counter``. Ctrl-C (SIGINT to
    the terminal's whole process group) is left to the parent, which stops the workers
    (:func:`map_in_workers`): a worker interrupted while it waits for work would die with a
    traceback."""
    global _COUNTER
    _COUNTER = counter
    ignore_sigint()


def report(n: int = 1) -> None:
    """Add ``n`` frames to the shared counter (no-op outside a worker set up by init_worker)."""
    if _COUNTER is not None:
        with _COUNTER.get_lock():
            _COUNTER.value += n


def map_in_workers(fn: Callable[[Any], Any], jobs: Sequence[Any], workers: int,
                   bar: ProgressBar, *,
                   initializer: Callable[[Any], None] = init_worker) -> list[Any]:
    """``[fn(job) for job in jobs]`` on ``workers`` processes, in job order, while ``bar``
    follows the frames the workers :func:`report`. ``initializer(counter)`` sets a worker up
    (it must call :func:`init_worker`). On any exception (an interrupt) the pool's workers
    get SIGTERM (by default they end at once; a worker that installed its own handler
    unwinds its job), the pool is shut down (jobs not started are cancelled, the workers are
    waited for) and the exception goes on.
    """
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, wait

    ctx = multiprocessing.get_context()
    counter = shared_counter(ctx)
    with process_pool(workers, mp_context=ctx, initializer=initializer,
                      initargs=(counter,)) as pool:
        futures = [pool.submit(fn, j) for j in jobs]
        pending = set(futures)
        while pending:
            _, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            bar.update_to(counter.value)
        bar.update_to(counter.value)
    return [f.result() for f in futures]
