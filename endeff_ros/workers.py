"""Process pools that an interrupt stops: Ctrl-C or SIGTERM ends the command promptly.

A ``concurrent.futures.ProcessPoolExecutor`` left by an exception runs every queued job before
it shuts down, and its workers, which share the terminal's process group, get Ctrl-C too and
die with a traceback when it finds them waiting for work. :func:`process_pool` gives a pool
whose workers ignore SIGINT (the parent decides) and which, when its block is left by an
exception, sends SIGTERM to its own workers (not to other children of the caller), cancels
the queued jobs and waits for the workers to exit before the exception goes on.
"""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any


def ignore_sigint(*_args: Any) -> None:
    """Pool initializer: leave Ctrl-C to the parent, which stops the workers."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextmanager
def process_pool(workers: int, *, mp_context: Any = None,
                 initializer: Callable[..., None] = ignore_sigint,
                 initargs: tuple[Any, ...] = ()) -> Iterator[ProcessPoolExecutor]:
    """A pool of ``workers`` processes for a ``with`` block (see the module docstring).
    ``initializer`` must leave SIGINT ignored (:func:`ignore_sigint` does)."""
    others = {child.pid for child in multiprocessing.active_children()}
    pool = ProcessPoolExecutor(max_workers=workers,
                               mp_context=mp_context or multiprocessing.get_context(),
                               initializer=initializer, initargs=initargs)
    try:
        yield pool
    except BaseException:
        for child in multiprocessing.active_children():
            if child.pid not in others:
                child.terminate()
        # Waited for: shutdown(wait=False) leaves the pool's manager thread running while the
        # interpreter exits, and the thread can close its wake-up pipe while the exit handler
        # writes to it ("Exception ignored ... OSError: Bad file descriptor" printed at exit).
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown()
