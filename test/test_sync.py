"""Tests of the approximate-time synchroniser (modelled on message_filters' test_approxsync)."""

from __future__ import annotations

import random

import pytest

from endeff_ros.sync import ApproximateTimeSynchronizer

MS = 1_000_000  # nanoseconds per millisecond
PERIOD = 33 * MS


def _sync(n: int = 2, queue: int = 10, slop_ms: float = 5.0,
          **kwargs: object) -> tuple[ApproximateTimeSynchronizer, list[tuple[object, ...]]]:
    got: list[tuple[object, ...]] = []
    sync = ApproximateTimeSynchronizer(n, queue, int(slop_ms * MS),
                                       lambda *msgs: got.append(msgs), **kwargs)
    return sync, got


def test_exact_pairs() -> None:
    sync, got = _sync()
    for k in range(10):
        t = k * PERIOD
        assert sync.add(0, t, ('rgb', k)) == []
        assert sync.add(1, t, ('depth', k)) == [(('rgb', k), ('depth', k))]
    assert got == [(('rgb', k), ('depth', k)) for k in range(10)]
    assert sync.stats.emitted == 10
    assert sync.stats.dropped == [0, 0]


def test_exact_pairs_either_input_first() -> None:
    sync, got = _sync(n=3)
    for k in range(6):
        t = k * PERIOD
        order = [k % 3, (k + 1) % 3, (k + 2) % 3]
        for i in order:
            sync.add(i, t, (i, k))
    assert got == [((0, k), (1, k), (2, k)) for k in range(6)]
    assert sync.stats.dropped == [0, 0, 0]


def test_jittered_pairs_within_slop() -> None:
    rng = random.Random(4)
    sync, got = _sync(slop_ms=5.0)
    for k in range(50):
        t = k * PERIOD
        sync.add(0, t + rng.randint(-2 * MS, 2 * MS), ('rgb', k))
        sync.add(1, t + rng.randint(-2 * MS, 2 * MS), ('depth', k))
    assert got == [(('rgb', k), ('depth', k)) for k in range(50)]
    assert sync.stats.dropped == [0, 0]


def test_pairs_outside_slop_do_not_match() -> None:
    sync, got = _sync(slop_ms=5.0)
    for k in range(5):
        t = k * PERIOD
        sync.add(0, t, ('rgb', k))
        sync.add(1, t + 10 * MS, ('depth', k))  # always 10 ms late: never within 5 ms
    assert got == []
    assert sync.stats.emitted == 0
    assert sum(sync.stats.dropped) > 0


def test_dropped_frame_on_one_input() -> None:
    """Depth frame 3 never arrives: RGB frame 3 is counted as dropped, later pairs match."""
    sync, got = _sync(slop_ms=5.0)
    for k in range(8):
        t = k * PERIOD
        sync.add(0, t + MS, ('rgb', k))
        if k != 3:
            sync.add(1, t, ('depth', k))
    assert got == [(('rgb', k), ('depth', k)) for k in range(8) if k != 3]
    assert sync.stats.dropped == [1, 0]
    assert sync.stats.emitted == 7


def test_dropped_frame_then_burst_of_the_other_input() -> None:
    """Depth frames 2 and 3 arrive after RGB 4 (a slow driver): nothing is mismatched."""
    sync, got = _sync(slop_ms=5.0)
    for k in range(5):
        sync.add(0, k * PERIOD, ('rgb', k))
    for k in range(5):
        sync.add(1, k * PERIOD, ('depth', k))
    assert got == [(('rgb', k), ('depth', k)) for k in range(5)]
    assert sync.stats.dropped == [0, 0]


def test_out_of_order_arrival() -> None:
    sync, got = _sync(slop_ms=5.0)
    # RGB 1 arrives before RGB 0 (e.g. two transport threads); depth arrives in order.
    sync.add(0, 1 * PERIOD, ('rgb', 1))
    sync.add(0, 0 * PERIOD, ('rgb', 0))
    sync.add(1, 0 * PERIOD, ('depth', 0))
    sync.add(1, 1 * PERIOD + MS, ('depth', 1))
    assert got == [(('rgb', 0), ('depth', 0)), (('rgb', 1), ('depth', 1))]
    assert sync.stats.dropped == [0, 0]


def test_message_older_than_last_set_is_dropped() -> None:
    sync, got = _sync(slop_ms=5.0)
    sync.add(0, 2 * PERIOD, 'rgb2')
    sync.add(1, 2 * PERIOD, 'depth2')
    assert sync.add(0, 1 * PERIOD, 'rgb1 (late)') == []
    assert sync.add(1, 2 * PERIOD, 'depth2 (duplicate)') == []
    assert sync.stats.dropped == [1, 1]
    sync.add(0, 3 * PERIOD, 'rgb3')
    sync.add(1, 3 * PERIOD, 'depth3')
    assert got == [('rgb2', 'depth2'), ('rgb3', 'depth3')]


def test_latched_camera_info() -> None:
    """Input 2 (camera info) is latched: nothing is emitted before it has a message, then its
    newest message completes every set and is never counted as dropped."""
    sync, got = _sync(n=3, latched=(2,))
    sync.add(0, 0, 'rgb0')
    sync.add(1, 0, 'depth0')
    assert got == []
    assert sync.add(2, 0, 'info_a') == [('rgb0', 'depth0', 'info_a')]
    sync.add(0, PERIOD, 'rgb1')
    sync.add(1, PERIOD, 'depth1')
    sync.add(2, 5 * PERIOD, 'info_b')  # a newer camera info replaces the old one
    sync.add(0, 2 * PERIOD, 'rgb2')
    sync.add(1, 2 * PERIOD, 'depth2')
    assert got == [('rgb0', 'depth0', 'info_a'), ('rgb1', 'depth1', 'info_a'),
                   ('rgb2', 'depth2', 'info_b')]
    assert sync.stats.dropped == [0, 0, 0]


def test_latched_input_before_any_stream() -> None:
    sync, got = _sync(n=3, latched=(0,))
    assert sync.add(0, 0, 'info') == []
    sync.add(1, 0, 'rgb')
    sync.add(2, MS, 'depth')
    assert got == [('info', 'rgb', 'depth')]


def test_queue_overflow_is_counted() -> None:
    """With depth silent, RGB beyond the queue size is pushed out and counted per input."""
    sync, got = _sync(queue=3, slop_ms=5.0)
    for k in range(10):
        sync.add(0, k * PERIOD, ('rgb', k))
    assert got == []
    assert sync.stats.dropped == [7, 0]
    # The three newest RGB frames are still queued and pair with late depth.
    sync.add(1, 8 * PERIOD, ('depth', 8))
    assert got == [(('rgb', 8), ('depth', 8))]
    assert sync.stats.dropped == [8, 0]  # RGB 7 can no longer pair


def test_long_backlog_does_not_hit_the_recursion_limit() -> None:
    sync, got = _sync(queue=5000, slop_ms=1.0)
    for k in range(3000):
        sync.add(0, k * MS, k)
    sync.add(1, 10_000 * MS, 'late depth')
    assert got == []
    assert sync.stats.dropped == [3000, 0]


def test_return_value_without_callback() -> None:
    sync = ApproximateTimeSynchronizer(2, 5, 0)
    assert sync.add(1, 7, 'b') == []
    assert sync.add(0, 7, 'a') == [('a', 'b')]
    assert sync.stats.emitted == 1


@pytest.mark.parametrize(('args', 'kwargs', 'match'), [
    ((0, 10, 0), {}, 'n_inputs >= 1'),
    ((2, 0, 0), {}, 'queue_size >= 1'),
    ((2, 10, -1), {}, 'slop >= 0'),
    ((2, 10, 0), {'latched': (2,)}, 'out of range'),
    ((2, 10, 0), {'latched': (-1,)}, 'out of range'),
    ((1, 10, 0), {'latched': (0,)}, 'not latched'),
    ((2, 10, 0), {'latched': (0, 1)}, 'not latched'),
])
def test_bad_constructor_arguments(args: tuple[int, int, int], kwargs: dict[str, object],
                                   match: str) -> None:
    with pytest.raises(ValueError, match=match):
        ApproximateTimeSynchronizer(*args, **kwargs)  # type: ignore[arg-type]


def test_bad_input_index() -> None:
    sync = ApproximateTimeSynchronizer(2, 5, 0)
    for index in (2, -1):
        with pytest.raises(IndexError, match='out of range'):
            sync.add(index, 0, 'x')


def test_on_drop_reports_each_dropped_message_with_its_reason() -> None:
    """Every drop the counters see is handed to ``on_drop`` once, with why it happened."""
    from endeff_ros.sync import FLUSHED, LATE, OVERFLOW, UNPAIRED

    drops: list[tuple[int, int, object, str]] = []
    sync = ApproximateTimeSynchronizer(2, 3, 5 * MS, on_drop=lambda *d: drops.append(d))
    for k in range(5):  # rgb 0, 1 pushed out of the queue of 3
        sync.add(0, k * PERIOD, f'rgb{k}')
    assert drops == [(0, 0, 'rgb0', OVERFLOW), (0, PERIOD, 'rgb1', OVERFLOW)]
    drops.clear()
    sync.add(1, 3 * PERIOD, 'depth3')  # pairs with rgb3; rgb2 has no depth within the slop
    assert drops == [(0, 2 * PERIOD, 'rgb2', UNPAIRED)]
    drops.clear()
    sync.add(1, 2 * PERIOD, 'depth2')  # older than the emitted set
    sync.add(1, 6 * PERIOD, 'depth6')  # rgb4 can no longer pair: depth is beyond the slop
    sync.add(1, 7 * PERIOD, 'depth7')
    assert drops == [(1, 2 * PERIOD, 'depth2', LATE), (0, 4 * PERIOD, 'rgb4', UNPAIRED)]
    drops.clear()
    sync.flush()
    assert drops == [(1, 6 * PERIOD, 'depth6', FLUSHED), (1, 7 * PERIOD, 'depth7', FLUSHED)]
    assert sync.stats.dropped == [4, 3]
