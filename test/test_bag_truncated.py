"""Bags cut short (a crash, a full disk, an interrupted copy): read up to the cut with a
warning naming what was lost, scored and processed; ``--strict`` refuses them."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from bag_helpers import BagSpec, FakeTracker, fake_estimate_frame, storage_file, write_bag

from endeff_ros.bag.errors import BagError
from endeff_ros.bag.reader import BagReader, ReaderOptions

FRAMES = 30
DEPTH = '/camera/depth/image_raw'


def _cut_bag(root: Path, storage: str, keep: float = 0.6) -> Path:
    """A bag of 160x120 frames (several 1 MiB MCAP chunks) cut to ``keep`` of its size."""
    bag = root / f'cut_{storage}'
    write_bag(bag, BagSpec(frames=FRAMES, storage=storage, width=160, height=120, fx=200.0,
                           blob_px=4))
    f = storage_file(bag)
    data = f.read_bytes()
    f.write_bytes(data[:int(len(data) * keep)])
    return bag


def _read(bag: Path, options: ReaderOptions | None = None) -> tuple[list, BagReader, list[str]]:
    warnings: list[str] = []
    with BagReader(bag, options, warn=warnings.append) as reader:
        return list(reader.records()), reader, warnings


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_truncated_bag_is_read_up_to_the_cut(tmp_path: Path, storage: str) -> None:
    bag = _cut_bag(tmp_path, storage)
    recs, reader, warnings = _read(bag)
    assert reader.salvaged
    assert 5 <= len(recs) < FRAMES
    stamps = [r.frame.stamp_ns for r in recs]
    # Ground truth is written after its depth image: the last frame may have lost it.
    assert stamps == sorted(stamps) and all(r.gt is not None for r in recs[:-1])
    got, want = reader.stats.lost[DEPTH]
    assert want == FRAMES and got < FRAMES and reader.stats.frames == len(recs)
    assert reader.stats.to_dict()['lost'][DEPTH] == {'read': got, 'expected': FRAMES}
    text = warnings[-1]
    assert f'{got} of {FRAMES} messages on {DEPTH}' in text and '--strict' in text
    assert f'{len(recs)} frames yielded' in text


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_strict_refuses_truncated_bags(tmp_path: Path, storage: str) -> None:
    bag = _cut_bag(tmp_path, storage)
    with pytest.raises(BagError, match='--strict'):
        _read(bag, ReaderOptions(strict=True))


def test_truncated_single_file_without_metadata(tmp_path: Path) -> None:
    """Without metadata.yaml nothing says how much was expected: read what is there."""
    bag = _cut_bag(tmp_path, 'mcap')
    loose = tmp_path / 'loose.mcap'
    shutil.move(storage_file(bag), loose)
    recs, reader, warnings = _read(loose)
    assert 5 <= len(recs) < FRAMES and reader.stats.lost == {}
    assert reader.stats.read_error is not None and 'truncated or corrupt' in warnings[-1]


def test_eval_scores_the_readable_part(tmp_path: Path) -> None:
    from endeff_ros.evaluate import evaluate_bag

    bag = _cut_bag(tmp_path, 'sqlite3')
    with BagReader(bag, warn=lambda _t: None) as reader:
        readable = len(list(reader.records()))
    res = evaluate_bag(bag, estimate_fn=fake_estimate_frame, tracker_factory=FakeTracker)
    assert res.frames == readable and res.scored_frames >= readable - 1
    assert res.stats['lost'][DEPTH]['expected'] == FRAMES
    with pytest.raises(BagError, match='--strict'):
        evaluate_bag(bag, options=ReaderOptions(strict=True), estimate_fn=fake_estimate_frame,
                     tracker_factory=FakeTracker)


def test_process_truncated_bag_and_folder_without_metadata(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:

    import endeff_ros.core.tracker as tracker_mod
    from endeff_ros.cli import main as cli_main

    monkeypatch.setattr(tracker_mod, 'Tracker', FakeTracker)
    bag = _cut_bag(tmp_path, 'mcap')
    (bag / 'metadata.yaml').unlink()  # a folder eval reads: its one storage file
    assert cli_main(['process', str(bag), '-o', str(tmp_path / 'out')]) == 0
    cap = capsys.readouterr()
    assert 'warning: truncated or corrupt' in cap.err
    from rosbags.highlevel import AnyReader

    with AnyReader([tmp_path / 'out']) as out:
        n = sum(1 for c, _, _ in out.messages() if c.topic == '/camera/end_effectors')
    assert 5 <= n < FRAMES
    assert cli_main(['process', str(bag), '-o', str(tmp_path / 'strict'), '--strict']) == 1
    assert '--strict' in capsys.readouterr().err and not (tmp_path / 'strict').exists()


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_copy_input_of_a_truncated_bag(tmp_path: Path, storage: str) -> None:
    from rosbags.highlevel import AnyReader

    from endeff_ros.bag.process import process_bag

    bag = _cut_bag(tmp_path, storage)
    res = process_bag(bag, tmp_path / 'out', copy_input=True, tracker_factory=FakeTracker)
    with AnyReader([tmp_path / 'out']) as r:
        topics = [c.topic for c, _, _ in r.messages()]
    assert topics.count('/camera/end_effectors') == res.frames
    assert res.frames <= topics.count(DEPTH) < FRAMES
