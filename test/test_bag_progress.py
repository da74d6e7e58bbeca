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


def test_count_frames_and_shared_counter(tmp_path: Path) -> None:
    write_bag(tmp_path / 'a', BagSpec(frames=4))
    write_bag(tmp_path / 'b', BagSpec(frames=3, drop_depth={1}))
    (tmp_path / 'c').mkdir()  # not a bag: counts 0, reported when processed
    assert progress.count_frames([tmp_path / 'a', tmp_path / 'b', tmp_path / 'c']) == 6
    counter = progress.shared_counter()
    progress.report(5)  # not a worker yet: ignored
    progress.init_worker(counter)
    try:
        progress.report(2)
        progress.report()
    finally:
        progress.init_worker(None)
    assert counter.value == 3
