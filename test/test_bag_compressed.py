"""Bags recorded through image_transport (``compressed`` / ``compressedDepth`` topics)."""

from __future__ import annotations

import array
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from bag_helpers import (
    KINECT,
    PERIOD_NS,
    REALSENSE,
    START_NS,
    TOPICS,
    TS,
    BagSpec,
    cloud_msg,
    gt_positions,
    info_msg,
    render_depth,
)
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import StoragePlugin

from endeff_ros import image_codecs as codecs
from endeff_ros.bag.errors import BagError
from endeff_ros.bag.reader import BagReader, ReaderOptions
from endeff_ros.ros import convert

COMPRESSED = 'sensor_msgs/msg/CompressedImage'


def _rgb(spec: BagSpec, i: int) -> np.ndarray:
    rgb = np.full((spec.height, spec.width, 3), 90, np.uint8)
    rgb[render_depth(spec, i) < 3.4] = (200, 30, 30)
    return rgb


def _compressed(stamp_ns: int, frame_id: str, fmt: str, data: bytes) -> Any:
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    header = TS.types['std_msgs/msg/Header'](
        stamp=TS.types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nsec), frame_id=frame_id)
    return TS.types[COMPRESSED](header=header, format=fmt,
                                data=np.frombuffer(data, np.uint8).copy())


def write_compressed_bag(path: Path, spec: BagSpec, *, color: str = 'png',
                         depth: str = 'compressedDepth', depth_encoding: str = '16UC1',
                         topics: dict[str, str] | None = None) -> None:
    """Colour as ``<color topic>/compressed`` (rgb8 through ``color`` codec), depth as
    ``<depth topic>/<depth>`` (``compressedDepth`` or ``compressed``)."""
    topics = topics or TOPICS
    storage = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}[spec.storage]
    with Writer(path, version=9, storage_plugin=storage) as writer:
        conns: dict[str, Any] = {}

        def write(topic: str, typ: str, log: int, msg: Any) -> None:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, typ, typestore=TS)
            writer.write(conns[topic], log, TS.serialize_cdr(msg, typ))

        for i in range(spec.frames):
            stamp = START_NS + i * PERIOD_NS
            d = render_depth(spec, i)
            raw = np.round(d * 1000).astype(np.uint16) if depth_encoding == '16UC1' else d
            write(topics['info'], 'sensor_msgs/msg/CameraInfo', stamp, info_msg(spec, stamp))
            fmt, data = codecs.encode_depth(raw, depth_encoding, depth)
            write(f'{topics["depth"]}/{depth}', COMPRESSED, stamp + 1,
                  _compressed(stamp, spec.frame_id, fmt, data))
            fmt, data = codecs.encode_color(_rgb(spec, i), 'rgb8', color)
            write(f'{topics["color"]}/compressed', COMPRESSED, stamp + 2,
                  _compressed(stamp + 4_000_000, spec.frame_id, fmt, data))
            write(topics['gt'], 'sensor_msgs/msg/PointCloud2', stamp + 4,
                  cloud_msg(stamp, spec.frame_id, gt_positions(spec, i)))


def _read(path: Path, options: ReaderOptions | None = None) -> tuple[list, BagReader]:
    with BagReader(path, options) as bag:
        return list(bag.records()), bag


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
@pytest.mark.parametrize(('depth', 'encoding'), [('compressedDepth', '16UC1'),
                                                 ('compressedDepth', '32FC1'),
                                                 ('compressed', '16UC1')])
def test_reads_compressed_contract_bag(tmp_path: Path, storage: str, depth: str,
                                       encoding: str) -> None:
    spec = BagSpec(frames=4, storage=storage)
    write_compressed_bag(tmp_path / 'bag', spec, depth=depth, depth_encoding=encoding)
    recs, bag = _read(tmp_path / 'bag')
    assert bag.selection is not None and bag.selection.preset == 'benchmark contract'
    assert bag.selection.color == '/camera/color/image_raw/compressed'
    assert bag.selection.depth == f'/camera/depth/image_raw/{depth}'
    assert len(recs) == 4 and bag.stats.colorless == 0 and bag.stats.gt_matched == 4
    for i, rec in enumerate(recs):
        want = render_depth(spec, i)
        want[want == 0] = np.nan
        if encoding == '16UC1':  # lossless millimetres
            np.testing.assert_array_equal(rec.frame.depth,
                                          np.float32(np.round(want * 1000)) * np.float32(1e-3))
        else:  # inverse-depth quantisation: d^2 / 10100 per step, < 2 mm at 3.5 m
            np.testing.assert_allclose(rec.frame.depth, want, atol=2e-3, equal_nan=True)
        np.testing.assert_array_equal(rec.frame.color, _rgb(spec, i))  # PNG: exact, RGB


def test_jpeg_colour_and_driver_layouts(tmp_path: Path) -> None:
    spec = BagSpec(frames=3)
    for name, topics in (('rs', REALSENSE), ('k4a', KINECT)):
        write_compressed_bag(tmp_path / name, spec, color='jpeg', topics=topics)
        recs, bag = _read(tmp_path / name)
        assert bag.selection is not None and 'detected' in bag.selection.preset
        assert bag.selection.color == topics['color'] + '/compressed'
        assert bag.selection.depth == topics['depth'] + '/compressedDepth'
        assert len(recs) == 3
        diff = np.abs(recs[1].frame.color.astype(int) - _rgb(spec, 1))
        assert diff.mean() < 4.0  # JPEG: close, not exact


def test_compressed_only_bag_errors_name_the_compressed_topics(tmp_path: Path) -> None:
    topics = {'color': '/cam/rgb', 'depth': '/cam/dep', 'info': '/cam/info', 'gt': '/gt'}
    write_compressed_bag(tmp_path / 'bag', BagSpec(frames=2), topics=topics)
    with pytest.raises(BagError, match='missing topic') as info:
        _read(tmp_path / 'bag')
    assert '/cam/rgb/compressed' in str(info.value)
    assert '/cam/dep/compressedDepth' in str(info.value)
    # Naming the raw topic of a compressed-only bag points at the compressed one.
    opts = ReaderOptions(color_topic='/cam/rgb', depth_topic='/cam/dep/compressedDepth',
                         info_topic='/cam/info')
    with pytest.raises(BagError, match='the bag has /cam/rgb/compressed'):
        _read(tmp_path / 'bag', opts)
    opts = ReaderOptions(color_topic='/cam/rgb/compressed',
                         depth_topic='/cam/dep/compressedDepth', info_topic='/cam/info')
    recs, _ = _read(tmp_path / 'bag', opts)
    assert len(recs) == 2


def test_raw_topics_win_over_compressed(tmp_path: Path) -> None:
    """A bag with both (image_transport republishing): the raw topics are read."""
    from bag_helpers import write_bag

    write_bag(tmp_path / 'bag', BagSpec(frames=2))
    with BagReader(tmp_path / 'bag') as bag:
        topics = dict(bag.topic_types)
    topics['/camera/color/image_raw/compressed'] = COMPRESSED
    from endeff_ros.bag.reader import select_topics

    sel = select_topics(topics, ReaderOptions())
    assert sel.color == '/camera/color/image_raw' and sel.depth == '/camera/depth/image_raw'


def test_convert_frame_from_compressed_messages() -> None:
    """The node's converter takes CompressedImage messages (duck-typed) like raw images."""
    spec = BagSpec(frames=1)
    mm = np.round(render_depth(spec, 0) * 1000).astype(np.uint16)
    depth = _compressed(START_NS, 'cam', *codecs.encode_depth(mm, '16UC1'))
    color = _compressed(START_NS, 'cam', *codecs.encode_color(_rgb(spec, 0), 'rgb8', 'png'))
    assert convert.is_compressed(depth) and not convert.is_compressed(info_msg(spec, 0))
    frame = convert.frame_from_messages(color, depth, info_msg(spec, START_NS))
    assert frame.stamp_ns == START_NS and frame.frame_id == 'cam'
    np.testing.assert_array_equal(frame.color, _rgb(spec, 0))
    assert np.isnan(frame.depth[0, 0]) and frame.depth[5, 5] == np.float32(3500) * 1e-3
    # rclpy messages carry ``data`` as array.array / bytes, not numpy.
    like_rclpy = SimpleNamespace(header=depth.header, format=depth.format,
                                 data=array.array('B', depth.data.tobytes()))
    np.testing.assert_array_equal(convert.compressed_depth_to_array(like_rclpy), frame.depth)


def test_corrupt_compressed_frame_names_bag_and_stamp(tmp_path: Path) -> None:
    path = tmp_path / 'bag'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        spec = BagSpec(frames=1)
        c_info = writer.add_connection(TOPICS['info'], 'sensor_msgs/msg/CameraInfo',
                                       typestore=TS)
        c_d = writer.add_connection(TOPICS['depth'] + '/compressedDepth', COMPRESSED,
                                    typestore=TS)
        c_c = writer.add_connection(TOPICS['color'] + '/compressed', COMPRESSED, typestore=TS)
        writer.write(c_info, START_NS, TS.serialize_cdr(info_msg(spec, START_NS),
                                                        'sensor_msgs/msg/CameraInfo'))
        bad = _compressed(START_NS, 'cam', '16UC1; compressedDepth png', b'\0' * 12 + b'junk')
        writer.write(c_d, START_NS + 1, TS.serialize_cdr(bad, COMPRESSED))
        col = _compressed(START_NS, 'cam', *codecs.encode_color(_rgb(spec, 0), 'rgb8', 'png'))
        writer.write(c_c, START_NS + 2, TS.serialize_cdr(col, COMPRESSED))
    with pytest.raises(BagError, match=f'frame at stamp {START_NS} ns.*cannot decode'):
        _read(path)


def test_process_and_eval_read_compressed_bags(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """``endeff process`` on a compressed recording gives the clouds of its raw twin."""
    from bag_helpers import FakeTracker, fake_estimate_frame, write_bag
    from rosbags.highlevel import AnyReader

    import endeff_ros.core.tracker as tracker_mod
    from endeff_ros.cli import main as cli_main
    from endeff_ros.evaluate import evaluate_bag

    monkeypatch.setattr(tracker_mod, 'Tracker', FakeTracker)
    spec = BagSpec(frames=4)
    write_compressed_bag(tmp_path / 'packed', spec)  # PNG colour, compressedDepth 16UC1
    write_bag(tmp_path / 'raw', spec)
    clouds = {}
    for name in ('packed', 'raw'):
        out = tmp_path / f'{name}_out'
        assert cli_main(['process', str(tmp_path / name), '-o', str(out)]) == 0
        with AnyReader([out]) as r:
            clouds[name] = [convert.xyz(convert.cloud_to_array(r.deserialize(raw, c.msgtype)))
                            for c, _, raw in r.messages()]
    assert len(clouds['packed']) == 4
    for a, b in zip(clouds['packed'], clouds['raw'], strict=True):
        np.testing.assert_array_equal(a, b)
    res = evaluate_bag(tmp_path / 'packed', estimate_fn=fake_estimate_frame,
                       tracker_factory=FakeTracker)
    assert res.scored_frames == 4 and res.score('temporal').recall == 1.0
