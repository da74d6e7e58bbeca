"""The optional tqdm progress bar of ``endeff process`` / ``endeff eval``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from bag_helpers import BagSpec, write_bag

from endeff_ros.bag import progress


def test_bar_shows_frames_rate_and_eta(capsys: pytest.CaptureFixture[str]) -> None:
    with progress.progress_bar(40, enabled=True) as bar:
        assert bar.enabled
        bar.update(10)
        bar.update_to(25)
    err = capsys.readouterr().err
    assert '25/40' in err and 'frame/s' in err and '<' in err  # "elapsed<remaining"
    assert bar.done == 25


def test_no_bar_off_a_terminal_or_without_tqdm(capsys: pytest.CaptureFixture[str],
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    with progress.progress_bar(10) as bar:  # stderr is captured: not a TTY
        bar.update(3)
    assert not bar.enabled and bar.done == 3
    monkeypatch.setitem(sys.modules, 'tqdm', None)  # import tqdm raises ImportError
    with progress.progress_bar(10, enabled=True) as bar:
        bar.update(4)
    assert not bar.enabled
    assert capsys.readouterr().err == ''


def test_total_grows_past_the_estimate(capsys: pytest.CaptureFixture[str]) -> None:
    with progress.progress_bar(2, enabled=True) as bar:
        bar.update(5)
    assert '5/5' in capsys.readouterr().err


def test_count_frames_and_worker_progress(tmp_path: Path) -> None:
    write_bag(tmp_path / 'a', BagSpec(frames=4))
    write_bag(tmp_path / 'b', BagSpec(frames=3, drop_depth={1}))
    (tmp_path / 'c').mkdir()  # not a bag: counts 0, reported when processed
    assert progress.count_frames([tmp_path / 'a', tmp_path / 'b', tmp_path / 'c']) == 6
    progress.report(5)  # not in a worker: nothing to send, no error
    with progress.progress_bar(0, enabled=False) as bar:
        assert progress.map_in_workers(_count, [3, 4, 250], 2, bar) == [3, 4, 250]
    assert bar.done == 257  # every frame the workers reported reached the parent's bar


def _count(frames: int) -> int:
    for _ in range(frames):
        progress.report()
    return frames


def _nap(seconds: float) -> float:
    import time

    time.sleep(seconds)
    return seconds


class _InterruptedBar(progress.ProgressBar):
    """A bar whose first update raises KeyboardInterrupt, as Ctrl-C in the parent would."""

    def __init__(self) -> None:
        super().__init__(0, enabled=False)

    def update_to(self, done: int) -> None:
        raise KeyboardInterrupt


def test_an_interrupt_stops_the_pool_but_not_the_callers_own_children() -> None:
    import multiprocessing
    import time

    own = multiprocessing.get_context().Process(target=_nap, args=(30.0,))
    own.start()
    try:
        start = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            progress.map_in_workers(_nap, [30.0] * 5, 2, _InterruptedBar())
        # The workers were stopped, not waited for through their 30 s jobs and the queued ones ...
        assert time.monotonic() - start < 10
        assert [c for c in multiprocessing.active_children() if c is not own] == []
        # ... and the caller's own process still runs (a SIGTERM would end it within 1 s).
        own.join(1.0)
        assert own.is_alive()
    finally:
        own.terminate()
        own.join()
