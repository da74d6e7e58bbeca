"""endeff_ros.bag.reader on bags written by an independent writer (test/bag_helpers.py)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from bag_helpers import (
    KINECT,
    PERIOD_NS,
    REALSENSE,
    START_NS,
    BagSpec,
    render_depth,
    storage_file,
    write_bag,
)

from endeff_ros.bag.errors import BagError
from endeff_ros.bag.reader import BagReader, ReaderOptions, find_bags, read_frames

STORAGES = ('mcap', 'sqlite3')


def _read(path: Path, options: ReaderOptions | None = None) -> tuple[list, BagReader]:
    with BagReader(path, options) as bag:
        return list(bag.records()), bag


@pytest.mark.parametrize('storage', STORAGES)
@pytest.mark.parametrize('single_file', [False, True])
def test_reads_contract_bag(tmp_path: Path, storage: str, single_file: bool) -> None:
    spec = BagSpec(frames=6, storage=storage, color_encoding='bgr8')
    truth = write_bag(tmp_path / 'bag', spec)
    path = storage_file(tmp_path / 'bag') if single_file else tmp_path / 'bag'
    recs, bag = _read(path)
    assert bag.selection is not None and bag.selection.preset == 'benchmark contract'
    assert [r.frame.stamp_ns for r in recs] == sorted(truth)
    for i, rec in enumerate(recs):
        f = rec.frame
        assert f.frame_id == 'camera_color_optical_frame'
        assert f.intrinsics.fx == 80.0 and f.intrinsics.cx == pytest.approx(31.5)
        expect = render_depth(spec, i)
        expect[expect == 0] = np.nan
        np.testing.assert_allclose(f.depth, expect, atol=6e-4, equal_nan=True)  # mm -> m
        assert f.color is not None and f.color.dtype == np.uint8
        # bgr8 in the bag, RGB out: blobs are red.
        assert tuple(f.color[f.depth < 3.0][0]) == (200, 30, 30)
        np.testing.assert_allclose(rec.gt, truth[f.stamp_ns], atol=1e-6)
        assert rec.log_time_ns == f.stamp_ns + spec.log_delay_ns + 1
    assert bag.stats.frames == 6 and bag.stats.gt_matched == 6 and bag.stats.colorless == 0


@pytest.mark.parametrize(('storage', 'compression'),
                         [('mcap', 'message'), ('sqlite3', 'file'), ('mcap', 'file')])
def test_compressed_bags(tmp_path: Path, storage: str, compression: str) -> None:
    write_bag(tmp_path / 'bag', BagSpec(frames=4, storage=storage, compression=compression,
                                        depth_encoding='32FC1'))
    frames = list(read_frames(tmp_path / 'bag'))
    assert len(frames) == 4 and all(gt is not None and gt.shape == (3, 3) for _, gt in frames)
    assert np.nanmin(frames[0][0].depth) == pytest.approx(2.0)


def test_log_order_differs_from_stamps(tmp_path: Path) -> None:
    """Messages recorded in scrambled order are fed to the synchroniser by header stamp."""
    truth = write_bag(tmp_path / 'bag', BagSpec(frames=10, shuffle_log=True))
    recs, bag = _read(tmp_path / 'bag')
    assert [r.frame.stamp_ns for r in recs] == sorted(truth)
    assert all(r.frame.color is not None for r in recs)
    assert all(np.allclose(r.gt, truth[r.frame.stamp_ns]) for r in recs)
    assert bag.stats.dropped == {t: 0 for t in bag.stats.dropped}


def test_dropped_frames_and_partial_ground_truth(tmp_path: Path) -> None:
    spec = BagSpec(frames=10, drop_color={3}, drop_depth={6}, gt_frames={0, 3, 7},
                   info_every=4)
    write_bag(tmp_path / 'bag', spec)
    recs, bag = _read(tmp_path / 'bag')
    stamps = [r.frame.stamp_ns for r in recs]
    want = [START_NS + i * PERIOD_NS for i in range(10) if i != 6]
    assert stamps == want
    # Depth 3 has no colour: yielded without it (the tracker falls back).
    assert [r.frame.color is None for r in recs] == [i == 3 for i in range(10) if i != 6]
    # Colour 6 has no depth: dropped and counted.
    assert bag.stats.dropped['/camera/color/image_raw'] == 1
    assert bag.stats.colorless == 1
    scored = [i for i, r in zip([i for i in range(10) if i != 6], recs, strict=True)
              if r.gt is not None]
    assert scored == [0, 3, 7]
    assert bag.stats.gt_messages == 3 and bag.stats.gt_unmatched == 0


def test_colour_beyond_slop_is_not_paired(tmp_path: Path) -> None:
    # Colour half a frame period (16.7 ms) after depth: beyond the default 15 ms slop.
    write_bag(tmp_path / 'bag', BagSpec(frames=5, color_offset_ns=PERIOD_NS // 2))
    recs, bag = _read(tmp_path / 'bag')
    assert len(recs) == 5 and all(r.frame.color is None for r in recs)
    assert bag.stats.dropped['/camera/color/image_raw'] == 5
    recs, _ = _read(tmp_path / 'bag', ReaderOptions(slop_s=0.02))
    assert len(recs) == 5 and sum(r.frame.color is not None for r in recs) >= 4


def test_colour_stream_stops_memory_stays_bounded(tmp_path: Path) -> None:
    write_bag(tmp_path / 'bag', BagSpec(frames=80, width=16, height=12, fx=20.0, blob_px=1,
                                        n_blobs=1, drop_color=set(range(2, 80))))
    with BagReader(tmp_path / 'bag') as bag:
        read_when_yielded = []
        recs = []
        for rec in bag.records():
            recs.append(rec)
            read_when_yielded.append(bag.stats.messages['/camera/depth/image_raw'])
    assert len(recs) == 80 and bag.stats.colorless == 78
    assert [r.frame.color is None for r in recs[:3]] == [False, False, True]
    # Colour-less frames come out as the synchroniser gives up on them, not at the end:
    # read-ahead is bounded by the reorder window (1 s = 30 frames) plus the queue (10).
    assert read_when_yielded[2] < 50


def test_depth_before_first_camera_info(tmp_path: Path) -> None:
    # Info from frame 3: earlier depth images wait for it in the synchroniser (as in the node).
    write_bag(tmp_path / 'a', BagSpec(frames=8, info_start=3))
    recs, bag = _read(tmp_path / 'a')
    assert len(recs) == 8 and all(r.frame.color is not None for r in recs)
    # Info from frame 15: the first 5 depth images fall out of the queue (size 10): dropped.
    write_bag(tmp_path / 'b', BagSpec(frames=20, info_start=15))
    recs, bag = _read(tmp_path / 'b')
    assert [r.frame.stamp_ns for r in recs] == [START_NS + i * PERIOD_NS for i in range(5, 20)]
    assert bag.stats.dropped['/camera/depth/image_raw'] == 5


@pytest.mark.parametrize(('topics', 'preset'), [(REALSENSE, 'RealSense'),
                                                (KINECT, 'Azure Kinect')])
def test_detects_driver_layouts(tmp_path: Path, topics: dict, preset: str) -> None:
    write_bag(tmp_path / 'bag', BagSpec(frames=3, topics=dict(topics)))
    recs, bag = _read(tmp_path / 'bag')
    assert bag.selection is not None
    assert preset in bag.selection.preset and topics['depth'] in bag.selection.describe()
    assert bag.selection.depth == topics['depth'] and len(recs) == 3


def test_explicit_topics(tmp_path: Path) -> None:
    topics = {'color': '/a/rgb', 'depth': '/a/depth', 'info': '/a/info', 'gt': '/a/gt'}
    write_bag(tmp_path / 'bag', BagSpec(frames=3, topics=topics))
    with pytest.raises(BagError, match='missing topic'):
        _read(tmp_path / 'bag')
    opts = ReaderOptions(color_topic='/a/rgb', depth_topic='/a/depth', info_topic='/a/info',
                         gt_topic='/a/gt')
    recs, bag = _read(tmp_path / 'bag', opts)
    assert len(recs) == 3 and all(r.gt is not None for r in recs)
    assert bag.selection is not None and bag.selection.preset == 'given topics'


def _damage(bag: Path, how: str) -> Path:
    f = storage_file(bag)
    data = f.read_bytes()
    if how == 'truncated':
        f.write_bytes(data[:len(data) // 2])
    elif how == 'corrupt':
        d = bytearray(data)
        start = len(d) // 3
        d[start:start + 5000] = bytes((b * 7 + 13) & 255 for b in d[start:start + 5000])
        f.write_bytes(bytes(d))
    elif how == 'garbage':
        f.write_bytes(os.urandom(4000))
    return bag


BAD = {
    'missing topic': (dict(topics={'color': '/x/color', 'depth': '/camera/depth/image_raw',
                                   'info': '/camera/depth/camera_info',
                                   'gt': '/ground_truth/end_effectors'}), None,
                      'missing topic.*/camera/color/image_raw'),
    'unknown encoding': (dict(depth_encoding='8UC1'), None, "unsupported depth encoding '8UC1'"),
    'unknown colour encoding': (dict(color_encoding='yuv422'), None, 'colour encoding'),
    'no camera info': (dict(info_every=0), None, 'camera_info'),
    'truncated': ({}, 'truncated', 'truncated|malformed|invalid|corrupt'),
    'corrupt': ({}, 'corrupt', 'corrupt|malformed|invalid'),
    'garbage': ({}, 'garbage', 'invalid|not a database|corrupt'),
}


@pytest.mark.parametrize('storage', STORAGES)
@pytest.mark.parametrize('case', sorted(BAD))
def test_bad_bags_raise_bag_error(tmp_path: Path, storage: str, case: str) -> None:
    kwargs, damage, pattern = BAD[case]
    bag = tmp_path / f'bad_{case.replace(" ", "_")}'
    write_bag(bag, BagSpec(frames=6, storage=storage, **kwargs))
    if damage:  # damaged storage is read up to the damage unless strict (test_bag_truncated)
        _damage(bag, damage)
    with pytest.raises(BagError, match=pattern) as info:
        _read(bag, ReaderOptions(strict=True))
    assert str(bag) in str(info.value)  # the message names the bag
    assert info.value.bag == str(bag)


def test_not_a_bag(tmp_path: Path) -> None:
    with pytest.raises(BagError, match='no such file'):
        _read(tmp_path / 'nope')
    (tmp_path / 'x.txt').write_text('hello')
    with pytest.raises(BagError, match='not a rosbag2 bag'):
        _read(tmp_path / 'x.txt')


def test_find_bags(tmp_path: Path) -> None:
    write_bag(tmp_path / 'root' / 'mcap' / 'b', BagSpec(frames=1))
    write_bag(tmp_path / 'root' / 'sqlite3' / 'a', BagSpec(frames=1, storage='sqlite3'))
    loose = tmp_path / 'root' / 'loose'
    write_bag(loose, BagSpec(frames=1))
    single = storage_file(loose).rename(tmp_path / 'root' / 'single.mcap')
    (loose / 'metadata.yaml').unlink()
    loose.rmdir()
    found = find_bags([tmp_path / 'root'])
    assert found == [tmp_path / 'root' / 'mcap' / 'b', tmp_path / 'root' / 'single.mcap',
                     tmp_path / 'root' / 'sqlite3' / 'a']
    assert find_bags([single]) == [single]
    assert len(list(read_frames(single))) == 1
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagError, match='no rosbag2 bags'):
        find_bags([tmp_path / 'empty'])


@pytest.mark.parametrize('storage', STORAGES)
def test_prefetch_thread_yields_the_same_frames(tmp_path: Path, storage: str) -> None:
    import threading

    write_bag(tmp_path / 'bag', BagSpec(frames=12, storage=storage, drop_color={4},
                                        shuffle_log=True))
    plain, bag = _read(tmp_path / 'bag', ReaderOptions(prefetch=False))
    ahead, bag2 = _read(tmp_path / 'bag', ReaderOptions(prefetch=True))
    assert len(plain) == len(ahead) == 12 and bag.stats.to_dict() == bag2.stats.to_dict()
    for a, b in zip(plain, ahead, strict=True):
        assert a.frame.stamp_ns == b.frame.stamp_ns and a.log_time_ns == b.log_time_ns
        np.testing.assert_array_equal(a.frame.depth, b.frame.depth)
        assert (a.frame.color is None) == (b.frame.color is None)
        if a.frame.color is not None:
            np.testing.assert_array_equal(a.frame.color, b.frame.color)
    # Leaving early stops the thread.
    with BagReader(tmp_path / 'bag', ReaderOptions(prefetch=True)) as reader:
        it = reader.records()
        next(it)
        assert any(t.name.startswith('bag-reader') for t in threading.enumerate())
        it.close()
    assert not any(t.name.startswith('bag-reader') for t in threading.enumerate())


def test_prefetch_thread_passes_errors_on(tmp_path: Path) -> None:
    write_bag(tmp_path / 'bag', BagSpec(frames=3, depth_encoding='8UC1'))
    with pytest.raises(BagError, match=f"frame at stamp {START_NS} ns.*'8UC1'"):
        _read(tmp_path / 'bag', ReaderOptions(prefetch=True))
