"""Worker processes that an interrupt always stops: Ctrl-C or SIGTERM ends the command within
seconds, with every worker gone.

Why not ``concurrent.futures.ProcessPoolExecutor``: its workers share one job pipe guarded by
a lock, so a worker stopped at the wrong moment leaves the others blocked on that lock or on
the pipe, which never reaches end-of-file while any worker holds its write end; its shutdown
and its exit handler join threads and processes without a time limit; and forking from a
process that already runs threads (tqdm, rosbags, BLAS) can deadlock the child. Hence
:func:`run_jobs`:

- workers are *spawned* (a fresh interpreter, nothing inherited from the caller's threads);
- each worker has its own pipe to the parent, and takes a job only when idle: no shared lock;
- workers ignore SIGINT (Ctrl-C reaches the whole process group; the parent decides) and
  raise :class:`~endeff_ros.cli_common.Terminated` on SIGTERM, which unwinds the job they run
  (its ``finally`` blocks remove partial outputs) or ends an idle worker quietly;
- workers die with their parent: on Linux the kernel sends them SIGTERM when it goes
  (``PR_SET_PDEATHSIG``), elsewhere a watchdog thread sees the new parent pid;
- when the caller's loop is left by an exception (an interrupt), the parent sends SIGTERM to
  every worker, waits at most :data:`GRACE_S` for them, kills those still there and joins
  each for a bounded time before the exception goes on. A second interrupt only skips the
  grace period.

A worker that dies (killed, out of memory) fails only the job it was running, with
:class:`WorkerDied`; a new worker takes the remaining jobs.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import wait
from typing import Any

from endeff_ros.cli_common import Terminated, interruption

#: Seconds the workers get to unwind their jobs after SIGTERM before they are killed.
GRACE_S = 3.0
#: Seconds a worker that finished its jobs gets to exit before it is terminated.
STOP_S = 2.0
#: How often (s) a worker sends its progress count to the parent, at most.
_PROGRESS_EVERY_S = 0.1

#: In a worker: its pipe to the parent, the frames reported and not yet sent, when last sent.
_CONN: Any = None
_UNSENT = 0
_SENT_AT = 0.0


class WorkerDied(RuntimeError):
    """The worker running a job ended without a result (killed, crashed, out of memory)."""


@dataclass
class Outcome:
    """What one job gave: its return value, or the exception it raised."""

    value: Any = None
    error: BaseException | None = None

    def result(self) -> Any:
        """The value, or raise the job's exception."""
        if self.error is not None:
            raise self.error
        return self.value


def report_progress(n: int = 1) -> None:
    """In a worker: count ``n`` more units of work for the parent's ``on_progress`` (sent at
    most every 0.1 s, the rest with the job's result). A no-op outside a worker."""
    global _UNSENT, _SENT_AT
    if _CONN is None:
        return
    _UNSENT += n
    now = time.monotonic()
    if now - _SENT_AT >= _PROGRESS_EVERY_S:
        _CONN.send_bytes(pickle.dumps(('progress', _UNSENT)))
        _UNSENT, _SENT_AT = 0, now


def run_jobs(fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]], workers: int, *,
             initializer: Callable[..., None] | None = None, initargs: tuple[Any, ...] = (),
             on_progress: Callable[[int], None] | None = None,
             poll_s: float = 0.2) -> list[Outcome]:
    """``fn(*job)`` for every job on ``workers`` spawned processes; the outcomes in job order.

    ``fn``, the jobs and the results must be picklable (``fn`` a module-level function).
    ``initializer(*initargs)`` runs once in each worker. ``on_progress(total)`` is called in
    the parent at least every ``poll_s`` seconds with the sum of what the workers passed to
    :func:`report_progress`. An exception in the parent (KeyboardInterrupt for Ctrl-C,
    ``Terminated`` for SIGTERM) stops every worker (module docstring) and goes on.
    """
    ctx = multiprocessing.get_context('spawn')
    queue = deque(enumerate(jobs))
    outcomes: list[Outcome | None] = [None] * len(jobs)
    live: list[_Worker] = []
    progress = 0
    try:
        for _ in range(max(1, min(workers, len(queue)))):
            live.append(_Worker.start(ctx, initializer, initargs))
        while queue or any(w.task is not None for w in live):
            for w in live:
                if w.task is None and queue:
                    w.give(fn, *queue.popleft())
            waiting = {w.conn: w for w in live}
            waiting.update({w.proc.sentinel: w for w in live})
            for ready in wait(list(waiting), timeout=poll_s):
                w = waiting[ready]
                if w not in live:
                    continue
                if ready is w.conn:
                    progress += w.receive(outcomes)
                if w.dead():
                    live.remove(w)
                    progress += w.close(outcomes)
                    if queue and len(live) < workers:  # a new worker for the jobs left
                        live.append(_Worker.start(ctx, initializer, initargs))
            if on_progress is not None:
                on_progress(progress)
    except BaseException:
        _stop(live, terminate=True)
        raise
    _stop(live, terminate=False)
    return [o if o is not None else Outcome(error=WorkerDied('job never ran'))
            for o in outcomes]


class _Worker:
    """The parent's handle of one worker: its process, its pipe and the job it runs."""

    def __init__(self, proc: Any, conn: Any) -> None:
        self.proc = proc
        self.conn = conn
        self.task: int | None = None
        self._eof = False

    @classmethod
    def start(cls, ctx: Any, initializer: Callable[..., None] | None,
              initargs: tuple[Any, ...]) -> _Worker:
        parent_conn, child_conn = ctx.Pipe()
        proc = ctx.Process(target=_worker_main, name='endeff-worker', daemon=True,
                           args=(child_conn, os.getpid(), initializer, initargs))
        # The new interpreter inherits SIGINT ignored, so a Ctrl-C to the process group while
        # it is still importing (before _worker_main ignores it) prints no traceback there.
        main_thread = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
        try:
            proc.start()
        finally:
            if previous is not None:
                signal.signal(signal.SIGINT, previous)
        child_conn.close()
        return cls(proc, parent_conn)

    def give(self, fn: Callable[..., Any], index: int, job: tuple[Any, ...]) -> None:
        """Send job ``index``; a worker that died meanwhile is noticed by :meth:`dead`."""
        self.task = index
        try:
            self.conn.send_bytes(pickle.dumps((index, fn, tuple(job))))
        except (BrokenPipeError, ConnectionResetError):
            self._eof = True

    def receive(self, outcomes: list[Outcome | None]) -> int:
        """Read one message; store a result in ``outcomes``; return the progress it adds."""
        try:
            message = pickle.loads(self.conn.recv_bytes())
        except (EOFError, OSError):
            self._eof = True
            return 0
        except Exception as err:  # noqa: BLE001 - a result that does not unpickle
            message = ('done', self.task, None, RuntimeError(
                f'the result of a worker could not be read: {type(err).__name__}: {err}'), 0)
        if message[0] == 'progress':
            return int(message[1])
        _, index, value, error, done = message
        outcomes[index] = Outcome(value, error)
        self.task = None
        return int(done)

    def dead(self) -> bool:
        return self._eof or not self.proc.is_alive()

    def close(self, outcomes: list[Outcome | None]) -> int:
        """After the worker ended (or closed its pipe): keep a result it sent before, fail the
        job it ran otherwise, release its pipe and process."""
        done = 0
        while not self._eof and self.task is not None and self.conn.poll():
            done += self.receive(outcomes)
        self.proc.join(1.0)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join(1.0)
        if self.task is not None and outcomes[self.task] is None:
            outcomes[self.task] = Outcome(error=WorkerDied(
                f'worker process {self.proc.pid} ended (exit code {self.proc.exitcode}) '
                'before finishing its job'))
        self.task = None
        self.conn.close()
        return done


def _stop(live: list[_Worker], *, terminate: bool) -> None:
    """End every worker in ``live``: asked to stop (``terminate`` False) or sent SIGTERM; killed
    if still there after the grace period; joined for a bounded time."""
    procs = [w.proc for w in live]
    try:
        for w in live:
            try:
                if terminate:
                    w.proc.terminate()
                else:
                    w.conn.send_bytes(pickle.dumps(None))
            except (OSError, ValueError):  # gone already
                pass
        deadline = time.monotonic() + (GRACE_S if terminate else STOP_S)
        while any(p.is_alive() for p in procs) and time.monotonic() < deadline:
            wait([p.sentinel for p in procs if p.is_alive()],
                 timeout=max(0.0, deadline - time.monotonic()))
        for p in procs:
            if p.is_alive():
                p.terminate()
        deadline = time.monotonic() + (0.0 if terminate else GRACE_S)
        while any(p.is_alive() for p in procs) and time.monotonic() < deadline:
            wait([p.sentinel for p in procs if p.is_alive()],
                 timeout=max(0.0, deadline - time.monotonic()))
    except KeyboardInterrupt:  # a second Ctrl-C / SIGTERM: no more grace
        pass
    finally:
        for p in procs:
            if p.is_alive():
                p.kill()
        for w in live:
            w.proc.join(1.0)
            w.conn.close()
        live.clear()


# --------------------------------------------------------------------------------------------
# In the worker
# --------------------------------------------------------------------------------------------

def _worker_main(conn: Any, parent_pid: int, initializer: Callable[..., None] | None,
                 initargs: tuple[Any, ...]) -> None:
    """A worker's loop: run the jobs the parent sends until told to stop or terminated."""
    global _CONN, _UNSENT
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        _die_with_parent(parent_pid)
        if initializer is not None:
            initializer(*initargs)
        _CONN = conn
        while True:
            try:
                task = pickle.loads(conn.recv_bytes())
            except EOFError:  # the parent is gone
                return
            if task is None:
                return
            index, fn, job = task
            try:
                reply = ('done', index, fn(*job), None)
            except Exception as err:  # noqa: BLE001 - the parent decides what a failure means
                if (stop := interruption(err)) is not None:
                    raise stop from err
                reply = ('done', index, None, _portable(err))
            done, _UNSENT = _UNSENT, 0
            try:
                data = pickle.dumps((*reply, done))
            except Exception as err:  # noqa: BLE001 - an unpicklable result
                data = pickle.dumps(('done', index, None, RuntimeError(
                    f'the result of the job cannot be sent back: {type(err).__name__}: '
                    f'{err}'), done))
            conn.send_bytes(data)
    except KeyboardInterrupt:  # SIGTERM (Terminated): the job has unwound; end quietly
        sys.exit(143)
    except (BrokenPipeError, ConnectionResetError):  # the parent is gone
        sys.exit(1)


def _on_sigterm(signum: int, frame: Any) -> None:
    """SIGTERM in a worker: unwind (Terminated), once. A second SIGTERM (sent to the process
    group and by the parent) is ignored so that it cannot break the cleanup of the first; a
    worker that does not end is killed by the parent after the grace period.

    Raised inside the import machinery (a module lock's weakref callback, run whenever the
    collector frees one), the exception would be printed with its traceback and swallowed,
    the worker going on until it is killed: the signal is sent again, to be taken once that
    code has returned."""
    if frame is not None and frame.f_code.co_filename.startswith('<frozen importlib'):
        os.kill(os.getpid(), signum)
        return
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise Terminated(signum)


def _portable(err: BaseException) -> BaseException:
    """``err`` with the worker's traceback as a note, or a RuntimeError naming it if it does
    not survive pickling (the parent must always learn why a job failed)."""
    text = ''.join(traceback.format_exception(err))
    try:
        err.add_note(f'in worker process {os.getpid()}:\n{text}')
        pickle.loads(pickle.dumps(err))
    except Exception:  # noqa: BLE001
        return RuntimeError(f'{type(err).__name__}: {err}\n{text}')
    return err


def _die_with_parent(parent_pid: int) -> None:
    """Make this worker get SIGTERM when the parent ends, even by SIGKILL: the kernel's
    parent-death signal on Linux, and a watchdog thread everywhere (for other systems and for
    a parent that died before the signal was set up)."""
    if sys.platform.startswith('linux'):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    threading.Thread(target=_watch_parent, args=(parent_pid,), name='endeff-parent-watch',
                     daemon=True).start()


def _watch_parent(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(0.5)
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(GRACE_S)
    os._exit(143)
