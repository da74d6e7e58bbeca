"""The node's scheduling without DDS: stamped messages in, the worker's jobs out."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import pytest

from endeff_ros.core.params import EndeffParams
from endeff_ros.ros.scheduler import (
    CAMERA_INFO_GRACE_S,
    COLOR_LAG_MARGIN_S,
    COLOR_LAG_MIN,
    COLOR_STOPPED_FRAMES,
    Early,
    Scheduler,
)

MS = 1_000_000


@dataclass(frozen=True)
class Msg:
    kind: str
    stamp: int


def make(**kw: object) -> Scheduler:
    args = {'use_color': True, 'queue_size': 10, 'slop_ns': 15 * MS, 'color_timeout_s': 0.1,
            'jump_threshold_ns': 1000 * MS, 'stamp_of': lambda m: m.stamp}
    args.update(kw)
    return Scheduler(**args)  # type: ignore[arg-type]


def feed(s: Scheduler, kind: str, stamp_ms: float, receipt: float = 0.0, **kw: bool) -> Msg:
    msg = Msg(kind, round(stamp_ms * MS))
    s.on_input(kind, msg, receipt, **kw)
    return msg


def drain(s: Scheduler) -> list[tuple[str, tuple]]:
    jobs = []
    while (job := s.next_job(timeout=0.0)) is not None:
        jobs.append(job)
    return jobs


def test_a_complete_set_is_processed() -> None:
    s = make()
    info = feed(s, 'camera_info', 0)
    color = feed(s, 'color', 100)
    depth = feed(s, 'depth', 102)
    jobs = drain(s)
    assert jobs[0][0] == 'process'
    msgs, _ = jobs[0][1]
    assert msgs == {'color': color, 'depth': depth, 'camera_info': info}
    assert s.stats.received == {'color': 1, 'depth': 1, 'camera_info': 1}


def test_early_work_while_a_partner_is_awaited() -> None:
    s = make()
    info = feed(s, 'camera_info', 0)
    depth = feed(s, 'depth', 100)
    assert drain(s) == [('prepare', (depth, info))]  # Sections 3-4 need no colour
    color = feed(s, 'color', 101)
    assert [j for j, _ in drain(s)] == ['process']
    color = feed(s, 'color', 133)
    assert drain(s) == [('prepare_flow', (color, info))]  # the flow needs no depth
    # A colour image whose flow the caller computed alongside gets no early-flow job.
    feed(s, 'color', 166, flow_done=True)
    assert drain(s) == []


def test_the_newest_set_wins_and_skips_are_counted() -> None:
    s = make()
    feed(s, 'camera_info', 0)
    for k in range(3):
        feed(s, 'color', 100 + 33 * k)
        feed(s, 'depth', 101 + 33 * k)
    process = [args for job, args in drain(s) if job == 'process']
    assert len(process) == 1
    assert process[0][0]['depth'].stamp == 167 * MS
    assert s.skipped == 2 and s.sets == 3


def test_depth_without_colour_is_processed_after_the_timeout() -> None:
    s = make(color_timeout_s=0.1)
    feed(s, 'camera_info', 0)
    depth = feed(s, 'depth', 100, receipt=10.0)
    drain(s)
    s.flush_colorless(10.05)
    assert drain(s) == []
    s.flush_colorless(10.2)
    (job, (msgs, receipt)), = drain(s)
    assert job == 'process' and msgs['color'] is None and msgs['depth'] is depth
    assert receipt == 10.0 and s.stats.colorless == 1
    # Its colour arriving late makes no second set of the same depth image.
    feed(s, 'color', 101)
    assert [j for j, _ in drain(s) if j == 'process'] == []


def test_without_colour_depth_and_info_make_a_set() -> None:
    s = make(use_color=False)
    assert s.inputs == ['depth', 'camera_info']
    feed(s, 'camera_info', 0)
    depth = feed(s, 'depth', 100)
    (job, (msgs, _)), = drain(s)
    assert job == 'process' and msgs['depth'] is depth


def test_stamps_jumping_back_reset_once() -> None:
    events: list[str] = []
    s = make(jump_threshold_ns=1000 * MS, on_event=events.append)
    feed(s, 'camera_info', 0)
    feed(s, 'color', 5000)
    feed(s, 'depth', 5000)
    drain(s)
    assert s.begin_set() == (None, False)
    feed(s, 'color', 4500)  # back by less than the threshold: no reset
    assert s.begin_set() == (None, False)
    feed(s, 'color', 100)
    feed(s, 'depth', 100)
    assert events and 'jumped back' in events[0]
    assert s.begin_set() == (None, True)
    assert s.begin_set() == (None, False)
    # After the reset the older stamps form sets again.
    assert any(j == 'process' for j, _ in drain(s))


def test_a_set_not_newer_than_the_last_is_a_duplicate() -> None:
    s2 = make()
    feed(s2, 'camera_info', 0)
    feed(s2, 'depth', 300, receipt=1.0)
    s2.flush_colorless(2.0)  # handed on without colour
    feed(s2, 'depth', 300, receipt=2.0)
    feed(s2, 'color', 300)  # the same depth stamp again, now with colour
    assert s2.stats.duplicates == 1


def test_parameters_change_before_the_next_set_and_hold_early_work() -> None:
    s = make()
    feed(s, 'camera_info', 0)
    depth = feed(s, 'depth', 100)
    new = EndeffParams()
    s.change_params(new)
    assert not s.begin_estimate(depth) and not s.may_flow()
    assert s.begin_set() == (new, False)
    assert s.begin_estimate(depth) and s.may_flow()


def test_early_results_serve_only_their_own_set() -> None:
    s = make()
    params = EndeffParams()
    info = feed(s, 'camera_info', 0)
    depth = feed(s, 'depth', 100)
    assert s.begin_estimate(depth)
    s.end_estimate(Early(depth.stamp, 'frame', 'estimate', params, 1.0))
    color = feed(s, 'color', 101)
    s.store_flow(Early(color.stamp, 'rgb', 'flow', params, 1.0, updates=3))
    msgs = {'color': color, 'depth': depth, 'camera_info': info}
    early, flow = s.take_early(msgs, params, updates=3)
    assert early.result == 'estimate' and flow.result == 'flow'
    assert s.take_early(msgs, params, updates=3) == (None, None)  # used once
    # Another set, other parameters or a tracker updated since: not used.
    s.end_estimate(Early(depth.stamp, 'frame', 'estimate', params, 1.0))
    s.store_flow(Early(color.stamp, 'rgb', 'flow', params, 1.0, updates=3))
    early, flow = s.take_early(msgs, params, updates=4)
    assert early.result == 'estimate' and flow is None  # the tracker changed since the flow
    s.end_estimate(Early(depth.stamp, 'frame', 'estimate', params, 1.0))
    assert s.take_early(msgs, EndeffParams(), updates=3) == (None, None)
    other = {'color': color, 'depth': Msg('depth', 133 * MS), 'camera_info': info}
    s.end_estimate(Early(depth.stamp, 'frame', 'estimate', params, 1.0))
    assert s.take_early(other, params, updates=3)[0] is None


def test_the_flow_runs_alongside_only_while_its_depth_partner_is_estimated() -> None:
    s = make(slop_ns=15 * MS)
    info = feed(s, 'camera_info', 0)
    depth = feed(s, 'depth', 100)
    assert s.flow_alongside_info(101 * MS) is None
    assert s.begin_estimate(depth)
    assert s.flow_alongside_info(101 * MS) is info
    assert s.flow_alongside_info(130 * MS) is None  # outside the slop: not its partner
    s.end_estimate(None)
    assert s.flow_alongside_info(101 * MS) is None


def test_missing_camera_info_is_noticed_after_a_grace_period() -> None:
    s = make()
    feed(s, 'depth', 100, receipt=5.0)
    assert not s.missing_camera_info(5.0 + CAMERA_INFO_GRACE_S / 2)
    assert s.missing_camera_info(5.0 + CAMERA_INFO_GRACE_S * 2)
    feed(s, 'camera_info', 0, receipt=6.0)
    assert not s.missing_camera_info(7.0)


def test_resync_keeps_drop_counts_and_camera_info() -> None:
    s = make(queue_size=1)
    feed(s, 'camera_info', 0)
    feed(s, 'depth', 100)
    feed(s, 'depth', 133)  # pushes the first out of a 1-message queue
    assert s.dropped()['depth'] == 1
    s.resync(queue_size=5, slop_ns=30 * MS)
    assert s.slop_ns == 30 * MS and s.dropped()['depth'] >= 1
    feed(s, 'color', 200)
    feed(s, 'depth', 225)  # 25 ms apart: pairs with the new slop, camera info kept
    assert any(j == 'process' for j, _ in drain(s))


def test_close_wakes_the_worker() -> None:
    s = make()
    s.close()
    assert s.closed and s.next_job(timeout=5.0) is None


@pytest.mark.parametrize('kind', ['color', 'depth'])
def test_received_counts_every_input(kind: str) -> None:
    s = make()
    for k in range(4):
        feed(s, kind, 100 + 33 * k)
    assert s.stats.received[kind] == 4


def _stream(s: Scheduler, frames: int, *, drop_color=(), color=True, t0=1000.0,
            period=33.3) -> list[int]:
    """Feed ``frames`` depth images (and colour 2 ms later, except ``drop_color`` frames);
    returns the depth stamps (ns) of the sets the worker processed, in order."""
    done = []
    for k in range(frames):
        stamp = t0 + k * period
        feed(s, 'depth', stamp, receipt=k * period / 1e3)
        if color and k not in drop_color:
            feed(s, 'color', stamp + 2, receipt=k * period / 1e3 + 0.002)
        s.flush_colorless(k * period / 1e3 + 0.003)
        done += [args[0]['depth'].stamp for job, args in drain(s) if job == 'process']
    return done


def test_every_depth_image_is_answered_when_colour_images_are_lost() -> None:
    """A depth image whose colour never comes is handed on as soon as a newer colour image
    shows that it is lost, and its set does not replace the next complete set."""
    warnings: list[str] = []
    s = make(color_timeout_s=10.0, on_warning=lambda kind, text: warnings.append(kind))
    feed(s, 'camera_info', 0)
    done = _stream(s, 30, drop_color={3, 13, 23})
    assert done[:29] == [round((1000.0 + k * 33.3) * MS) for k in range(29)]
    assert s.stats.colorless == 3 and s.skipped == 0
    assert warnings.count('color_lost') == 3


def test_without_colour_depth_images_do_not_wait_for_the_timeout() -> None:
    """No colour at all: the first depth images wait (colour may still come); once colour
    counts as stopped they are answered, oldest first, and every later one on arrival."""
    s = make(color_timeout_s=10.0)
    feed(s, 'camera_info', 0)
    stamps = [round((1000.0 + k * 33.3) * MS) for k in range(10)]
    done = []
    for k, stamp in enumerate(stamps):
        s.on_input('depth', Msg('depth', stamp), k * 0.0333)
        done.append([args[0]['depth'].stamp for job, args in drain(s) if job == 'process'])
    assert done[:COLOR_STOPPED_FRAMES] == [[]] * COLOR_STOPPED_FRAMES
    assert done[COLOR_STOPPED_FRAMES] == stamps[:COLOR_STOPPED_FRAMES + 1]
    assert done[COLOR_STOPPED_FRAMES + 1:] == [[t] for t in stamps[COLOR_STOPPED_FRAMES + 1:]]
    assert s.stats.colorless == 10 and s.skipped == 0


def test_a_colour_timeout_hands_on_every_waiting_depth_image_in_order() -> None:
    s = make(color_timeout_s=0.1)
    feed(s, 'camera_info', 0)
    feed(s, 'depth', 1000.0, receipt=1.0)
    feed(s, 'depth', 1033.3, receipt=1.033)
    s.flush_colorless(1.2)  # both waited longer than the timeout
    jobs = [(job, args[0]['depth'].stamp, args[1]) for job, args in drain(s)
            if job == 'process']
    assert jobs == [('process', 1000 * MS, 1.0), ('process', round(1033.3 * MS), 1.033)]
    assert s.stats.colorless == 2 and s.skipped == 0


def test_colourless_sets_wait_in_order_behind_a_busy_worker_and_stay_bounded() -> None:
    """While the worker is busy, sets whose colour is lost queue oldest first, before a newer
    complete set; beyond ``COLOR_STOPPED_FRAMES`` queued behind the slot's, the oldest are
    skipped and counted."""
    s = make(color_timeout_s=10.0)
    feed(s, 'camera_info', 0)
    for first, color in ((1000.0, 1100.0), (1133.3, 1233.3)):
        for k in range(3):  # three depth images whose colour never comes, then a newer colour
            feed(s, 'depth', first + 33.3 * k)
        feed(s, 'color', color)
    feed(s, 'depth', 1300.0)
    feed(s, 'color', 1301.0)  # a complete set, newer than all of them
    done = [args[0]['depth'].stamp for job, args in drain(s) if job == 'process']
    # the first in the slot, the 3 newest queued; the 2 between are skipped
    assert COLOR_STOPPED_FRAMES == 3
    assert done == [round(t * MS) for t in (1000.0, 1133.3, 1166.6, 1199.9, 1300.0)]
    assert s.skipped == 2 and s.stats.colorless == 6


def test_a_reset_forgets_the_queued_colourless_sets() -> None:
    s = make(color_timeout_s=0.1)
    feed(s, 'camera_info', 0)
    for k in range(3):
        feed(s, 'depth', 1000.0 + 33.3 * k, receipt=1.0)
    s.flush_colorless(2.0)  # three queued, none taken yet
    s.request_reset()
    assert [job for job, _ in drain(s) if job == 'process'] == []
    # After the reset a set whose colour is lost is still served, before a newer complete set.
    feed(s, 'color', 1150.0, receipt=2.9)
    feed(s, 'depth', 1200.0, receipt=3.0)
    feed(s, 'color', 1300.0, receipt=3.03)  # the colour of 1200 is lost
    feed(s, 'depth', 1333.3, receipt=3.06)
    feed(s, 'color', 1334.0, receipt=3.06)
    assert [args[0]['depth'].stamp for job, args in drain(s) if job == 'process'] == [
        1200 * MS, round(1333.3 * MS)]


def test_one_stamp_far_ahead_is_quarantined_and_resets_nothing() -> None:
    warnings: list[str] = []
    s = make(jump_threshold_ns=1000 * MS, on_warning=lambda kind, text: warnings.append(kind))
    feed(s, 'camera_info', 0)
    first = _stream(s, 3)
    feed(s, 'depth', 1000.0 + 86_400_000)  # one frame stamped a day ahead
    assert s.stats.quarantined == 1 and warnings == ['stamp_ahead']
    later = _stream(s, 3, t0=1000.0 + 3 * 33.3)
    assert s.begin_set() == (None, False)  # no reset
    assert len(first) == 3 and len(later) == 3 and later[0] > first[-1]


def test_a_confirmed_jump_ahead_is_followed() -> None:
    s = make(jump_threshold_ns=1000 * MS)
    feed(s, 'camera_info', 0)
    _stream(s, 3)
    done = _stream(s, 3, t0=60_000.0)  # a new recording a minute later
    assert s.stats.quarantined == 2  # the first frame of the jump (colour and depth)
    assert len(done) >= 2 and s.begin_set() == (None, False)


def test_late_messages_are_dropped_with_a_warning() -> None:
    warnings: list[str] = []
    s = make(on_warning=lambda kind, text: warnings.append(kind))
    feed(s, 'camera_info', 0)
    _stream(s, 3)
    feed(s, 'depth', 1000.0)  # older than the last set handed on, within the jump threshold
    assert 'late_input' in warnings


PERIOD_S = 0.0333


def _lagged_stream(s: Scheduler, frames: int, lag_s, *, drop_color=(), tick_s=0.0005
                   ) -> list[tuple[int, bool, float]]:
    """Depth images every ``PERIOD_S`` (receipt k * PERIOD_S, stamp 1000 ms + that), each
    colour image ``lag_s(k)`` s after its depth image (stamped 2 ms after it; none for
    ``drop_color``), and a worker calling :meth:`flush_colorless` every ``tick_s``. Returns
    the sets processed, in order: (depth stamp ns, with colour, seconds after its receipt)."""
    events = []
    for k in range(frames):
        t = k * PERIOD_S
        events.append((t, 0, 'depth', 1000.0 + t * 1e3))
        if k not in drop_color:
            events.append((t + lag_s(k), 0, 'color', 1002.0 + t * 1e3))
    events += [(j * tick_s, 1, 'flush', 0.0) for j in range(round(frames * PERIOD_S / tick_s))]
    done = []
    for t, _, kind, stamp_ms in sorted(events):
        if kind == 'flush':
            s.flush_colorless(t)
        else:
            feed(s, kind, stamp_ms, receipt=t)
        done += [(msgs['depth'].stamp, msgs['color'] is not None, t - receipt)
                 for job, (msgs, receipt, *_) in drain(s) if job == 'process']
    return done


def _stamps(frames: int) -> list[int]:
    return [round((1000.0 + k * PERIOD_S * 1e3) * MS) for k in range(frames)]


def test_the_wait_for_colour_is_learned_from_recent_colour_lags() -> None:
    """Until ``COLOR_LAG_MIN`` colour images have paired a depth image waits the full
    ``color_timeout``; then the largest recent lag plus the margin (0 when colour came
    first)."""
    s = make(color_timeout_s=0.1)
    feed(s, 'camera_info', 0)
    lags = [0.002, 0.005, None, 0.003] + [0.002] * (COLOR_LAG_MIN - 4)  # None: colour first
    for k, lag in enumerate(lags):
        t = k * PERIOD_S
        assert s.color_wait_s() == 0.1
        if lag is None:
            feed(s, 'color', 1002 + k * 33.3, receipt=t)
            feed(s, 'depth', 1000 + k * 33.3, receipt=t + 0.001)
        else:
            feed(s, 'depth', 1000 + k * 33.3, receipt=t)
            feed(s, 'color', 1002 + k * 33.3, receipt=t + lag)
    assert [j for j, _ in drain(s)].count('process') >= 1
    assert s.color_wait_s() == pytest.approx(0.005 + COLOR_LAG_MARGIN_S)
    # The wait never exceeds the timeout.
    s.color_timeout_s = 0.004
    assert s.color_wait_s() == 0.004


def test_a_lost_colour_is_handed_on_after_the_learned_wait() -> None:
    """A depth image whose colour is lost is answered once the learned wait has passed, not
    when the next colour image arrives or after ``color_timeout``; before enough colour
    images have paired it is answered as before (by the next colour image)."""
    warnings: list[str] = []
    s = make(color_timeout_s=0.1, on_warning=lambda kind, text: warnings.append(kind))
    feed(s, 'camera_info', 0)
    drops = {3, 13, 23}
    done = _lagged_stream(s, 30, lambda k: 0.002, drop_color=drops)
    assert [d for d, _, _ in done] == _stamps(30)  # every one, once, in order
    assert [k for k, (_, color, _) in enumerate(done) if not color] == sorted(drops)
    assert s.skipped == 0 and s.stats.colorless == 3 and s.stats.duplicates == 0
    wait = 0.002 + COLOR_LAG_MARGIN_S
    assert s.color_wait_s() == pytest.approx(wait)
    # Frame 3 (before COLOR_LAG_MIN lags): answered when the next colour image arrived.
    assert done[3][2] == pytest.approx(PERIOD_S + 0.002)
    for k in (13, 23):  # within a flush tick of the learned wait
        assert wait < done[k][2] <= wait + 0.0005 + 1e-9
    assert warnings.count('color_late') == 2 and 'color_too_late' not in warnings


@pytest.mark.parametrize(('late_lag', 'missed'), [(0.020, 1), (0.045, 2)])  # < / > a period
def test_the_wait_grows_back_when_the_colour_lag_grows(late_lag: float, missed: int) -> None:
    """Colour images arriving later than the learned wait are dropped (their depth images
    were answered without them), with a warning, but their lag counts: the wait grows, and
    the next colour images pair again instead of every later frame going without colour."""
    warnings: list[str] = []
    s = make(color_timeout_s=0.1, on_warning=lambda kind, text: warnings.append(kind))
    feed(s, 'camera_info', 0)
    done = _lagged_stream(s, 30, lambda k: 0.002 if k < 15 else late_lag)
    assert [d for d, _, _ in done] == _stamps(30)
    # The first frames with the longer lag go without colour, then all pair again.
    assert [k for k, (_, color, _) in enumerate(done) if not color] == list(
        range(15, 15 + missed))
    assert warnings.count('color_too_late') == missed
    assert s.color_wait_s() == pytest.approx(late_lag + COLOR_LAG_MARGIN_S)
    assert s.skipped == 0 and s.stats.colorless == missed


def test_the_worker_wakes_when_a_waiting_depth_image_is_due() -> None:
    """``next_job`` returns (None) when the longest-waiting depth image is due to be handed on,
    so that the worker's ``flush_colorless`` runs then rather than after its polling timeout;
    none is due before the camera info has come."""
    now = [0.0]
    s = make(color_timeout_s=0.1, clock=lambda: now[0])
    feed(s, 'depth', 1000, receipt=0.0)
    assert s.color_due_in(0.0) is None  # no camera info: nothing to hand on yet
    feed(s, 'camera_info', 0)
    assert s.color_due_in(0.03) == pytest.approx(0.07)
    drain(s)
    now[0] = 0.2  # overdue: the worker must not sleep its full timeout
    got: list[object] = []
    worker = threading.Thread(target=lambda: got.append(s.next_job(timeout=60.0)))
    worker.start()
    worker.join(timeout=20.0)
    assert not worker.is_alive() and got == [None]
    s.flush_colorless(now[0])
    assert [j for j, _ in drain(s)] == ['process'] and s.color_due_in(now[0]) is None


def test_a_colour_image_later_than_its_answered_depth_image_makes_no_work() -> None:
    """A colour image whose depth image was already answered without it gets neither a set
    nor an early flow (its set can never be processed), only a warning; also when the next
    depth image pushed its partner out of the synchroniser's queue."""
    for queue_size in (10, 1):
        warnings: list[str] = []
        s = make(color_timeout_s=0.1, queue_size=queue_size,
                 on_warning=lambda kind, text, seen=warnings: seen.append(kind))
        feed(s, 'camera_info', 0)
        _lagged_stream(s, COLOR_LAG_MIN + 1, lambda k: 0.002)
        t = (COLOR_LAG_MIN + 1) * PERIOD_S
        feed(s, 'depth', 1000.0 + t * 1e3, receipt=t)
        drain(s)
        s.flush_colorless(t + 0.01)  # past the learned wait of 6 ms
        assert [j for j, _ in drain(s)] == ['process'] and s.stats.colorless == 1
        feed(s, 'depth', 1000.0 + (t + PERIOD_S) * 1e3, receipt=t + PERIOD_S)
        assert [j for j, _ in drain(s)] == ['prepare']
        feed(s, 'color', 1002.0 + t * 1e3, receipt=t + PERIOD_S + 0.001)
        assert drain(s) == [] and warnings[-1] == 'color_too_late'
