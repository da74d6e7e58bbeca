"""Approximate-time synchronisation of stamped messages, without ROS.

``message_filters`` is not on PyPI, so the node and the offline bag tools share this one
implementation. The API is shaped like ``message_filters.ApproximateTimeSynchronizer``:
``ApproximateTimeSynchronizer(n_inputs, queue_size, slop)`` with a callback receiving one
message per input. Stamps are integers in nanoseconds.

Policy: whenever a message arrives, the synchroniser looks for the set (one message per input,
each from its queue) with the smallest stamp spread that contains no message older than any
already emitted set and whose spread is within ``slop``. To keep latency bounded it emits as soon
as every input has a message that pairs within ``slop`` with the *oldest* pivot candidate, and
it drops messages that can no longer pair (older than the last emitted set or pushed out of a
full queue). Every dropped message is counted per input and, when ``on_drop`` is given, handed
to it with the reason (one of :data:`DROP_REASONS`), so that a caller who must account for every
message (the bag reader yields depth images without a colour partner) learns exactly which
messages left the queues unpaired instead of inferring it from counters.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

#: Why a message left the synchroniser without being part of an emitted set.
LATE = 'late'            # not newer than the newest message of the last emitted set
OVERFLOW = 'overflow'    # pushed out of a full queue
UNPAIRED = 'unpaired'    # the oldest head, and every other input's messages are beyond slop
SKIPPED = 'skipped'      # older than the message chosen from its input for an emitted set
FLUSHED = 'flushed'      # still queued when :meth:`ApproximateTimeSynchronizer.flush` ran
DROP_REASONS = (LATE, OVERFLOW, UNPAIRED, SKIPPED, FLUSHED)


@dataclass
class SyncStats:
    """Counters of a synchroniser: emitted sets and messages dropped unpaired, per input."""

    emitted: int = 0
    dropped: list[int] = field(default_factory=list)


class ApproximateTimeSynchronizer:
    """Group messages of ``n_inputs`` streams whose stamps lie within ``slop_ns`` of each other.

    Inputs that are optional for a set (e.g. camera info, which may arrive less often) are
    named in ``latched``: the newest message seen on such an input is reused for every set and
    never counted as dropped. ``on_drop(index, stamp_ns, msg, reason)`` is called for every
    message of a non-latched input that is dropped, at the moment it is dropped.
    """

    def __init__(self, n_inputs: int, queue_size: int, slop_ns: int,
                 callback: Callable[..., Any] | None = None, *,
                 latched: tuple[int, ...] = (),
                 on_drop: Callable[[int, int, Any, str], Any] | None = None) -> None:
        if n_inputs < 1 or queue_size < 1 or slop_ns < 0:
            msg = (f'synchroniser needs n_inputs >= 1, queue_size >= 1, slop >= 0 '
                   f'(got {n_inputs}, {queue_size}, {slop_ns})')
            raise ValueError(msg)
        bad = [i for i in latched if not 0 <= i < n_inputs]
        if bad:
            msg = f'latched input(s) {bad} out of range for {n_inputs} inputs'
            raise ValueError(msg)
        if len(set(latched)) >= n_inputs:
            msg = 'synchroniser needs at least one input that is not latched'
            raise ValueError(msg)
        self.n_inputs = n_inputs
        self.queue_size = queue_size
        self.slop_ns = slop_ns
        self.callback = callback
        self.on_drop = on_drop
        self.latched = frozenset(latched)
        self._queues: list[deque[tuple[int, Any]]] = [deque() for _ in range(n_inputs)]
        self._latest: dict[int, Any] = {}
        self._last_emitted_ns: int | None = None
        self.stats = SyncStats(dropped=[0] * n_inputs)

    def add(self, index: int, stamp_ns: int, msg: Any) -> list[tuple[Any, ...]]:
        """Feed one message of input ``index``; returns (and calls back with) completed sets."""
        if not 0 <= index < self.n_inputs:
            msg = f'input index {index} out of range for {self.n_inputs} inputs'
            raise IndexError(msg)
        if index in self.latched:
            self._latest[index] = msg
            return self._drain()
        queue = self._queues[index]
        if self._last_emitted_ns is not None and stamp_ns <= self._last_emitted_ns:
            self._drop(index, (stamp_ns, msg), LATE)
            return []
        queue.append((stamp_ns, msg))
        if len(queue) > 1 and queue[-2][0] > stamp_ns:
            items = sorted(queue, key=lambda item: item[0])
            queue.clear()
            queue.extend(items)
        while len(queue) > self.queue_size:
            self._drop(index, queue.popleft(), OVERFLOW)
        return self._drain()

    def flush(self) -> None:
        """Drop every queued message (reason ``flushed``), oldest first, e.g. at end of input."""
        for index, queue in enumerate(self._queues):
            while queue:
                self._drop(index, queue.popleft(), FLUSHED)

    def _drop(self, index: int, item: tuple[int, Any], reason: str) -> None:
        self.stats.dropped[index] += 1
        if self.on_drop is not None:
            self.on_drop(index, item[0], item[1], reason)

    def _drain(self) -> list[tuple[Any, ...]]:
        out = []
        while True:
            found = self._match()
            if found is None:
                break
            out.append(found)
            if self.callback is not None:
                self.callback(*found)
        return out

    def _match(self) -> tuple[Any, ...] | None:
        streams = [i for i in range(self.n_inputs) if i not in self.latched]
        if any(i not in self._latest for i in self.latched):
            return None
        chosen: dict[int, tuple[int, Any]] | None = None
        while chosen is None:
            if any(not self._queues[i] for i in streams):
                return None
            # Pivot: the oldest head among the streams. Drop heads that cannot pair with any
            # message of another stream because that stream's messages are all too new.
            # (A loop, not recursion: a long backlog must not hit the recursion limit.)
            pivot_stream = min(streams, key=lambda i: self._queues[i][0][0])
            pivot_ns = self._queues[pivot_stream][0][0]
            chosen = {pivot_stream: self._queues[pivot_stream][0]}
            for i in streams:
                if i == pivot_stream:
                    continue
                best = min(self._queues[i], key=lambda item: abs(item[0] - pivot_ns))
                if abs(best[0] - pivot_ns) > self.slop_ns:
                    if all(item[0] > pivot_ns + self.slop_ns for item in self._queues[i]):
                        # Nothing on input i will ever pair with the pivot: drop it.
                        self._drop(pivot_stream, self._queues[pivot_stream].popleft(),
                                   UNPAIRED)
                        chosen = None
                        break
                    return None
                chosen[i] = best
        # Emit: remove the chosen messages and everything older on each stream.
        newest = max(item[0] for item in chosen.values())
        for i, item in chosen.items():
            queue = self._queues[i]
            while queue and queue[0] is not item:
                self._drop(i, queue.popleft(), SKIPPED)
            queue.popleft()
        self._last_emitted_ns = newest
        for i in streams:
            queue = self._queues[i]
            while queue and queue[0][0] <= newest:
                self._drop(i, queue.popleft(), LATE)
        self.stats.emitted += 1
        return tuple(chosen[i][1] if i in chosen else self._latest[i]
                     for i in range(self.n_inputs))
