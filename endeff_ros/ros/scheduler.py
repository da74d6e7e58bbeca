"""The node's scheduling, without ROS: which input set to process, and what to do early.

``endeff_node`` receives colour, depth and camera-info messages on DDS threads and runs the
tracker on one worker thread. Everything between the two is decided here, so that it can be
tested by feeding stamped messages (as the synchroniser is), with no DDS:

- **Newest set wins.** Inputs are synchronised by stamp (:mod:`endeff_ros.sync`); a complete set
  goes into a one-item slot (:class:`~endeff_ros.ros.processing.LatestSlot`) and a set the worker
  was too slow for is skipped and counted, never queued, so latency cannot grow.
- **Early work.** While a depth image waits for its colour partner, the worker may already run
  Sections 3-4 on it (``prepare`` jobs: they need no colour); while a colour image waits for its
  depth partner, it may compute the optical flow (``prepare_flow`` jobs: they need no depth).
  A result made early (:class:`Early`) serves only the set it was made for, with the parameters
  it was made with, and only if the tracker did not change in between.
- **Every depth image answered.** A depth image still without colour after ``color_timeout``
  is handed on alone (as the offline bag reader does); once ``COLOR_LAG_MIN`` colour images
  have paired, after the largest of the recent colour lags (how long after its depth image a
  colour image arrived, 0 if first) plus ``COLOR_LAG_MARGIN_S`` if that is shorter, so that a
  lost colour image costs about the camera's colour lag rather than the timeout. A colour
  image arriving after its depth image was handed on is dropped with a warning, but its lag
  counts, so that the wait grows when the colour lag does (else every later colour image would
  miss the wait that never grows). Sooner still when its colour is known to be
  lost: a newer colour image has arrived (colour stamps only grow, so it can no longer pair),
  or the colour stream has stopped (``COLOR_STOPPED_FRAMES`` depth images in a row without
  any colour), so that with no colour at all no frame waits. Such a set goes into a slot of
  its own that the worker serves before the newest complete set, so that neither replaces
  the other. Every depth image waiting at that moment is handed on, oldest first: when colour
  stops, the images that waited to see whether it would come are answered too (at most
  ``COLOR_STOPPED_FRAMES`` such sets wait behind the slot's, so that work stays bounded); a
  depth image arriving once colour has stopped is an ordinary set (newest wins), as without
  a colour input.
- **Order and resets.** A set whose depth is not newer than one already handed on is a
  duplicate. Stamps going back by more than the jump threshold (a bag replayed in a loop), or
  the ROS clock jumping back, reset the tracker and the synchroniser. A single stamp more
  than the threshold *ahead* of the stream is quarantined (dropped with a warning) unless the
  next one confirms the jump, so that one bad stamp cannot reset the tracks. Messages older
  than the last set handed on are dropped by the synchroniser, with a warning.

Messages are opaque here: the caller passes ``stamp_of(msg) -> int`` (ns). Thread safety: every
public method may be called from any thread; the worker calls :meth:`next_job`.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from endeff_ros.core.params import EndeffParams
from endeff_ros.ros.processing import LatestSlot, NodeStats, take_first
from endeff_ros.sync import ApproximateTimeSynchronizer

#: Seconds without camera info while depth images arrive before the node warns.
CAMERA_INFO_GRACE_S = 0.5

#: Depth images in a row without any colour image after which colour counts as stopped.
COLOR_STOPPED_FRAMES = 3

#: Colour lags (receipt of a colour image minus that of its depth image, 0 if the colour came
#: first) kept, and how many are needed before they set the wait for colour: a window of about
#: a second at 30 Hz, so that the wait follows a changing lag but one lag sets it for a while.
COLOR_LAG_WINDOW, COLOR_LAG_MIN = 30, 10
#: Margin over the largest recent colour lag after which a colour image counts as lost, s:
#: receipt jitter of a colour image on time stays below it on a loaded machine.
COLOR_LAG_MARGIN_S = 0.004

_COLORLESS_WHY = {
    'lost': 'a colour image was lost: its depth image is processed without colour',
    'late': 'a colour image did not arrive within the wait for colour (color_timeout, or the '
            'recent colour lag): its depth image is processed without colour',
    'stopped': 'no colour images are arriving: depth images are processed without colour',
}

#: Job names of the scheduler's slots (:meth:`Scheduler.next_job`), in the order the worker
#: prefers them: sets whose colour was lost (older), the newest complete set, early work.
JOBS = ('process', 'process', 'prepare', 'prepare_flow')


@dataclasses.dataclass(frozen=True)
class Early:
    """A result computed while its set was incomplete: Sections 3-4 of the depth image
    (``data``: the frame without colour) or the flow to the colour image (``data``: the RGB
    array); with the parameters it used and the milliseconds it took."""

    stamp_ns: int
    data: Any
    result: Any
    params: EndeffParams
    ms: float
    updates: int = 0  # tracker updates done before it was computed (flow: must be current)


class Scheduler:
    """Synchronises the node's inputs and decides the worker's next job (module docstring).

    ``use_color``: synchronise colour too (else depth and camera info only). ``queue_size`` and
    ``slop_ns``: the synchroniser's. ``color_timeout_s``: how long a depth image waits for its
    colour. ``jump_threshold_ns``: stamps going back by more reset. ``stats``: the node's
    counters (``received``, ``duplicates``, ``colorless``, warnings). ``on_event(text)``:
    informational messages; ``on_warning(kind, text)``: problems with the input (the node logs
    them, rate-limited per kind). ``clock()``: the clock of the receipts, monotonic s (the
    worker's wait in :meth:`next_job` ends when a waiting depth image is due).
    """

    def __init__(self, *, use_color: bool, queue_size: int, slop_ns: int,
                 color_timeout_s: float, jump_threshold_ns: int,
                 stamp_of: Callable[[Any], int], stats: NodeStats | None = None,
                 on_event: Callable[[str], None] | None = None,
                 on_warning: Callable[[str, str], None] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.inputs = ['color', 'depth', 'camera_info'] if use_color else ['depth',
                                                                            'camera_info']
        self.stats = stats or NodeStats()
        self.color_timeout_s = float(color_timeout_s)
        self.jump_threshold_ns = int(jump_threshold_ns)
        self._stamp_of = stamp_of
        self._on_event = on_event or (lambda text: None)
        self._on_warning = on_warning or (lambda kind, text: None)
        self._clock = clock
        self._lock = threading.Lock()
        self._slot: LatestSlot[tuple[dict[str, Any], float]] = LatestSlot()
        # Sets whose colour image is known to be lost (served before the newest set).
        self._lost: LatestSlot[tuple[dict[str, Any], float]] = self._slot.companion()
        # Such sets queued behind the one in the lost slot (oldest first), and the set last
        # put in the slot (None once the worker took it): the slot holds one at a time.
        self._lost_backlog: deque[tuple[dict[str, Any], float]] = deque()
        self._lost_item: tuple[dict[str, Any], float] | None = None
        self._lost_replaced = 0
        # Depth images (with the camera info) waiting for the early Sections 3-4, colour images
        # waiting for the early flow; the last early result of each.
        self._early: LatestSlot[tuple[Any, Any]] = self._slot.companion()
        self._early_color: LatestSlot[tuple[Any, Any]] = self._slot.companion()
        self._prepared: Early | None = None
        self._prepared_flow: Early | None = None
        # Depth stamp whose early Sections 3-4 the worker is running (None: not running).
        self._estimating_ns: int | None = None
        self._last_info: Any = None
        self._first_unpaired_depth: float | None = None
        self._newest_ns: int | None = None
        # Quarantined stamps far ahead of the stream, per input: a jump is followed when the
        # next image of the same input confirms it (one bad frame stamps colour and depth).
        self._ahead: dict[str, int] = {}
        self._depth_since_color = 0  # depth images received since the last colour image
        self._color_lags: deque[float] = deque(maxlen=COLOR_LAG_WINDOW)  # s, newest last
        # Receipts of the recent depth images no colour image has come for yet (stamp ->
        # receipt, oldest first), also once handed on: a late colour image's lag counts.
        self._depth_receipts: dict[int, float] = {}
        self._reset_pending = False
        self._params_pending: EndeffParams | None = None
        self._waiting: dict[int, tuple[Any, float]] = {}  # depth stamp -> (msg, receipt)
        self._floor_ns: int | None = None  # newest depth stamp handed to the worker
        self._dropped_before = {k: 0 for k in self.inputs}
        self._queue_size, self._slop_ns = int(queue_size), int(slop_ns)
        self._sync = self._make_sync()

    # ------------------------------------------------------------------ synchroniser
    def _make_sync(self) -> ApproximateTimeSynchronizer:
        sync = ApproximateTimeSynchronizer(len(self.inputs), self._queue_size, self._slop_ns,
                                           latched=(self.inputs.index('camera_info'),),
                                           on_drop=self._on_sync_drop)
        if self._last_info is not None:
            sync.add(self.inputs.index('camera_info'), 0, self._last_info)
        return sync

    def _replace_sync(self) -> None:
        """New synchroniser (lock held); keeps the drop counts and the camera info."""
        for i, kind in enumerate(self.inputs):
            self._dropped_before[kind] += self._sync.stats.dropped[i]
        self._sync = self._make_sync()

    def _on_sync_drop(self, index: int, stamp_ns: int, msg: Any, reason: str) -> None:
        """A message the synchroniser dropped (lock held): late ones are worth a warning (the
        others are the normal unpaired leftovers, counted in ``dropped``)."""
        if reason == 'late':
            kind = self.inputs[index]
            self._on_warning('late_input', f'{kind} image stamped {stamp_ns / 1e9:.3f} s is not '
                             f'newer than the last set handed on: dropped')

    def resync(self, queue_size: int, slop_ns: int) -> None:
        """Use a synchroniser with a new queue size and slop (pending messages are dropped)."""
        with self._lock:
            self._queue_size, self._slop_ns = int(queue_size), int(slop_ns)
            self._replace_sync()

    @property
    def slop_ns(self) -> int:
        """The synchroniser's largest stamp difference within a set, ns."""
        return self._slop_ns

    def dropped(self) -> dict[str, int]:
        """Messages the synchroniser dropped unpaired, per input."""
        with self._lock:
            return {k: self._dropped_before[k] + self._sync.stats.dropped[i]
                    for i, k in enumerate(self.inputs)}

    @property
    def skipped(self) -> int:
        """Sets replaced in their slot before the worker took them."""
        return self._slot.skipped + self._lost.skipped + self._lost_replaced

    @property
    def sets(self) -> int:
        """Sets handed to the worker."""
        return self._slot.put_count + self._lost.put_count

    # ------------------------------------------------------------------ inputs
    def on_input(self, kind: str, msg: Any, receipt: float, *, flow_done: bool = False) -> None:
        """Take one message of input ``kind`` received at ``receipt`` (monotonic s).
        ``flow_done``: a colour image whose flow the caller already computed (no early flow)."""
        stamp = self._stamp_of(msg)
        with self._lock:
            self.stats.received[kind] += 1
            if kind == 'camera_info':
                self._last_info = msg
                self._first_unpaired_depth = None
            elif not self._check_stamp(kind, stamp):
                return
            if kind == 'depth' and self._first_unpaired_depth is None:
                self._first_unpaired_depth = receipt
            alone = []  # a depth image that is a set by itself (colour has stopped)
            too_late = kind == 'color' and self._note_color(stamp, receipt)
            if kind == 'color':
                self._depth_since_color = 0
                # Depth images that can no longer pair with any colour image lost theirs.
                self._queue_lost(self._hand_on_colorless(
                    [s for s in self._waiting if s < stamp - self._slop_ns], 'lost'))
            if kind == 'depth' and 'color' in self.inputs:
                self._depth_since_color += 1
                self._waiting[stamp] = (msg, receipt)
                if self._depth_since_color > COLOR_STOPPED_FRAMES:
                    # Those that waited to see whether colour would come are answered first;
                    # this one, which did not wait, is an ordinary set (newest wins).
                    batch = self._hand_on_colorless([s for s in self._waiting if s <= stamp],
                                                    'stopped')
                    alone = [m for m, _ in batch[-1:] if self._stamp_of(m['depth']) == stamp]
                    self._queue_lost(batch[:len(batch) - len(alone)])
                elif self._last_info is not None:
                    self._early.put((msg, self._last_info))
            found_sets = self._sync.add(self.inputs.index(kind), stamp, msg)
            if kind == 'depth' and 'color' in self.inputs:
                depth_at = self.inputs.index('depth')
                self._note_depth(stamp, receipt,
                                 paired=any(found[depth_at] is msg for found in found_sets))
            ready = alone + [self._claim(dict(zip(self.inputs, found))) for found in found_sets]
            if (kind == 'color' and not ready and not too_late and not flow_done
                    and self._last_info is not None):
                self._early_color.put((msg, self._last_info))
        for msgs in ready:
            if msgs is not None:
                self._slot.put((msgs, receipt))

    def _check_stamp(self, kind: str, stamp: int) -> bool:
        """Follow the stream's newest stamp (lock held): a jump back resets; a single stamp
        far ahead is quarantined (False: drop the message) until a second one confirms it."""
        newest, limit = self._newest_ns, self.jump_threshold_ns
        if newest is not None and stamp < newest - limit:
            self._on_event(f'input stamps jumped back by {(newest - stamp) / 1e9:.3f} s: '
                           f'resetting')
            self._request_reset()
            self._newest_ns = stamp
            self._ahead.clear()
            return True
        if newest is not None and stamp > newest + limit:
            seen = self._ahead.get(kind)
            if seen is None or not seen < stamp <= seen + limit:
                self._ahead[kind] = stamp
                self.stats.quarantined += 1
                self._on_warning('stamp_ahead', f'{kind} image stamped {stamp / 1e9:.3f} s, '
                                 f'{(stamp - newest) / 1e9:.3f} s ahead of the stream: '
                                 f'ignored unless the next stamps follow it')
                return False
            self._on_event(f'input stamps jumped ahead by {(stamp - newest) / 1e9:.3f} s')
        self._ahead.clear()
        self._newest_ns = max(stamp, newest or stamp)
        return True

    def _note_depth(self, stamp: int, receipt: float, *, paired: bool) -> None:
        """A depth image arrived (lock held): paired at once, its colour came first (lag 0);
        else its receipt is kept for its colour image's lag (:meth:`_note_color`)."""
        if paired:
            self._color_lags.append(0.0)
            return
        self._depth_receipts[stamp] = receipt
        while len(self._depth_receipts) > COLOR_LAG_WINDOW:
            del self._depth_receipts[next(iter(self._depth_receipts))]

    def _note_color(self, stamp: int, receipt: float) -> bool:
        """Count a colour image's lag behind its depth partner (lock held): the recent depth
        image nearest in stamp, within the slop, that no colour image came for yet (none: the
        colour came first, counted when its depth pairs). True, with a warning, if that depth
        image was already handed on without colour: this one is too late and is dropped; its
        lag still counts, so that the wait for colour grows to a growing lag."""
        near = [s for s in self._depth_receipts if abs(s - stamp) <= self._slop_ns]
        if not near:
            return False
        partner = min(near, key=lambda s: abs(s - stamp))
        lag = max(0.0, receipt - self._depth_receipts.pop(partner))
        self._color_lags.append(lag)
        late = (partner not in self._waiting and self._floor_ns is not None
                and partner <= self._floor_ns)
        if late:
            self._on_warning('color_too_late', f'colour image stamped {stamp / 1e9:.3f} s '
                             f'arrived {lag * 1e3:.1f} ms after its depth image, which was '
                             f'processed without it: dropped (the wait for colour grows)')
        return late

    def color_wait_s(self) -> float:
        """How long a depth image waits for its colour, s: ``color_timeout_s``, or once
        ``COLOR_LAG_MIN`` lags are known, the largest recent one plus ``COLOR_LAG_MARGIN_S`` if
        shorter (a colour image later than every recent one is taken as lost, so that a lost
        one costs about the colour lag instead of a frame period or the timeout)."""
        with self._lock:
            return self._color_wait_s()

    def _color_wait_s(self) -> float:
        """:meth:`color_wait_s` (lock held)."""
        lags = self._color_lags
        if len(lags) < COLOR_LAG_MIN:
            return self.color_timeout_s
        return min(self.color_timeout_s, max(lags) + COLOR_LAG_MARGIN_S)

    def color_due_in(self, now: float) -> float | None:
        """Seconds from ``now`` until the longest-waiting depth image is handed on without
        colour by :meth:`flush_colorless` (negative: overdue); None if none waits or no camera
        info has come (then none can be handed on)."""
        with self._lock:
            first = min((t for _, t in self._waiting.values()), default=None)
            if first is None or self._last_info is None:
                return None
            return first + self._color_wait_s() - now

    def _hand_on_colorless(self, stamps: list[int], why: str
                           ) -> list[tuple[dict[str, Any], float]]:
        """The sets of these waiting depth images without colour, oldest first, with their
        receipts (lock held); none before the camera info has come."""
        if not stamps or self._last_info is None:
            return []
        batch = []
        for stamp in sorted(stamps):
            msg, receipt = self._waiting[stamp]
            msgs = self._claim({'color': None, 'depth': msg, 'camera_info': self._last_info})
            if msgs is not None:
                batch.append((msgs, receipt))
        if batch:
            self.stats.colorless += len(batch)
            self._on_warning(f'color_{why}', _COLORLESS_WHY[why])
        return batch

    def _queue_lost(self, batch: list[tuple[dict[str, Any], float]]) -> None:
        """Queue sets whose colour is lost behind those already queued (lock held); the
        queue holds at most ``COLOR_STOPPED_FRAMES`` sets besides the one in the slot (the
        oldest beyond are skipped), so that its work stays bounded."""
        self._lost_backlog.extend(batch)
        while len(self._lost_backlog) > COLOR_STOPPED_FRAMES:
            self._lost_backlog.popleft()
            self._lost_replaced += 1
        self._feed_lost()

    def _feed_lost(self) -> None:
        """The next queued set into the lost slot, once the worker took the previous one
        (lock held)."""
        if self._lost_item is None and self._lost_backlog:
            self._lost_item = self._lost_backlog.popleft()
            self._lost.put(self._lost_item)

    def _claim(self, msgs: dict[str, Any]) -> dict[str, Any] | None:
        """Accept a set unless its depth is not newer than one already handed on (lock held)."""
        stamp = self._stamp_of(msgs['depth'])
        for old in [s for s in self._waiting if s <= stamp]:
            del self._waiting[old]
        if self._floor_ns is not None and stamp <= self._floor_ns:
            self.stats.duplicates += 1
            return None
        self._floor_ns = stamp
        return msgs

    def flush_colorless(self, now: float) -> None:
        """Hand on the depth images that waited :meth:`color_wait_s` for their colour."""
        with self._lock:
            wait = self._color_wait_s()
            self._queue_lost(self._hand_on_colorless(
                [s for s, (_, t) in self._waiting.items() if now - t > wait], 'late'))

    def missing_camera_info(self, now: float) -> bool:
        """Depth images have waited more than ``CAMERA_INFO_GRACE_S`` with no camera info."""
        first = self._first_unpaired_depth
        return self._last_info is None and first is not None and (
            now - first > CAMERA_INFO_GRACE_S)

    # ------------------------------------------------------------------ resets, parameters
    def _request_reset(self) -> None:
        """Forget the tracks and the synchroniser state (lock held)."""
        self._reset_pending = True
        self._waiting.clear()
        self._depth_receipts.clear()
        self._floor_ns = None
        self._replace_sync()
        self._slot.clear()
        self._lost.clear()
        self._lost_backlog.clear()
        self._lost_item = None

    def request_reset(self) -> None:
        """Reset the tracker before the next set, and forget the pending inputs."""
        with self._lock:
            self._request_reset()

    def change_params(self, params: EndeffParams) -> None:
        """The tracker takes ``params`` before the next set; early work waits until then."""
        with self._lock:
            self._params_pending = params

    def begin_set(self) -> tuple[EndeffParams | None, bool]:
        """What the worker applies before processing a set: (new parameters or None, whether
        to reset the tracker). Each is returned once; early results are forgotten on reset."""
        with self._lock:
            params, self._params_pending = self._params_pending, None
            reset, self._reset_pending = self._reset_pending, False
            if reset:
                self._prepared = self._prepared_flow = None
            return params, reset

    # ------------------------------------------------------------------ the worker's jobs
    def next_job(self, timeout: float) -> tuple[str, tuple[Any, ...]] | None:
        """``(job, args)``: ``('process', (msgs, receipt))``, ``('prepare', (depth, info))``
        or ``('prepare_flow', (color, info))``, preferring complete sets; None after
        ``timeout`` s without any, or once closed; sooner (0.5 ms after) when a waiting depth
        image is due to be handed on without colour, so that the caller's
        :meth:`flush_colorless` runs on time rather than after its polling period."""
        due = self.color_due_in(self._clock())
        if due is not None:
            timeout = min(timeout, max(0.0, due + 0.0005))
        got = take_first([self._lost, self._slot, self._early, self._early_color],
                         timeout=timeout)
        if got is not None and got[0] == 0:
            with self._lock:
                if got[1] is self._lost_item:
                    self._lost_item = None
                self._feed_lost()
        return None if got is None else (JOBS[got[0]], got[1])

    def begin_estimate(self, depth: Any) -> bool:
        """May the worker run the early Sections 3-4 of ``depth`` now? (Not while parameters
        or a reset are pending, nor for a depth image older than one already handed on.)"""
        stamp = self._stamp_of(depth)
        with self._lock:
            if (self._params_pending is not None or self._reset_pending
                    or (self._floor_ns is not None and stamp <= self._floor_ns)):
                return False
            self._estimating_ns = stamp
            return True

    def end_estimate(self, early: Early | None) -> None:
        """The early Sections 3-4 finished (``early``: its result, None if unusable)."""
        with self._lock:
            self._estimating_ns = None
        if early is not None:
            self._prepared = early

    def may_flow(self) -> bool:
        """May an early optical flow run now (no parameters or reset pending)?"""
        with self._lock:
            return self._params_pending is None and not self._reset_pending

    def flow_alongside_info(self, stamp_ns: int) -> Any:
        """The camera info if the worker is estimating the depth partner of a colour image
        stamped ``stamp_ns`` (so its flow can run alongside, on another core), else None."""
        with self._lock:
            estimating, info = self._estimating_ns, self._last_info
            if estimating is None or info is None or abs(stamp_ns - estimating) > self._slop_ns:
                return None
            return info

    def store_flow(self, early: Early) -> None:
        """An early optical flow result, for the set of its colour image."""
        self._prepared_flow = early

    def take_early(self, msgs: dict[str, Any], params: EndeffParams,
                   updates: int) -> tuple[Early | None, Early | None]:
        """The early estimate and flow made for exactly this set, with ``params``, and (flow)
        with the tracker as it is after ``updates`` updates; both slots are emptied, since an
        early result serves only the next set processed."""
        early, self._prepared = self._prepared, None
        flow, self._prepared_flow = self._prepared_flow, None
        early = early if early and self._fits(early, msgs['depth'], params) else None
        flow = flow if (flow and self._fits(flow, msgs.get('color'), params)
                        and flow.updates == updates) else None
        return early, flow

    def _fits(self, early: Early, msg: Any, params: EndeffParams) -> bool:
        """Made for this image, with these parameters."""
        return msg is not None and early.params is params and early.stamp_ns == self._stamp_of(
            msg)

    # ------------------------------------------------------------------ shutdown
    def close(self) -> None:
        """Wake and stop the worker."""
        for slot in (self._lost, self._slot, self._early, self._early_color):
            slot.close()

    @property
    def closed(self) -> bool:
        return self._slot.closed
